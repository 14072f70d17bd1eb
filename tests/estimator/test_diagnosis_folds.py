"""How a candidate is judged: a training block up to a rest and a test block after it, two folds inside the
training block, and the residuals' trimmed mean squares compared. The paired trim keeps the short events one model
explains (a load cell that steps only where a constant-force load leaves or lands on its stop); an effect of the
starting state is judged on the fold that validates on the start, a drift from zero on the one that validates on
the end; a fold fitted on one pull, with no release of T_in in its fit block, does not judge the route.

The clean rig recording is 45 s at 500 Hz, the lumped simulator's recordings 60 s at its own rate; seeds are
development seeds (the benchmark's final seeds are never used in tests).
"""

import numpy as np
import pytest

from estimator.offline.diagnosis import folds as diagnosis_folds
from estimator.offline.diagnosis import readings as diagnosis_readings
from estimator.offline.diagnosis import thresholds as th
from estimator.offline.diagnosis.fit import (
    paired_trimmed_ms,
    prepare,
    split_at_rest,
    trimmed_ms,
)
from estimator.offline.diagnosis.selection import diagnose
from study.lumped import scenarios as lumped_scenarios


def test_split_is_a_time_block_at_a_rest(clean_result):
    rec, res = clean_result
    sp = res["split"]
    assert 0.52 <= sp["train_fraction"] <= 0.68
    assert sp["n_train"] + sp["n_heldout"] == len(rec.data)
    # which samples served for what: folds inside the training block, the test block after it
    tr, te = sp["train"], sp["test"]
    assert tr["index"] == [0, sp["n_train"]] and te["index"] == [sp["n_train"], len(rec.data)]
    assert te["time_s"][0] >= sp["time_s"] > tr["time_s"][1]
    for fold in sp["folds"]:
        f, v = fold["fit"]["index"], fold["validation"]["index"]
        assert 0 <= min(f + v) and max(f + v) <= sp["n_train"]           # never the test block
        assert f[1] <= v[0] or v[1] <= f[0]                              # fit and validation apart
        assert f[1] - f[0] > v[1] - v[0] > 0.2 * sp["n_train"]
    assert sp["n_train"] == int(np.sum(rec.data.time < sp["time_s"]))    # everything before, nothing after
    s = prepare(rec.data)
    k = split_at_rest(s, 0.6)
    window = slice(max(k - 25, 0), k + 25)                                # +-0.1 s around the split
    assert np.max(np.abs(s.velocity[window])) < 0.5 * np.max(np.abs(s.velocity))
    with pytest.raises(ValueError, match="train_fraction"):
        split_at_rest(s, 0.95)


def test_paired_trim_keeps_the_short_events_one_model_explains():
    # the base misses a few short events (1 % of the samples) that the extension explains; both miss a few
    # transients (1 %): trimmed apart, each model drops its own largest 2 % and the events vanish from the
    # comparison; paired, only the transients neither explains are dropped
    rng = np.random.default_rng(3)
    n = 2000
    noise = rng.standard_normal(n)
    both = np.zeros(n)
    both[::100] = 50.0                     # transients neither model explains
    events = np.zeros(n)
    events[50::100] = 20.0                 # what only the extension explains
    r_ext, r_base = noise + both, noise + both + events
    assert trimmed_ms(r_base, 0.02) < 1.5 * trimmed_ms(r_ext, 0.02)
    ms_ext, ms_base = paired_trimmed_ms(r_ext, r_base, 0.02)
    assert ms_base > 3.0 * ms_ext
    assert ms_ext < 2.0                    # the common transients are left out
    assert paired_trimmed_ms(r_base, r_ext, 0.02) == (ms_base, ms_ext)


def test_lumped_lag_of_a_load_cell_that_only_steps_is_named():
    # a constant-force load: T_out steps only where the load leaves or lands on its stop, so a 42 ms lag shows in
    # about 1 % of the samples; the paired trim keeps those samples (each model's own trim would drop them)
    rec = lumped_scenarios.record("sensor_lag:T_out", seed=713111, level=0.8, duration=60.0)
    res = diagnose(rec.data, effects=("sensor_lag:T_out", "sensor_offset:x_in", "velocity_friction"))
    assert res["cause"] == "sensor_lag:T_out", ({k: c["score"] for k, c in res["candidates"].items()})
    assert res["parameters"]["tau_T_out"]["value"] == pytest.approx(0.042, rel=0.1)
    assert res["gain"] > 0.5


