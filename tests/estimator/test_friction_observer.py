"""The friction observer and tracker (estimator/online/friction_observer.py) and the per-cycle form that tracks friction
(ExtendedEstimator(track_friction=True)): the loop width gives K, a load's own hysteresis cancels, a step of friction
at an instant the model never saw is followed."""
from __future__ import annotations

import math

import numpy as np
import pytest

from estimator.online.extended import TRACKED, ExtendedEstimator
from estimator.online.friction_observer import FrictionObserver, FrictionTracker
from estimator.sheath import SheathModel
from study.scenarios import record


def _loops(K_of_cycle, *, k_load=2000.0, a=0.0, c_v=0.0, load_hysteresis=0.0, cycles=6, n=400):
    """Full-slip capstan loops on an elastic load: per cycle one pulling and one releasing branch over the same
    distal positions. Yields (T_in, x_out, direction, speed factor)."""
    x = np.linspace(1e-3, 5e-3, n)
    for c in range(cycles):
        K = K_of_cycle(c)
        for s, xs in ((1, x), (-1, x[::-1])):
            T_out = k_load * xs * (1.0 + s * load_hysteresis)
            f = 1.0 + c_v * 0.01
            T_in = (T_out + a) * np.exp(s * K * f) - a
            yield from ((float(ti), float(xo), s, f) for ti, xo in zip(T_in, xs, strict=True))


def _estimates(obs, samples):
    return [k for ti, xo, s, f in samples if (k := obs.observe(ti, xo, s, f)) is not None]


@pytest.mark.parametrize("a, c_v", [(0.0, 0.0), (0.8, 0.0), (0.0, 20.0)])
def test_the_loop_width_gives_the_friction_exponent(a, c_v):
    est = _estimates(FrictionObserver(a=a), _loops(lambda c: 0.7, a=a, c_v=c_v))
    assert len(est) >= 9                                  # one per branch after the first of each direction
    assert np.allclose(est, 0.7, atol=1e-3)


def test_a_wrong_offset_or_a_stuck_sample_gives_no_exponent():
    obs = FrictionObserver()
    assert obs.observe(5.0, 1e-3, 0) is None              # stuck: not a branch sample
    assert _estimates(FrictionObserver(min_points=10_000), _loops(lambda c: 0.7)) == []
    with pytest.raises(ValueError, match="spacing"):
        FrictionObserver(spacing=0.0)


def test_a_step_of_friction_is_seen_within_two_branches():
    est = _estimates(FrictionObserver(), _loops(lambda c: 0.7 if c < 3 else 0.45, cycles=6))
    first_new = 2 * 3 - 1              # branch b (from 0) gives estimate b - 1; the first new branch is 6
    assert est[first_new] == pytest.approx(0.575, abs=2e-3)   # the mean of the two levels
    assert np.allclose(est[first_new + 1:], 0.45, atol=1e-3)


def test_the_tracker_cancels_a_load_hysteresis_and_clamps():
    est = _estimates(FrictionObserver(), _loops(lambda c: 0.7 if c < 3 else 0.9, load_hysteresis=0.05))
    assert est[0] > 0.72                                   # the load's hysteresis widens the loop
    tr = FrictionTracker(reference=2)
    out = [tr.update(k, 0.7) for k in est]
    assert out[:2] == [None, None]
    assert tr.bias == pytest.approx(0.5 * math.log(1.05 / 0.95), abs=2e-3)
    assert out[-1] == pytest.approx(0.9, abs=2e-3)
    assert FrictionTracker(K_max=1.0, reference=1).update(0.5, 0.0) is None
    t = FrictionTracker(K_max=1.0, reference=1, median=1)
    t.update(0.5, 0.5)
    assert t.update(9.0, 0.5) == 1.0 and t.update(-3.0, 0.5) == 0.0
    assert t.update(math.nan, 0.5) is None


def test_the_tracker_passes_a_step_and_rejects_a_single_outlier():
    t = FrictionTracker(reference=1, median=3)
    t.update(0.7, 0.7)
    out = [t.update(k, 0.7) for k in (0.7, 0.7, 0.4, 0.7, 0.7, 0.5, 0.45, 0.45, 0.45)]
    assert out[3] == 0.7                        # one branch far off: held
    assert out[-1] == 0.45 and out[-3] == 0.5   # a step: followed once two branches agree


def _run(rec, values, track):
    tr = rec.truth
    u, w = SheathModel(K=1.0, compliance=1.0).nodes(32)
    est = ExtendedEstimator(values, u, w, tr["compliance"], tension_noise=tr["noise_T_in"], average=5,
                            track_friction=track)
    d = rec.data
    out, K = np.empty(len(d.time)), np.empty(len(d.time))
    for k, (a, b, c) in enumerate(zip(d.T_in, d.x_in, d.time, strict=True)):
        out[k], K[k] = est.step(float(a), float(b), float(c)).T_out, est.friction
    return est, out, K


def test_a_sheath_reshaped_at_another_instant_is_followed_on_the_simulated_rig():
    """The tracked K starts from the model's first level and corrects it from the first estimates, then follows the
    step where the rig's sheath is reshaped, not where the model's was."""
    rec = record("friction_step", seed=5, level=0.7, duration=40.0)
    p, K = rec.truth["parameters"], rec.truth["K"]
    # a model fitted on another session: its first level 15 % high, its step 12 s late
    fitted_elsewhere = {"K": 1.15 * K, "dK": p["dK"], "t_s": p["t_s"] + 12.0}
    tracked, out_t, K_t = _run(rec, fitted_elsewhere, True)
    _, out_r, _ = _run(rec, fitted_elsewhere, False)
    d = rec.data
    assert tracked.tracker is not None and tracked.tracker.estimates >= 10
    before, later = d.time < p["t_s"], (d.time > p["t_s"] + 2.0) & (d.time < p["t_s"] + 15.0)
    assert np.median(K_t[before]) == pytest.approx(K, abs=0.02)
    assert np.median(K_t[later]) == pytest.approx(K + p["dK"], abs=0.02)
    after = (d.time > p["t_s"] + 3.0) & (d.time < p["t_s"] + 12.0)
    rms = [float(np.sqrt(np.mean((o[after] - d.T_out[after]) ** 2))) for o in (out_t, out_r)]
    assert rms[0] < 0.5 * rms[1]


def test_the_tracked_entries_are_the_friction_changes():
    assert set(TRACKED) == {"curvature_drift", "friction_step"}
