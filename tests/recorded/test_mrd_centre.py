"""The centre map (estimator.online.spindle_centre, estimator.offline.spindle.centre_fit, recorded.mrd_centre):
synthetic runs whose band edges follow the capstan law c +- F0 + r e^(+-K) tau_d around a jaw torque that
depends on the angle, the direction and the load."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from estimator.offline.spindle.centre_fit import (
    fit_centre_map,
    held_features,
    predict_held,
    run_centre,
    scale_profile,
    within_run_gain,
)
from estimator.offline.spindle.shared import RunData, kinematic_ratio
from estimator.online.spindle import first_reversal
from estimator.online.spindle_centre import (
    MIN_SAMPLES,
    centre_features,
    centre_ready,
    predict_centre_map,
    stroke_centre,
)
from recorded.mrd_centre import (
    CENTRE,
    centre_one_run,
    centre_time_split,
    gain_identifiability,
    implied_load_gain,
    mid_centre_run,
    model_choice,
    score_centre,
)

R_TRUE, K, F0, C0, SLOPE = 1.01, 0.25, 0.05, -0.014, -0.017
GAIN = 1.0 / (R_TRUE * math.cosh(K))          # jaw torque per band-centre torque


def synth(name: str, load: float, freq: float = 0.3, seed: int = 0, drift: float = 0.0) -> RunData:
    """``drift``: a slow relative swing of the load (0.037 Hz), the part of the jaw torque that is not a
    function of (angle, direction)."""
    t = np.arange(0.0, 12.0, 0.001)
    th = 0.5 * (1 - np.cos(2 * math.pi * freq * t))
    s = np.sign(np.sin(2 * math.pi * freq * t))                    # +1 while the angle rises
    td = load * (1 + drift * np.sin(2 * math.pi * 0.037 * t)) - 0.01 * th ** 2 + 0.002 * s
    tp = C0 + SLOPE * th - s * F0 + R_TRUE * np.exp(-s * K) * td    # rising angle: the low (back-driven) edge
    tp = tp + 5e-4 * np.random.default_rng(seed).standard_normal(t.size)
    return RunData(name, tp, th, td, th, first_reversal(th, 0.001), 0.001)


def _rms(p, r: RunData) -> float:
    e = predict_held(p, r.tau_p, r.theta_p, r.dt)[r.k0:] - r.tau_d[r.k0:]
    return float(np.sqrt(np.mean(e ** 2)))


def test_stroke_centre_is_causal_and_reads_the_band_middle():
    r = synth("a", 0.03)
    win = (0.1, 0.9)
    c = stroke_centre(r.tau_p, r.theta_p, r.dt, win, (F0, 0.0), 0.0, (SLOPE, SLOPE), 0.5)
    truth = (C0 + SLOPE * 0.5 + R_TRUE * math.cosh(K) * 0.03
             - 0.01 * np.mean(r.theta_p[r.k0:] ** 2) * R_TRUE * math.cosh(K))
    assert abs(c[-1] - truth) < 0.004                                # both edges seen: the band's middle
    cut = 7000
    tail = r.tau_p.copy()
    tail[cut:] += 1.0                                               # a different future
    c2 = stroke_centre(tail, r.theta_p, r.dt, win, (F0, 0.0), 0.0, (SLOPE, SLOPE), 0.5)
    assert np.array_equal(c[:cut - 30], c2[:cut - 30])              # causal up to the rate's 25 ms window
    with pytest.raises(ValueError):
        stroke_centre(r.tau_p, r.theta_p[:-1], r.dt, win, (F0, 0.0), 0.0)


def test_load_gain_fitted_across_loads_predicts_a_new_load():
    runs = [synth(f"{i}", load, seed=i) for i, load in enumerate((0.01, 0.025, 0.045))]
    p, _ = fit_centre_map(runs)
    assert p.coef[1, 0] == pytest.approx(GAIN, rel=0.08)
    new = synth("new", 0.035, freq=0.2, seed=9)
    assert _rms(p, new) < 0.0015                                    # 3 % of the 0.05 N m load range
    assert run_centre(new, p.window) > run_centre(runs[0], p.window)


def test_one_load_cannot_tell_the_gain_but_the_other_loads_can():
    """On one run the fit cost is flat in the load gain, while the error at another load is not."""
    cal, other = synth("cal", 0.025), synth("other", 0.045, seed=3)
    prof = scale_profile([cal], np.array([0.7, GAIN, 1.3]))
    costs = [rms for _, _, rms in prof]
    errs = [_rms(p, other) for _, p, _ in prof]
    assert max(costs) - min(costs) < 0.2 * min(errs[0], errs[2])
    assert errs[1] < 0.5 * min(errs[0], errs[2])
    p, rec = centre_one_run([cal], 0.05)
    assert rec["load_gain"]["from"].startswith("1 / n_k") and len(rec["profile"]) > 3
    assert p.coef[1, 0] == pytest.approx(1.0 / rec["load_gain"]["n_k"])


def test_mid_centre_run_picks_the_middle_load_from_spindle_torque():
    runs = [synth(f"{i}", load, seed=i) for i, load in enumerate((0.01, 0.045, 0.025))]
    assert mid_centre_run(runs) == "2"


def test_centre_ready_is_where_the_half_width_stops_mattering():
    """Before centre_ready the centre rests on one edge and the calibration's half-width; from it on, on both
    edges, so two half-widths give the same reading; scores start there and keep the k0 figures apart."""
    r = synth("a", 0.03)
    win = (0.1, 0.9)
    k = centre_ready(r.theta_p, r.dt, win)
    assert r.k0 < k < r.theta_p.size
    a, b = (stroke_centre(r.tau_p, r.theta_p, r.dt, win, (w0, 0.0), 0.0, (SLOPE, SLOPE), 0.5) for w0 in (F0, 2 * F0))
    assert np.array_equal(a[k:], b[k:]) and a[k - 1] != b[k - 1]
    assert centre_ready(r.theta_p[:k], r.dt, win) == k                  # causal: the future is not needed
    assert centre_ready(np.full(3000, 0.5), r.dt, win) == 3000          # never in motion: never ready
    assert MIN_SAMPLES > 0
    p, _ = fit_centre_map([r])
    sc = score_centre(p, r, r.k0, 0.05)
    assert sc["scored_from_s"] == pytest.approx(centre_ready(r.theta_p, r.dt, p.window) * r.dt)
    assert set(sc["from_k0"]) == {"torque_rmse_fs", "torque_max_fs"}


def test_model_choice_takes_the_lower_calibration_split_score():
    """The headline's model is chosen on the calibration runs' time split only; the rule and its inputs are recorded."""
    cal = [synth("cal", 0.025, freq=0.4)]
    split = centre_time_split(cal, 0.05)
    assert 0.0 < split < 0.05                                           # the map fits its own second half
    for pair_score, expect in ((10 * split, CENTRE), (0.5 * split, "pair")):
        c = model_choice("pair", pair_score, 0.01, cal, 0.05, 0.002)
        assert c["chosen"] == expect and c["candidates"][CENTRE] == pytest.approx(split)
        assert "calibration data only" in c["rule"] and c["in_sample_not_used"]["pair"] == 0.01


def test_within_run_gain_needs_jaw_torque_that_is_not_a_function_of_angle_and_direction():
    """The gain 1 / (r cosh K) is read inside one run only from jaw torque beyond the shape along the stroke:
    recovered with a slow load swing, unbounded without one (the MRD runs' case, docs/results/mrd.md)."""
    swing = within_run_gain(synth("swing", 0.03, drift=0.3))
    assert swing["gain"] == pytest.approx(GAIN, rel=0.05)
    lo, hi = swing["profile_ci95"]
    assert lo < 1.0 / GAIN < hi and hi - lo < 0.2
    assert swing["periods"] == 4 and swing["jackknife_se"] is not None and swing["jackknife_se"] < 0.05
    flat = within_run_gain(synth("flat", 0.03))
    assert flat["jaw_free_rms_Nm"] < 1e-3 * flat["jaw_rms_Nm"]
    assert flat["profile_ci95"][1] - flat["profile_ci95"][0] > 1.0    # no information on the gain
    with pytest.raises(ValueError):
        within_run_gain(RunData("still", np.zeros(500), np.full(500, 0.5), np.zeros(500), np.zeros(500), 10, 0.001))
    g = gain_identifiability([synth("a", 0.02, drift=0.3), synth("b", 0.04, seed=2, drift=0.3)], GAIN)
    assert g["summary"]["runs_within_4pc_of_folder_gain"] == 2 and set(g["runs"]) == {"a", "b"}
    assert g["runs"]["a"]["n_k"] == pytest.approx(1.0)                 # synth's jaw angle is the spindle's


def test_kinematic_ratio_with_stretch_reads_the_ratio_at_zero_spindle_torque():
    r = synth("k", 0.03)
    n, lam = 0.9, 2.0                                                   # ratio, compliance [rad/(N m)]
    th_d = n * (r.theta_p - lam * r.tau_p) + 0.01 * np.sign(np.gradient(r.theta_p))
    k = RunData("k", r.tau_p, r.theta_p, r.tau_d, th_d, r.k0, r.dt)
    assert kinematic_ratio([k], stretch=True) == pytest.approx(n, abs=0.002)
    assert abs(kinematic_ratio([k]) - n) > 0.01                          # the stretch bends the plain ratio


def test_shape_is_held_outside_the_calibration_angles():
    """Fitted on part of the stroke, the map holds the shape at the last angle seen instead of
    extrapolating its degree-4 polynomial; inside the range it is the plain map."""
    full = synth("full", 0.03, freq=0.4)
    part = RunData("part", full.tau_p, np.minimum(full.theta_p, 0.6), full.tau_d, full.theta_d, full.k0, full.dt)
    p, _ = fit_centre_map([part], scale=GAIN)
    (ul, uh), (dl, dh) = p.notes["shape_range"]
    assert uh <= 0.6 - p.theta_ref + 1e-9 and dh <= 0.6 - p.theta_ref + 1e-9
    d = np.linspace(min(ul, dl), max(uh, dh), 50) + p.theta_ref
    z, c = np.tanh(np.linspace(-3, 3, 50)), np.full(50, 0.01)
    inside = (d - p.theta_ref >= max(ul, dl)) & (d - p.theta_ref <= min(uh, dh))
    assert np.allclose(held_features(d, c, z, p.theta_ref, 4, p.notes["shape_range"])[inside],
                       centre_features(d, c, z, p.theta_ref, 4)[inside])
    held = predict_held(p, full.tau_p, full.theta_p, full.dt)[full.k0:] - full.tau_d[full.k0:]
    poly = predict_centre_map(p, full.tau_p, full.theta_p, full.dt)[full.k0:] - full.tau_d[full.k0:]
    assert np.max(np.abs(held)) < 0.01 < np.max(np.abs(poly))       # the true shape moves 0.006 N m beyond 0.6


def test_model_choice_at_one_load_keeps_only_a_load_gain_the_run_allows():
    """The time split cannot see the load gain; a candidate whose implied gain lies outside the
    calibration runs' own reading of it is not eligible, whatever its split score."""
    cal = [synth("cal", 0.025, freq=0.4, drift=0.3)]
    p, _ = fit_centre_map(cal, scale=GAIN)
    g = implied_load_gain(lambda r, u: predict_held(p, r.tau_p + u, r.theta_p, r.dt), cal)
    assert g == pytest.approx(GAIN, rel=1e-6)                           # the band moves, the map carries b_0
    split = centre_time_split(cal, 0.05)
    for pair_gain, expect in ((0.2, CENTRE), (GAIN, "pair")):
        c = model_choice("pair", 0.5 * split, 0.01, cal, 0.05, 0.002, {"pair": pair_gain, CENTRE: g})
        assert c["chosen"] == expect and c["load_gain_check"]["eligible"][CENTRE]
    none = model_choice("pair", 0.5 * split, 0.01, cal, 0.05, 0.002, {"pair": 0.2, CENTRE: 0.2})
    assert none["chosen"] == "pair"                                     # nothing eligible, equally far: the split
    lo, hi = none["load_gain_check"]["slope_interval"]
    near = model_choice("pair", 0.5 * split, 0.01, cal, 0.05, 0.002, {"pair": 0.2, CENTRE: 1.0 / (1.05 * hi)})
    assert not any(near["load_gain_check"]["eligible"].values())        # nothing eligible: the
    assert near["chosen"] == CENTRE                                     # nearest to the run's reading, not the split
    assert near["load_gain_check"]["log_distance"][CENTRE] == pytest.approx(math.log(1.05))
    # a load gain of the wrong sign lies no finite distance from the reading: null in the JSON the result is
    neg = model_choice("pair", 0.5 * split, 0.01, cal, 0.05, 0.002, {"pair": 0.2, CENTRE: -1.0})
    assert neg["load_gain_check"]["log_distance"][CENTRE] is None and neg["chosen"] == "pair"
    assert json.loads(json.dumps(neg, allow_nan=False)) == neg
    two = [synth("a", 0.01, freq=0.4), synth("b", 0.04, freq=0.4, seed=2)]     # two loads: a tight reading
    lc = model_choice("pair", 0.0, 0.01, two, 0.05, 0.002, {"pair": 0.9 * GAIN, CENTRE: GAIN})["load_gain_check"]
    assert lc["slope"] == pytest.approx(1.0 / GAIN, rel=0.02) and lc["eligible"] == {"pair": False, CENTRE: True}


def test_a_design_load_gain_replaces_the_encoders_and_is_recorded():
    """``--calibration gain=G:RUN``: the one number a one-run calibration lacks, given from outside."""
    from recorded.mrd_calibration import split_design_gain
    from teleop.errors import ConfigError
    assert split_design_gain("gain=0.943:mid") == (0.943, "mid") and split_design_gain("31") == (None, "31")
    assert split_design_gain(None) == (None, None)
    for bad in ("gain=x:31", "gain=-1:31", "gain=0:31", "gain=0.9:segment:4"):
        with pytest.raises(ConfigError):
            split_design_gain(bad)
    cal, other = synth("cal", 0.025), synth("other", 0.045, seed=3)
    p, rec = centre_one_run([cal], 0.05, given=GAIN)
    assert p.coef[1, 0] == GAIN and rec["load_gain"]["from"].startswith("given") and "profile" in rec
    q, _ = centre_one_run([cal], 0.05, given=1.2 * GAIN)                # a design value 20 % off
    assert _rms(p, other) < 0.5 * _rms(q, other)


def test_a_folder_measures_its_load_gain_and_another_folder_takes_it_from_the_json(tmp_path):
    """The folder's load gain across its loads (the stroke-averaged number a one-run calibration
    needs) is reported with a jackknife SE, and ``--calibration gain=OTHER.json:RUN`` reads it from another
    folder's JSON; a folder of one load level, a missing file or a JSON without it is refused by name."""
    import json

    from recorded.mrd_calibration import split_design_gain
    from recorded.mrd_centre import centre_folder
    from teleop.errors import ConfigError
    folder = [synth(f"{i}", load, seed=i) for i, load in enumerate((0.01, 0.02, 0.03, 0.04))]
    rec = centre_folder(folder, 0.05, lambda _: None)
    lg = rec["load_gain"]
    assert lg["several_loads"] and lg["value"] == pytest.approx(GAIN, rel=0.02)
    assert (0.0 < lg["jackknife_se"] < 0.02
            and lg["leave_one_run_out_range"][0] <= lg["value"] <= lg["leave_one_run_out_range"][1])
    out = tmp_path / "other.json"
    out.write_text(json.dumps({"centre_map": rec}, default=float))
    g, rest = split_design_gain(f"gain={out}:mid")
    assert g == pytest.approx(lg["value"]) and rest == "mid"
    colon = tmp_path / "a:b"                                            # a path with ':' in it is found whole
    colon.mkdir()
    (colon / "other.json").write_text(out.read_text())
    assert split_design_gain(f"gain={colon / 'other.json'}:mid") == (g, "mid")
    assert split_design_gain(f"gain={colon / 'other.json'}") == (g, "")
    cal, other = synth("cal", 0.025), synth("other", 0.045, seed=3)
    p, _ = centre_one_run([cal], 0.05, given=g)
    assert _rms(p, other) < 0.002                                       # the other load, from one run and the number
    one = centre_folder([synth("a", 0.02), synth("b", 0.02, seed=1)], 0.05, lambda _: None, loro=False)
    assert not one["load_gain"]["several_loads"]
    (tmp_path / "one.json").write_text(json.dumps({"centre_map": one}, default=float))
    (tmp_path / "bare.json").write_text("{}")
    for bad, word in (("one.json", "one load level"), ("bare.json", "no centre_map.load_gain"),
                      ("gone.json", "no such file")):
        with pytest.raises(ConfigError, match=word):
            split_design_gain(f"gain={tmp_path / bad}:31")