def test_lumped_pretension_seen_only_before_the_first_slide_is_judged_on_the_start():
    # 1.8 N of preload on a joint that sits on its stop from rest: the first pull erases the preload's profile, so the
    # base misses only the first 1.3 s and the forward fold, validated after that, cannot show it (its base at the
    # floor). Judged on the backward fold, which holds the start (Effect.initial_state), it is named with T0 within 25 %
    rec = lumped_scenarios.record("pretension", seed=3201101, level=0.2, duration=60.0)
    res = diagnose(rec.data, effects=("pretension", "sensor_gain:T_in", "sensor_offset:T_out"))
    assert res["causes"] == ["pretension"], (res["structure"], {k: c["score"] for k, c in res["candidates"].items()})
    T0 = res["parameters"]["T0"]["value"]
    assert T0 == pytest.approx(rec.truth["parameters"]["tension"], rel=0.25)
    # an effect that is not of the starting state keeps the worse fold: the T_in gain's S stays near 1
    assert res["candidates"]["sensor_gain:T_in"]["score"] > 0.9


def test_lumped_drift_from_zero_at_the_start_is_judged_on_the_end():
    # a distal load-cell drift of -0.0048 N/s (0.29 N over the minute) is zero at the start, where the channel was
    # zeroed: the backward fold validates on the start, where it is smallest, and its base is at the floor there.
    # Judged on the forward fold (Effect.from_start), it is named with its rate within 25 %
    rec = lumped_scenarios.record("sensor_drift:T_out", seed=3415102, level=0.2, duration=60.0)
    res = diagnose(rec.data, effects=("sensor_drift:T_out", "sensor_offset:T_out", "curvature_drift"))
    assert res["causes"] == ["sensor_drift:T_out"], (res["structure"],
                                                     {k: c["score"] for k, c in res["candidates"].items()})
    assert res["parameters"]["d_T_out"]["value"] == pytest.approx(rec.truth["parameters"]["rate"], rel=0.25)
    drift = res["candidates"]["sensor_drift:T_out"]
    assert drift["scored_on"].startswith("the forward fold") and drift["score"] == drift["fold_scores"][0]
    assert drift["fold_scores"][1] > 0.5
    # a drift of K is not counted from a zero (K(t) = K + K_rate (t - t0) fits either way): the worse fold counts
    assert res["candidates"]["curvature_drift"]["scored_on"].startswith("both")


def test_holds_release_reads_a_fall_from_the_running_maximum():
    t = np.linspace(0.0, 10.0, 2001)
    pull = 2.0 * t
    assert not diagnosis_readings.holds_release(pull)
    assert not diagnosis_readings.holds_release(pull + 0.01 * np.sin(50.0 * t))      # noise on a pull is no release
    cycle = 10.0 * np.sin(0.5 * t)                                              # up to 10 N and back down
    assert diagnosis_readings.holds_release(cycle)
    assert not diagnosis_readings.holds_release(np.ones(50)) and not diagnosis_readings.holds_release(np.ones(1))


def test_a_fold_fitted_on_one_pull_does_not_judge_the_route(monkeypatch):
    # a clean recording of one slow pull to 18 N, released only after the forward fold's fit block. Fitted on the
    # pull alone the route's shape is unknown and the forward validation block (the release) would show the base's
    # extrapolation. The backward fold, whose fit block holds the release, judges alone: "none"; the same rig with a
    # 14 % K drift hidden is named
    twin = lumped_scenarios.record(None, seed=4402103, level=0.2, duration=60.0)
    res = diagnose(twin.data)
    assert res["cause"] == "none", res["structure"]
    assert res["split"]["judged_folds"][0].startswith("backward alone")
    from study.report import split_text
    assert "Judged on the backward alone" in split_text(res)
    assert max(res["structure"]["base"].values()) < th.STRUCTURE_RATIO
    drift = diagnose(lumped_scenarios.record("curvature_drift", seed=4402103, level=0.2, duration=60.0).data)
    assert drift["cause"] == "curvature_drift" and drift["gain"] > 0.3
    # with both folds judging, the extrapolation is read as structure
    monkeypatch.setattr(diagnosis_folds, "holds_release", lambda T_in: True)
    assert diagnose(twin.data)["cause"] == "unknown"
