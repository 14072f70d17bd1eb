"""Diagnosis: recordings with one effect hidden at a seeded random magnitude in its realistic range
must be diagnosed with the right identifier (naming the channel for the sensor effects), a held-out
gain >= 0.3 and the magnitude within 25 %; clean recordings must give ``none``; an effect outside
the catalogue must give ``unknown``. Two simulators: the project's rig (study.scenarios, every
catalogue id) and the independent lumped-mass simulator (study.lumped.scenarios, a subset; the
benchmark runs the full confusion matrix on both).

Recordings are 45-60 s at 500 Hz here (the benchmark uses 90 s at 1 kHz and the lumped simulator's own
rates); seeds are development seeds (the benchmark's final seeds are never used in tests).
"""
import json
import math
from dataclasses import replace

import numpy as np
import pytest

from estimator.data import MeasuredData
from estimator.errors import DataError
from estimator.offline.diagnosis import folds as diagnosis_folds
from estimator.offline.diagnosis import readings as diagnosis_readings
from estimator.offline.diagnosis import selection
from estimator.offline.diagnosis import thresholds as th
from estimator.offline.diagnosis.fit import (
    paired_trimmed_ms,
    predictions,
    prepare,
    rest_start,
    split_at_rest,
    start_points,
    trimmed_ms,
)
from estimator.offline.diagnosis.readings import look_alike, toe_or_play
from estimator.offline.diagnosis.selection import diagnose
from estimator.offline.diagnosis.thresholds import (
    EXCESS_MIN,
    EXCESS_MIN_WITHOUT,
    FLOOR_SCORE_WITHOUT,
    K_RESTART,
    STRONG_SCORE,
)
from estimator.offline.effects.catalogue import CATALOGUE, EFFECT_IDS, EQUIVALENT
from estimator.offline.effects.types import route_shape
from study.lumped import scenarios as lumped_scenarios
from study.scenarios import record

DUR, RATE = 45.0, 500.0
# rig parameter -> fitted parameter (physical effects; a sensor effect's one parameter is its own)
FITTED = {"viscous": "c_v", "tension": "T0", "K_rate": "K_rate", "softening": "beta", "toe_tension": "T_c",
          "static_ratio": "r_s", "tension_offset": "a", "distance": "x_p", "width": "d_b"}


def check_named(eid: str, rec, res: dict, rel: float = 0.25) -> None:
    """The identifier (or, for the inseparable pairs, its equivalent), the gain and the magnitude."""
    scores = {k: round(v["score"], 3) for k, v in res["candidates"].items()}
    ok = {eid, *EQUIVALENT.get(eid, ())} if eid.startswith("sensor_gain") else {eid}
    assert res["cause"] in ok, (res["causes"], scores)
    assert res["gain"] >= 0.3, (res["gain"], scores)
    truth = rec.truth["parameters"]
    if eid.startswith("sensor_"):
        name, true = next(iter(truth.items()))
        e = CATALOGUE[res["cause"]]
        if res["cause"] != eid:         # a T_in gain g reads as a T_out gain 1/(1 + g) - 1
            true = 1.0 / (1.0 + true) - 1.0
        p = res["parameters"][e.parameters[0].name]
        assert p["effect"] == res["cause"] and p["value"] == pytest.approx(true, rel=rel), (name, truth)
    for name, true in truth.items():
        if name in FITTED:
            p = res["parameters"][FITTED[name]]
            assert p["effect"] == eid and p["value"] == pytest.approx(true, rel=rel), (name, p, truth)
    prim = res["primary_signal"]
    unit = "N" if prim == "T_out" else "m"
    assert res["extended"][f"rmse_{prim}_{unit}"] < 0.7 * res["base"][f"rmse_{prim}_{unit}"]


@pytest.fixture(scope="module")
def clean_result():
    rec = record(None, seed=21, duration=DUR, rate_hz=RATE)
    return rec, diagnose(rec.data)


@pytest.mark.parametrize("eid", EFFECT_IDS)
def test_hidden_effect_is_named_and_earns_its_gain(eid):
    # magnitude at 87 % of the realistic range; at its low end a short recording may leave a lag or a drift
    # within the floor (answer "none"): the benchmark reports those cases
    rec = record(eid, seed=11, duration=DUR, rate_hz=RATE)
    res = diagnose(rec.data)
    check_named(eid, rec, res)
    assert {k for k, c in res["candidates"].items() if c["accepted"]} == set(res["model"]["effects"])


# the independent lumped-mass simulator: random route of arcs and straight runs, random distal load,
# its own noise and quantisation (seeded; development seeds)
LUMPED = [("sensor_offset:T_in", 101), ("sensor_offset:T_out", 102), ("sensor_lag:T_in", 103),
          ("sensor_drift:T_out", 109), ("sensor_lag:x_in", 105), ("sensor_offset:x_out", 110), ("pretension", 107),
          # velocity friction on a preloaded spring: the base model's route fit (r_1 ~ 0) is a local minimum, so the
          # polished candidates also start from the uniform route; pre-sliding below its smallest travel
          # (PRESLIDING_MIN) cannot explain x_out in its place
          ("velocity_friction", 700111)]


@pytest.mark.parametrize("eid,seed", LUMPED)
def test_lumped_simulator_hidden_effect_is_named_with_its_channel(eid, seed):
    rec = lumped_scenarios.record(eid, seed=seed, duration=DUR, rate_hz=RATE, level=0.7)
    res = diagnose(rec.data)
    check_named(eid, rec, res)


def test_lumped_presliding_is_the_best_candidate_in_its_node_form():
    # per-node pre-sliding (117 um on a constant-force load): the node form, x_p within 25 %. The noise band of the
    # memory rule (NOISE_BAND, a dead zone of 3 sigma of T_in) takes part of its x_out signature, and its score sits
    # near what is accepted there (MID_SCORE): pre-sliding or none
    rec = lumped_scenarios.record("presliding", seed=109, duration=DUR, rate_hz=RATE, level=0.7)
    res = diagnose(rec.data)
    cand = res["candidates"]
    best = min(cand, key=lambda k: cand[k]["score"])
    assert best == "presliding" and cand[best]["score"] < 0.6, {k: round(c["score"], 3) for k, c in cand.items()}
    par = cand["presliding"]["parameters"]
    assert par["x_p"]["value"] == pytest.approx(rec.truth["parameters"]["distance"], rel=0.25), par
    assert par["presliding_form"]["value"] == 1.0
    assert res["cause"] in ("presliding", "none")


@pytest.mark.parametrize("seed", [501, 502])
def test_lumped_simulator_clean_recording_gives_none(seed):
    rec = lumped_scenarios.record(None, seed=seed, duration=DUR, rate_hz=RATE)
    res = diagnose(rec.data)
    assert res["cause"] == "none" and res["causes"] == [], res["structure"]
    assert max(res["structure"]["base"].values()) <= res["settings"]["structure_ratio"]


@pytest.mark.parametrize("seed", [21, 22, 23])
def test_clean_recordings_give_none(seed, clean_result):
    if seed == 21:
        rec, res = clean_result
    else:
        rec = record(None, seed=seed, duration=DUR, rate_hz=RATE)
        res = diagnose(rec.data)
    assert res["cause"] == "none" and res["causes"] == []
    assert res["gain"] == 0.0 and res["extended"] == res["base"]
    assert not any(c["accepted"] for c in res["candidates"].values())
    # the base model explains clean data to its noise floor
    assert res["base"]["rmse_T_out_N"] < 2.0 * res["noise"]["floor_T_out_N"]
    assert res["parameters"]["K"]["value"] == pytest.approx(rec.truth["K"], rel=0.02)
    assert res["parameters"]["compliance"]["value"] == pytest.approx(rec.truth["compliance"], rel=0.02)


def test_structure_no_extension_explains_is_unknown():
    rec = record("load_cell_drift", seed=31, level=1.0, duration=DUR, rate_hz=RATE)
    res = diagnose(rec.data)
    assert res["cause"] == "unknown" and res["causes"][-1] == "unknown"
    assert max(res["structure"]["base"].values()) > 3.0


def test_result_keys_units_and_json(clean_result):
    rec, res = clean_result
    for key in ("cause", "causes", "base", "extended", "gain", "parameters", "candidates", "primary_signal",
                "split", "noise", "structure", "model", "base_model", "settings", "elapsed_s"):
        assert key in res
    assert set(res["base"]) == {"rmse_T_out_N", "rmse_x_out_m"}
    # one of each pair of equivalent effects is fitted (they give the same outputs)
    assert set(res["candidates"]) == set(EFFECT_IDS) - {"sensor_gain:T_out", "sensor_offset:x_out"}
    for c in res["candidates"].values():
        assert {"validation_rmse_T_out_N", "validation_rmse_x_out_m", "score", "penalised_score", "accepted",
                "parameters", "equivalent", "fold_values", "fold_scores", "scored_on"} <= set(c)
        assert 1 <= len(c["fold_scores"]) <= 2 and c["score"] in c["fold_scores"]
    assert res["parameters"]["compliance"]["unit"] == "m/N"
    assert res["candidates"]["sensor_lag:T_in"]["parameters"]["tau_T_in"]["unit"] == "s"
    again = json.loads(json.dumps(res))
    assert again["cause"] == res["cause"]


def test_the_typed_result_writes_and_reads_the_same_json_keys(clean_result):
    from estimator.offline.diagnosis.result import Diagnosis, as_diagnosis
    rec, res = clean_result
    typed = Diagnosis.from_json(res)
    assert typed.cause == res["cause"] and typed.stick_slip.ratio == res["stick_slip"]["ratio"]
    out = typed.to_json()
    assert list(out) == list(res) and out == res
    assert list(out["candidates"]["stiction"]) == list(res["candidates"]["stiction"])
    assert as_diagnosis(typed) is typed
    # a key a caller adds (the file name) travels along, after the documented ones
    assert list(Diagnosis.from_json({**res, "file": "run.csv"}).to_json())[-1] == "file"
    with pytest.raises(KeyError, match="'gain' missing"):
        Diagnosis.from_json({k: v for k, v in res.items() if k != "gain"})


def test_a_route_the_thirds_fit_keeps_the_thirds(clean_result):
    # the rule that refines the route reads structure the thirds leave: on a clean rig recording they leave none,
    # and the route stays as it is
    rec, res = clean_result
    assert max(res["structure"]["base"].values()) <= res["settings"]["weak_structure"]
    assert res["settings"]["route_form"] == "thirds" and "r_3" not in res["parameters"]


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


def test_distal_tension_only_and_distal_position_only():
    rec = record("sensor_offset:T_in", seed=13, duration=DUR, rate_hz=RATE)
    res = diagnose(replace(rec.data, x_out=None))
    assert res["cause"] == "sensor_offset:T_in" and res["gain"] >= 0.3
    assert res["base"]["rmse_x_out_m"] is None and res["primary_signal"] == "T_out"
    rec = record("tendon_stiffening", seed=13, duration=DUR, rate_hz=RATE)
    res = diagnose(replace(rec.data, T_out=None))
    assert res["cause"] == "tendon_stiffening" and res["gain"] >= 0.3
    assert res["base"]["rmse_T_out_N"] is None and res["primary_signal"] == "x_out"


def test_non_finite_samples_are_refused_naming_the_column():
    rec = record(None, seed=21, duration=10.0, rate_hz=RATE)
    T_in = rec.data.T_in.copy()
    T_in[1234:] = np.nan              # e.g. a simulator or logger that failed part-way
    with pytest.raises(DataError, match=r"T_in has \d+ non-finite samples \(first at sample 1234\)"):
        diagnose(replace(rec.data, T_in=T_in))


def test_progress_callback_and_bad_inputs():
    rec = record("sensor_offset:T_in", seed=13, duration=30.0, rate_hz=RATE)
    calls = []
    diagnose(rec.data, progress=lambda done, total, label: calls.append((done, total, label)),
             effects=("sensor_offset:T_in", "friction_offset"))
    assert [c[0] for c in calls] == list(range(1, len(calls) + 1)) and calls[-1][0] == calls[-1][1]
    with pytest.raises(DataError, match="x_out"):
        diagnose(replace(rec.data, x_out=None, T_out=None))
    with pytest.raises(ValueError, match="too few"):
        diagnose(rec.data.slice(0, 200))
    with pytest.raises(ValueError, match="unknown effect"):
        diagnose(rec.data, effects=("backlash",))
    with pytest.raises(ValueError, match="train_fraction"):
        diagnose(rec.data, train_fraction=0.1)


def test_report_writes_markdown_and_figures(clean_result, tmp_path):
    from study.report import format_summary, write_report
    rec, res = clean_result
    path = write_report(res, rec.data, tmp_path / "rep")
    text = path.read_text()
    assert "**none**" in text and "| K |" in text and "| compliance |" in text
    for png in ("residuals_time.png", "residuals_by.png", "loops.png", "candidates.png"):
        assert (tmp_path / "rep" / png).stat().st_size > 10_000 and f"]({png})" in text
    assert format_summary(res).startswith("cause: none")


def test_a_second_effect_is_accepted_when_it_earns_its_place():
    rec = record(("sensor_offset:T_in", "tendon_stiffening"), seed=13, duration=DUR, rate_hz=RATE)
    res = diagnose(rec.data)
    assert set(res["causes"][:2]) == {"sensor_offset:T_in", "tendon_stiffening"}
    assert res["parameters"]["b_T_in"]["value"] == pytest.approx(rec.truth["parameters"]["offset"], rel=0.25)
    assert res["parameters"]["beta"]["value"] == pytest.approx(rec.truth["parameters"]["softening"], rel=0.25)
    # the pair earns both its parameters on the validation folds, and gains on the test block
    assert res["gain"] >= 0.3 and all(res["candidates"][k]["accepted"] for k in res["causes"][:2])


def _rest_then_pull(x_in_rest: float) -> MeasuredData:
    """A 2 s record: 0.5 s at rest (x_in reading ``x_in_rest``, x_out zero), then a pull (noise-free)."""
    t = np.arange(2000) / 1000.0
    ramp = np.clip(t - 0.5, 0.0, None)
    return MeasuredData(time=t, x_in=x_in_rest + 2e-3 * ramp, T_in=1.0 + 5.0 * ramp, x_out=1e-3 * ramp,
                        T_out=1.0 + 3.0 * ramp)


def test_a_position_reading_away_from_zero_at_rest_names_the_offset_not_pretension():
    # pretension fits far better (a loaded rest), but it cannot move the rest reading: an acceptable offset is named;
    # with the rest at zero pretension stays; an offset that is not acceptable (price >= 1) is never named
    price = {"pretension": 0.58, "sensor_offset:x_in": 0.955}
    assert look_alike("pretension", price, _rest_then_pull(-84e-6)) == "sensor_offset:x_in"
    assert look_alike("pretension", price, _rest_then_pull(0.0)) == "pretension"
    assert look_alike("pretension", {**price, "sensor_offset:x_in": 1.02}, _rest_then_pull(-84e-6)) == "pretension"


def test_rest_offset_reads_an_encoder_away_from_zero_at_a_rest_and_nothing_without_a_rest():
    assert diagnosis_readings.rest_offset(_rest_then_pull(0.0)) is None
    assert diagnosis_readings.rest_offset(_rest_then_pull(-84e-6)) == "sensor_offset:x_in"
    d = _rest_then_pull(0.0)
    assert diagnosis_readings.rest_offset(replace(d, x_out=d.x_out + 30e-6)) == "sensor_offset:x_out"
    # a reading within the channel's resolution is no offset: 1 um on an encoder of 1 um steps ...
    q = 1e-6
    coarse = replace(d, x_in=np.round((d.x_in + 1e-6) / q) * q)
    assert diagnosis_readings.rest_offset(coarse) is None
    # ... nor 2 um under 1 um of noise, but 2 um under 0.1 um of noise is
    rng = np.random.default_rng(3)
    for sigma, want in ((1e-6, None), (1e-7, "sensor_offset:x_in")):
        noisy = replace(d, x_in=d.x_in + 2e-6 + sigma * rng.standard_normal(d.x_in.size))
        assert diagnosis_readings.rest_offset(noisy) == want, sigma
    # a recording that starts moving has no rest to be zeroed at
    moving = MeasuredData(time=d.time, x_in=84e-6 + 2e-3 * d.time, T_in=1.0 + 5.0 * d.time, x_out=1e-3 * d.time,
                          T_out=1.0 + 3.0 * d.time)
    assert diagnosis_readings.rest_offset(moving) is None


def test_lumped_x_in_offset_the_models_leave_at_the_floor_is_named_by_the_initial_rest(monkeypatch):
    # a 36 um x_in offset, far from its clean twin in x_in's noise, but the base absorbs it to 1.8 x its floor and the
    # offset's S is 0.41: the models alone say "none". The encoder reads 36 um at the initial rest, where positions
    # are zeroed: the rest reading names it; the clean twin reads zero
    from estimator.offline.diagnosis import selection as diagnosis
    cands = ("sensor_offset:x_in", "tendon_stiffening", "friction_offset")
    rec = lumped_scenarios.record("sensor_offset:x_in", seed=4716102, level=0.2, duration=60.0)
    res = diagnose(rec.data, effects=cands)
    assert res["cause"] == "sensor_offset:x_in", (res["rest_offset"], res["structure"])
    assert res["rest_offset"]["named"] and res["rest_offset"]["reads"] == "sensor_offset:x_in"
    assert res["rest_offset"]["x_in_m"] == pytest.approx(rec.truth["parameters"]["offset"], rel=0.01)
    assert res["parameters"]["b_x_in"]["value"] == pytest.approx(rec.truth["parameters"]["offset"], rel=0.25)
    from study.report import format_summary
    assert "named by the initial rest: x_in reads 36" in format_summary(res)
    twin = diagnose(lumped_scenarios.record(None, seed=4716102, level=0.2, duration=60.0).data, effects=cands)
    assert twin["cause"] == "none" and twin["rest_offset"]["reads"] is None and not twin["rest_offset"]["named"]
    assert "initial rest" not in format_summary(twin)
    # without the reading the models alone leave it at "none"
    monkeypatch.setattr(diagnosis, "rest_offset", lambda data: None)
    assert diagnose(rec.data, effects=cands)["causes"] == []


def test_stiffening_or_backlash_is_named_by_the_better_score_unless_the_toe_is_a_dead_travel():
    # both acceptable: the better validation score names the cause (not the ranking's factor per parameter); a toe
    # at beta's upper bound or at the lower end of T_c is a dead travel, a backlash
    price = {"tendon_stiffening": 0.64, "distal_backlash": 0.36}
    toe = {"beta": 3.6, "T_c": 1.5}
    fits = {"tendon_stiffening": (0.038, toe), "distal_backlash": (0.061, {"d_b": 4e-4})}
    assert toe_or_play("distal_backlash", fits, price) == "tendon_stiffening"
    fits["distal_backlash"] = (0.031, {"d_b": 2e-4})
    assert toe_or_play("tendon_stiffening", fits, price) == "distal_backlash"
    fits["tendon_stiffening"] = (0.010, {"beta": 20.0, "T_c": 0.078})
    assert toe_or_play("tendon_stiffening", fits, price) == "distal_backlash"
    # not both acceptable, or another effect best: unchanged
    assert toe_or_play("tendon_stiffening", fits, {**price, "distal_backlash": 1.05}) == "tendon_stiffening"
    assert toe_or_play("sensor_offset:x_in", fits, price) == "sensor_offset:x_in"


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


def test_lumped_backlash_that_bent_the_base_route_into_a_corner_is_named_alone():
    # a 250 um backlash bends the base route to r_1 = r_2 = 0; refitted from there the backlash leaves structure,
    # refitted from the uniform route it takes its full width and leaves nothing
    rec = lumped_scenarios.record("distal_backlash", seed=707110, level=0.8, duration=60.0)
    res = diagnose(rec.data, effects=("distal_backlash", "pretension", "sensor_offset:x_in"))
    assert res["causes"] == ["distal_backlash"], (res["structure"],
                                                  {k: c["score"] for k, c in res["candidates"].items()})
    assert res["parameters"]["d_b"]["value"] == pytest.approx(250e-6, rel=0.05)


def test_lumped_pretension_a_constant_force_load_cannot_hold_is_named():
    # 4.2 N of preload against a 2.6 N constant-force load: at rest T_in reads 4.2 N and T_out 2.6 N (the distal part
    # slid back); the initial profile capped by the rest reading of T_out fits it, a uniform one would leave x_out off
    rec = lumped_scenarios.record("pretension", seed=701110, level=0.8, duration=60.0)
    res = diagnose(rec.data, effects=("pretension", "sensor_offset:x_in", "distal_backlash"))
    assert res["causes"] == ["pretension"], (res["structure"], {k: c["score"] for k, c in res["candidates"].items()})
    # a rest reading above the preload (a constant-force load on its stop, 1.8 N at both ends)
    # leaves the uniform profile: a profile rising toward the distal end fitted T0 = 0.65 N there
    rec = lumped_scenarios.record("pretension", seed=601100, level=0.2, duration=60.0)
    res = diagnose(rec.data, effects=("pretension", "sensor_offset:x_in", "distal_backlash"))
    assert res["causes"] == ["pretension"], (res["structure"], {k: c["score"] for k, c in res["candidates"].items()})


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


def test_a_recording_with_x_out_alone_is_judged_against_clean_recordings_made_that_way():
    # clean, a constant-force load: with T_out it is "none"; with x_out alone nothing pins K and a distal backlash of
    # ~50 um fits the base's dead zone at S 0.08 (under STRONG_SCORE). The bounds of clean x_out-only recordings
    # (FLOOR_SCORE_WITHOUT) apply
    rec = lumped_scenarios.record(None, seed=3700501, duration=60.0)
    fx = ("distal_backlash", "presliding", "sensor_offset:x_in")
    alone = replace(rec.data, T_out=None)
    res = diagnose(alone, effects=fx)
    assert res["causes"] == [] and res["settings"]["recorded"] == ["x_out"]
    assert res["candidates"]["distal_backlash"]["score"] < STRONG_SCORE
    assert res["settings"]["floor_score_without"] == FLOOR_SCORE_WITHOUT["T_out"]
    # told that T_out was recorded (set aside by the caller), the two-channel bounds apply and the backlash is named
    told = diagnose(alone, effects=fx, recorded=("T_out", "x_out"))
    assert told["causes"] == ["distal_backlash"] and told["settings"]["floor_score_without"] == {}
    with pytest.raises(ValueError, match="recorded must be distal channels"):
        diagnose(alone, effects=fx, recorded=("T_out",))
    # clean: a distal backlash at S 0.11 on a base at 1.9 x its floor removes B (1 - S) = 3.2
    # squared floors, over the two-channel EXCESS_MIN but not over the x_out-alone one (clean recordings reach 3.3)
    rec = lumped_scenarios.record(None, seed=1100784, duration=60.0)
    alone = replace(rec.data, T_out=None)
    res = diagnose(alone, effects=fx)
    assert res["causes"] == [] and res["settings"]["excess_min_applied"] == EXCESS_MIN_WITHOUT["T_out"]
    S = res["candidates"]["distal_backlash"]["score"]
    assert FLOOR_SCORE_WITHOUT["T_out"]["distal_backlash"] < S < STRONG_SCORE
    told = diagnose(alone, effects=fx, recorded=("T_out", "x_out"))
    assert told["causes"] == ["distal_backlash"] and told["settings"]["excess_min_applied"] == EXCESS_MIN


def test_an_extension_also_starts_from_a_typical_K_when_the_base_collapsed_to_zero(clean_result):
    # a 4.2 N pretension drives the base model to K = 0, where the noise band of the memory rule leaves K without a
    # gradient: the extension also starts from a typical K (K_RESTART)
    s = prepare(clean_result[0].data)
    pre = CATALOGUE["pretension"]
    assert [p["K"] for p in start_points([pre], {"K": 0.0}, s, {})] == [0.0, K_RESTART]
    assert [p["K"] for p in start_points([pre], {"K": 0.9}, s, {})] == [0.9]


def test_a_proximal_offset_also_starts_from_the_rest_reading(clean_result):
    # a -0.84 N T_in offset on a joint load lies beyond the +-0.5 N starts; the reading at rest before the first move
    # (a slack tendon) is the offset, and the fit starts from it too
    s = prepare(clean_result[0].data)
    off = CATALOGUE["sensor_offset:T_in"]
    assert [p["b_T_in"] for p in start_points([off], {"K": 0.9}, s, {})] == [-0.5, 0.5]
    shifted = replace(s, T_in=s.T_in - 0.84)
    starts = [p["b_T_in"] for p in start_points([off], {"K": 0.9}, shifted, {})]
    assert starts[:2] == [-0.5, 0.5] and len(starts) == 3 and abs(starts[2] + 0.84) < 0.05
    rec = lumped_scenarios.record("sensor_offset:T_in", seed=1208111, level=0.8, duration=60.0)
    res = diagnose(rec.data, effects=("sensor_offset:T_in", "sensor_lag:x_in"))
    b = res["candidates"]["sensor_offset:T_in"]["parameters"]["b_T_in"]["value"]
    assert res["causes"] == ["sensor_offset:T_in"] and b == pytest.approx(-0.84, rel=0.05), res["causes"]


def test_an_encoder_offset_starts_from_the_rest_reading_and_its_route_refit_too(clean_result):
    # an 84 um x_out offset on a constant-force load pressing its stop at rest bends the base route to r_1, r_2 < 0.01,
    # and from the +-50 um starts on that route the fit stops halfway. x_out - x_in read at the initial rest is the
    # offset; the fit and its route-free refit (from the uniform route) start from it
    s = prepare(clean_result[0].data)
    assert [p["b_x_out"] for p in start_points([CATALOGUE["sensor_offset:x_out"]], {"K": 0.9}, s, {})] == [-5e-5, 5e-5]
    shifted = replace(s, x_out=s.x_out + 84e-6)
    first = slice(0, 10)
    assert rest_start("b_x_out", shifted, first) == pytest.approx(84e-6, abs=3e-6)
    assert rest_start("b_x_in", shifted, first) == pytest.approx(-84e-6, abs=3e-6)
    assert math.isnan(rest_start("b_x_out", replace(s, x_out=None), first))
    starts = [p["b_x_in"] for p in start_points([CATALOGUE["sensor_offset:x_in"]], {"K": 0.9}, shifted, {})]
    assert starts[:2] == [-5e-5, 5e-5] and len(starts) == 3 and starts[2] == pytest.approx(-84e-6, abs=3e-6)
    rec = lumped_scenarios.record("sensor_offset:x_out", seed=1417111, level=0.8, duration=60.0)
    res = diagnose(rec.data, effects=("sensor_offset:x_in", "distal_backlash", "curvature_drift"))
    assert res["causes"][0] == "sensor_offset:x_out", (res["causes"],
                                                       {k: c["score"] for k, c in res["candidates"].items()})
    assert res["candidates"]["sensor_offset:x_in"]["score"] < 0.2


def test_a_fit_stuck_on_the_edge_of_a_step_in_K_refits_the_rest_with_K_held():
    # a 250 um distal backlash on a constant-force load leaves the base's K on the edge of a step in the residual, so
    # every trial step of the route-free refit fails and least_squares ends where it started; the others are refitted
    # with K held, then all from there
    rec = lumped_scenarios.record("distal_backlash", seed=1407110, level=0.8, duration=60.0)
    res = diagnose(rec.data, effects=("distal_backlash", "sensor_offset:x_in", "pretension"))
    assert res["causes"] == ["distal_backlash"], (res["causes"], {k: c["score"] for k, c in res["candidates"].items()})
    assert res["candidates"]["distal_backlash"]["score"] < 0.05
    assert res["parameters"]["d_b"]["value"] == pytest.approx(rec.truth["parameters"]["width"], rel=0.25)


def test_a_refinement_retried_with_K_held_is_not_kept_at_a_bound(monkeypatch):
    # a 1.3 N friction offset; the retry with K held can let a T_in gain run to its -0.5 bound and displace the
    # friction offset, so the retry is kept only inside the bounds. Shown on the memory-only base (SLIDE_SEEN off):
    # with the distal end read the friction offset explains the recording far better anyway
    rec = lumped_scenarios.record("friction_offset", seed=1305113, level=0.8, duration=60.0)
    res = diagnose(rec.data, effects=("friction_offset", "sensor_gain:T_in"))
    assert res["causes"] == ["friction_offset"], (res["causes"], {k: c["score"] for k, c in res["candidates"].items()})
    assert res["candidates"]["friction_offset"]["score"] < 0.01
    monkeypatch.setattr(th, "SLIDE_SEEN", False)
    res = diagnose(rec.data, effects=("friction_offset", "sensor_gain:T_in"))
    assert res["causes"][0] == "friction_offset", (res["causes"], {k: c["score"] for k, c in res["candidates"].items()})
    g = res["candidates"]["sensor_gain:T_in"]["parameters"]["g_T_in"]["value"]
    assert -0.49 < g < 0.49


def test_a_route_bent_by_a_pretension_is_refitted_when_no_polished_extension_explains_the_structure():
    # a 1.8 N pretension on a constant-force load bends the base route to r_2 = 0; on that route the pretension scores
    # above 1 and is not among the best three refitted with the route free. When none of the refitted ones brings the
    # structure under the threshold, every candidate gets its route refit
    rec = lumped_scenarios.record("pretension", seed=1301102, level=0.2, duration=60.0)
    res = diagnose(rec.data, effects=("sensor_offset:x_in", "distal_backlash", "sensor_drift:T_in",
                                      "velocity_friction", "pretension"))
    assert res["causes"] == ["pretension"], (res["structure"], {k: c["score"] for k, c in res["candidates"].items()})
    assert res["parameters"]["T0"]["value"] == pytest.approx(1.8, rel=0.05)
    assert res["candidates"]["pretension"]["score"] < 0.05
    # x_out moves: nothing set aside (the second round's held settings once overwrote this field, and
    # `teleop analyze` then read a {"velocity_form": ...} as a held distal end)
    assert res["settings"]["distal_end_held"] is None


def test_lumped_friction_offset_holding_a_slack_tendon_is_named():
    # a 1.1 N friction offset holds a 1.3 N constant-force load while the proximal end pays out 3 mm at zero tension:
    # the distal end stays. The slack ends when the paid-out length is taken up or a tension is held, not on one
    # noise sample of T_in above the slack threshold
    rec = lumped_scenarios.record("friction_offset", seed=805110, level=0.8, duration=60.0)
    res = diagnose(rec.data, effects=("friction_offset", "sensor_offset:T_out", "sensor_lag:x_in"))
    assert res["causes"] == ["friction_offset"], (res["structure"],
                                                  {k: c["score"] for k, c in res["candidates"].items()})
    assert res["parameters"]["a"]["value"] == pytest.approx(rec.truth["parameters"]["tension_offset"], rel=0.1)
    assert res["gain"] > 0.5


def test_lumped_clean_single_arc_route_takes_the_finer_route_and_gives_none():
    # one arc of 6.6 rad over 22 % of a 1.37 m sheath (33-55 % of its length), a preloaded spring: on thirds the wrap
    # spreads uniformly over the middle third and the elongation at reversals is 10-20 um off (x_out 5 x the floor).
    # The sixths put 90 % of the wrap in the third sixth and the residual is at the floor
    rec = lumped_scenarios.record(None, seed=900500, duration=60.0)
    res = diagnose(rec.data, effects=("tendon_stiffening", "friction_offset", "sensor_offset:x_in"))
    assert res["causes"] == [], (res["structure"], {k: c["score"] for k, c in res["candidates"].items()})
    assert res["settings"]["route_form"] == "sixths"
    assert max(res["structure"]["base"].values()) <= res["settings"]["structure_ratio"]
    third_sixth = res["parameters"]["r_3"]["value"] * (1.0 - res["parameters"]["r_1"]["value"]) \
        * (1.0 - res["parameters"]["r_2"]["value"])
    assert third_sixth > 0.6


def test_lumped_clean_route_of_two_short_arcs_takes_the_twelfths_and_gives_none():
    # two arcs of 5.0 and 7.6 rad over 13 and 11 % of a 1.63 m sheath (at 25-38 % and 64-75 % of its length), a
    # spring: the thirds leave x_out at 3.8 x the floor and the sixths fitted on one fold's block misplace the arcs.
    # The twelfths put the wrap where the arcs are
    rec = lumped_scenarios.record(None, seed=1517111, duration=60.0)
    res = diagnose(rec.data, effects=("distal_backlash", "sensor_offset:x_in", "sensor_drift:T_out"))
    assert res["causes"] == [], (res["structure"], {k: c["score"] for k, c in res["candidates"].items()})
    assert res["settings"]["route_form"] == "twelfths"
    assert max(res["structure"]["base"].values()) <= res["settings"]["structure_ratio"]
    u = route_shape(13, *(res["parameters"][f"r_{k}"]["value"] for k in range(1, 12)))
    # the true wrap at the twelfths' knots: 0 up to 25 %, 0.40 from 38 % to 64 %, 1 from 75 %
    assert u[2] < 0.1 and 0.3 < u[6] < 0.5 and u[7] < 0.5 and u[10] > 0.9


def test_an_effect_that_leaves_structure_on_the_thirds_is_refitted_on_the_finer_routes():
    # a T_in drift of 4.8 mN/s on a joint load, the wrap in one arc at 42-71 % of the sheath: the base, bent by the
    # drift, keeps the thirds; on them the drift, route free, leaves x_out above the threshold. On the finer routes
    # it explains both signals, scored against the finer route without an effect (which alone does not help)
    rec = lumped_scenarios.record("sensor_drift:T_in", seed=1514101, level=0.2, duration=60.0)
    res = diagnose(rec.data, effects=("sensor_drift:T_in", "sensor_offset:T_in", "presliding"))
    assert res["causes"] == ["sensor_drift:T_in"], (res["structure"],
                                                    {k: c["score"] for k, c in res["candidates"].items()})
    assert res["settings"]["route_form"] == "thirds" and res["settings"]["model_route_form"] in ("sixths", "twelfths")
    assert res["parameters"]["d_T_in"]["value"] == pytest.approx(rec.truth["parameters"]["rate"], rel=0.25)
    assert max(res["structure"]["extended"].values()) <= res["settings"]["structure_ratio"]
    assert res["gain"] >= 0.3


def test_a_distal_end_held_on_its_stop_sets_x_out_aside_and_gives_none():
    # a preloaded spring that T_out (at most 2.5 N) never lifts off its stop (preload 2.8 N): x_out stays within one
    # 1.2 um quantum while x_in travels 0.36 mm. Fitting that x_out would bend K and let a play "explain" the standing
    # distal end: it is set aside
    rec = lumped_scenarios.record(None, seed=1019112, duration=60.0)
    res = diagnose(rec.data, effects=("distal_backlash", "friction_offset", "sensor_offset:T_in"))
    held = res["settings"]["distal_end_held"]
    assert held is not None and held["range_m"] < 0.01 * held["travel_m"]
    assert res["causes"] == [], (res["structure"], {k: c["score"] for k, c in res["candidates"].items()})
    assert set(res["structure"]["base"]) == {"T_out"} and res["base"]["rmse_x_out_m"] is None
    assert "distal_backlash" not in res["candidates"]
    assert res["parameters"]["K"]["value"] == pytest.approx(rec.truth["K"], rel=0.05)
    assert predictions(res, rec.data)["x_out_base"] is None


def test_a_distal_end_pressed_on_its_stop_by_a_pretension_names_the_pretension():
    # a 4.2 N pretension holds a 125 N/m joint on its 1 mm stop from the start; x_out moves 8 um (1.4 % of x_in's
    # 0.59 mm travel), the stop's deflection and the tendon's pre-sliding. The pretension (on the finer route)
    # explains both signals with x_out kept; were structure left with x_out and none without, x_out would be set
    # aside as pressed (NEAR_HELD_SHARE)
    rec = lumped_scenarios.record("pretension", seed=1301113, level=0.8, duration=60.0)
    res = diagnose(rec.data, effects=("pretension", "distal_backlash", "sensor_offset:x_in", "sensor_lag:T_in"))
    assert res["causes"] == ["pretension"], (res["structure"], {k: c["score"] for k, c in res["candidates"].items()})
    assert res["parameters"]["T0"]["value"] == pytest.approx(4.2, rel=0.05)
    assert res["parameters"]["K"]["value"] == pytest.approx(rec.truth["K"], rel=0.03)
    held = res["settings"]["distal_end_held"]
    if held is None:
        assert max(res["structure"]["extended"].values()) <= res["settings"]["structure_ratio"]
    else:       # set aside only as a pressed stop, within 1-5 % of the travel
        assert held["pressed"] and 0.01 * held["travel_m"] < held["range_m"] < 0.05 * held["travel_m"]


def test_distal_end_held_only_when_x_out_stands_within_its_resolution():
    from dataclasses import replace

    from estimator.offline.diagnosis.readings import distal_end_held
    from estimator.offline.diagnosis.thresholds import HELD_STEPS, NEAR_HELD_SHARE
    rec = record(None, seed=21, duration=DUR, rate_hz=RATE)
    assert distal_end_held(rec.data) is None                               # a moving distal end
    q = 1e-6
    n = len(rec.data)
    still = np.round(np.random.default_rng(3).normal(0.0, 0.3e-6, n) / q) * q   # toggles by one quantum
    held = distal_end_held(replace(rec.data, x_out=still))
    assert held is not None and held["step_m"] == pytest.approx(q) and held["range_m"] <= HELD_STEPS * q
    # a 40 um wander over the recording is motion (20 % of a 0.4 mm travel is far beyond the resolution) ...
    moving = still + 40e-6 * np.sin(np.linspace(0.0, 6.0, n))
    assert distal_end_held(replace(rec.data, x_out=moving, x_in=np.linspace(0.0, 4e-4, n))) is None
    # ... 12 um (3 %) is not held, but barely moving (a distal end pressed on a stop: NEAR_HELD_SHARE)
    pressed = replace(rec.data, x_out=still + 6e-6 * np.sin(np.linspace(0.0, 6.0, n)), x_in=np.linspace(0.0, 4e-4, n))
    assert distal_end_held(pressed) is None and distal_end_held(pressed, NEAR_HELD_SHARE) is not None
    assert distal_end_held(replace(rec.data, x_out=None)) is None


def test_distal_at_end_reads_how_much_of_the_proximal_travel_the_distal_end_sits_on_a_stop():
    from estimator.offline.diagnosis.readings import distal_at_end
    from estimator.offline.diagnosis.thresholds import AT_END_HIDES, AT_END_SHARE
    rec = record(None, seed=21, duration=DUR, rate_hz=RATE)
    moving = distal_at_end(rec.data)
    assert moving is not None and moving["share"] < 0.3 and moving["hides"] == []
    # the same distal end with a stop 4 um above the 5th percentile of its travel: the tendon pulls it onto the stop
    # and holds it there for nearly all of the proximal travel
    x_stop = float(np.percentile(rec.data.x_out, 5.0)) + 4e-6
    stopped = distal_at_end(replace(rec.data, x_out=np.minimum(rec.data.x_out, x_stop)))
    assert stopped is not None and stopped["share"] >= AT_END_SHARE and stopped["hides"] == list(AT_END_HIDES)
    assert stopped["share"] > moving["share"] + 0.5
    assert distal_at_end(replace(rec.data, x_out=None)) is None
    assert distal_at_end(replace(rec.data, x_in=np.zeros(len(rec.data)))) is None    # no proximal travel
    with pytest.raises(ValueError, match="7 needed"):
        distal_at_end(rec.data.slice(0, 5))


def test_a_joint_held_on_its_stop_is_reported_as_unable_to_show_a_lag_of_x_out():
    # a 42 ms x_out lag on a joint driven onto its stop in the first second and held there: the lag's footprint is
    # that one rise, which no validation block holds. The reading says so, and the printed summary
    from study.analyze import format_diagnosis
    rec = lumped_scenarios.record("sensor_lag:x_out", seed=3919112, level=0.8, duration=60.0)
    assert rec.truth["load"]["kind"] == "joint"
    res = diagnose(rec.data, effects=("sensor_lag:x_out", "sensor_offset:x_out"))
    at_end = res["settings"]["distal_at_end"]
    assert at_end["share"] >= 0.9 and at_end["hides"] == ["sensor_lag:x_out"]
    res.update({"file": "joint.csv", "n_samples": len(rec.data), "duration_s": rec.data.duration})
    text = format_diagnosis(res)
    assert "sensor_lag:x_out cannot show in this recording" in text and f"{100 * at_end['share']:.0f} %" in text
    # the same lag where the distal end moves (a spring) is named, and nothing is said
    rec = lumped_scenarios.record("sensor_lag:x_out", seed=3919101, level=0.2, duration=60.0)
    res = diagnose(rec.data, effects=("sensor_lag:x_out", "sensor_offset:x_out"))
    assert res["settings"]["distal_at_end"]["hides"] == [] and res["causes"] == ["sensor_lag:x_out"]


def test_a_tension_offset_below_twice_the_floor_is_not_resolved():
    from estimator.offline.diagnosis.folds import unresolved as _unresolved
    from estimator.offline.diagnosis.thresholds import OFFSET_FLOORS
    floor = {"T_out": 0.03, "x_out": 2e-6}
    fo, tin, tout = (CATALOGUE[e] for e in ("friction_offset", "sensor_offset:T_in", "sensor_offset:T_out"))
    # F0 = a (1 - e^-K) at the tip: a = 0.07 N on K = 1.39 is 0.052 N < 2 x 0.03 N (a constant-force twin's)
    assert _unresolved([fo], {"K": 1.39, "a": 0.07}, floor)
    assert not _unresolved([fo], {"K": 1.39, "a": 0.467}, floor)               # a hidden one: F0 0.35 N
    assert _unresolved([tin], {"K": 0.8, "b_T_in": -0.018}, floor)
    assert not _unresolved([tout], {"K": 0.8, "b_T_out": OFFSET_FLOORS * 0.031}, floor)
    # other effects, and a recording without T_out, are not judged by it
    assert not _unresolved([CATALOGUE["velocity_friction"]], {"K": 1.0, "c_v": 1.0}, floor)
    assert not _unresolved([fo], {"K": 1.39, "a": 0.07}, {"x_out": 2e-6})
    # nor an offset that removes nearly all of a clear structure: its size is a pattern's
    assert not _unresolved([fo], {"K": 1.39, "a": 0.07}, floor, dominant=True)
    assert _unresolved([CATALOGUE["presliding"]], {"K": 1.0, "x_p": 20e-6}, floor, dominant=True)


def test_lumped_small_friction_offset_that_removes_the_structure_is_named_not_a_gain():
    # a friction offset on a constant force (K 1.39); the base leaves 5 x the T_out floor and the friction offset
    # removes 99 % of it (S 0.01), though F0 = 0.26 N sits just under twice the carried T_out floor: an offset that
    # removes nearly all of a clear structure is resolved by that pattern, and a T_in gain does not take its place
    rec = lumped_scenarios.record("friction_offset", seed=4705100, level=0.2, duration=60.0)
    res = diagnose(rec.data, effects=("friction_offset", "sensor_gain:T_in", "sensor_offset:T_out"))
    assert res["causes"] == ["friction_offset"], ({k: c["score"] for k, c in res["candidates"].items()})
    assert res["candidates"]["friction_offset"]["score"] < 0.1 and res["gain"] > 0.5
    twin = diagnose(lumped_scenarios.record(None, seed=4705100, level=0.2, duration=60.0).data,
                    effects=("friction_offset", "sensor_gain:T_in", "sensor_offset:T_out"))
    assert twin["causes"] == []


def test_lumped_clean_constant_force_load_gives_none_not_a_small_offset():
    # a clean constant-force load (3.5 N, K 0.81): a friction offset of a = 0.05 N (F0 1.4 x the T_out floor) or a
    # T_in offset of 0.018 N fits the noise; below OFFSET_FLOORS x the floor they are not resolved
    rec = lumped_scenarios.record(None, seed=1017111, duration=60.0)
    res = diagnose(rec.data, effects=("friction_offset", "sensor_offset:T_in", "sensor_offset:T_out"))
    assert res["causes"] == [], ({k: (c["score"], c["parameters"]) for k, c in res["candidates"].items()})


def test_an_effect_near_the_floor_that_removes_enough_of_the_base_structure_is_named(monkeypatch):
    # pre-sliding of 128 um on a preloaded spring. With the distal end read the recording is far from the floor (its
    # distal end moves before the memory's slip reaches it). On the memory-only base (SLIDE_SEEN off) the base leaves
    # 1.9 / 2.0 x the floor on T_out / x_out and pre-sliding explains 61 % of it (S 0.39, above STRONG_SCORE):
    # B (1 - S) = 4.5 squared floors is above EXCESS_MIN, so it is named
    rec = lumped_scenarios.record("presliding", seed=1406112, level=0.8, duration=60.0)
    res = diagnose(rec.data, effects=("presliding", "distal_backlash", "sensor_lag:T_in"))
    assert res["causes"] == ["presliding"]
    assert max(res["structure"]["base"].values()) > 10.0 * res["settings"]["structure_ratio"]
    monkeypatch.setattr(th, "SLIDE_SEEN", False)
    res = diagnose(rec.data, effects=("presliding", "distal_backlash", "sensor_lag:T_in"))
    assert res["causes"] == ["presliding"], (res["structure"], {k: c["score"] for k, c in res["candidates"].items()})
    base = res["structure"]["base"]
    assert max(base.values()) <= res["settings"]["weak_structure"]
    s = res["candidates"]["presliding"]["score"]
    assert s > res["settings"]["strong_score"]                  # the old rule alone would say "none"
    assert sum(v * v for v in base.values()) * (1.0 - s) >= res["settings"]["excess_min"]
    assert res["parameters"]["x_p"]["value"] == pytest.approx(rec.truth["parameters"]["distance"], rel=0.25)


def test_a_clean_recording_whose_best_extension_removes_less_than_the_excess_bound_gives_none(monkeypatch):
    # a clean constant-force load: on the memory-only base (SLIDE_SEEN off) stiction reaches S 0.47 on a base
    # structure of 1.97, B (1 - S) = 2.65, under EXCESS_MIN: "none". With the distal end read stiction explains none
    # of it
    rec = lumped_scenarios.record(None, seed=1704102, level=0.2, duration=60.0)
    res = diagnose(rec.data, effects=("stiction", "distal_backlash", "sensor_drift:T_out"))
    assert res["causes"] == []
    monkeypatch.setattr(th, "SLIDE_SEEN", False)
    res = diagnose(rec.data, effects=("stiction", "distal_backlash", "sensor_drift:T_out"))
    assert res["causes"] == [], (res["structure"], {k: c["score"] for k, c in res["candidates"].items()})
    base = res["structure"]["base"]
    s = res["candidates"]["stiction"]["score"]
    assert 2.5 < sum(v * v for v in base.values()) * (1.0 - s) < res["settings"]["excess_min"]


def test_a_distal_load_cell_gain_on_a_constant_force_load_is_named_once_the_distal_end_says_it_slides():
    # a -8.6 % T_out gain on a 5.8 N constant-force load. The true release sits at T_in = F e^-K, on the edge of the
    # band; the memory alone would hold the pulled T_out there for any K that is too large, and a K too large would
    # absorb the gain. The distal end moving with the proximal one says the tendon slides, and the release pins K
    rec = lumped_scenarios.record("sensor_gain:T_out", seed=2011110, level=0.8, duration=60.0)
    res = diagnose(rec.data, effects=("sensor_gain:T_out", "sensor_offset:T_out", "sensor_offset:T_in"))
    assert res["cause"] == "sensor_gain:T_out", (res["structure"],
                                                 {k: c["score"] for k, c in res["candidates"].items()})
    assert res["structure"]["base"]["T_out"] > 3.0 * res["settings"]["structure_ratio"]
    assert res["parameters"]["g_T_out"]["value"] == pytest.approx(rec.truth["parameters"]["gain"], rel=0.25)
    assert res["parameters"]["K"]["value"] == pytest.approx(rec.truth["K"], rel=0.05)
    assert res["gain"] > 0.5
    # the distal end's resolution used: 2 quanta of the encoder here (1.6 um), the JSON says so
    assert res["settings"]["distal_slide_travel_m"] == pytest.approx(2.0 * rec.truth["quantum_x_out"], rel=0.05)
    no_x = diagnose(replace(rec.data, x_out=None), effects=("sensor_gain:T_out",))
    assert no_x["settings"]["distal_slide_travel_m"] == 0.0


def test_floor_scores_bound_each_effect_below_its_lowest_clean_score():
    from estimator.offline.diagnosis.thresholds import FLOOR_FACTOR, MID_SCORE, floor_scores
    clean = [{"sensor_lag:T_out": 0.9, "stiction": 0.6}, {"sensor_lag:T_out": 0.8, "stiction": 0.43}]
    got = floor_scores(clean)
    assert got == {"sensor_lag:T_out": pytest.approx(min(MID_SCORE, FLOOR_FACTOR * 0.8)),
                   "stiction": pytest.approx(FLOOR_FACTOR * 0.43)}
    assert floor_scores(clean, factor=1.0, cap=math.inf)["stiction"] == 0.43
    with pytest.raises(ValueError, match="at least one clean recording"):
        floor_scores([])
    with pytest.raises(ValueError, match=r"recording 2: score of stiction is nan"):
        floor_scores([{"stiction": 0.5}, {"stiction": float("nan")}])
    with pytest.raises(ValueError, match="factor"):
        floor_scores(clean, factor=0.0)


def test_the_floor_table_holds_every_catalogue_candidate_below_the_price():
    # every bound lies between STRONG_SCORE's reach and the price of one parameter: the table can only add names
    # at the floor, never accept what the price refuses
    from estimator.offline.diagnosis.thresholds import FLOOR_SCORE, MID_SCORE, PENALTY
    assert set(FLOOR_SCORE) <= set(CATALOGUE)
    assert all(0.0 < v <= min(MID_SCORE, 1.0 - PENALTY) for v in FLOOR_SCORE.values())


def test_a_lag_at_the_floor_is_named_by_its_own_clean_bound(monkeypatch):
    # an 18 ms lag on the distal load cell of a spring load. The base leaves 1.06 x the floor and the lag explains
    # 72 % of it (S 0.28): above STRONG_SCORE and B (1 - S) under EXCESS_MIN, but a T_out lag never scores that low
    # on a clean recording at the floor: its own bound (FLOOR_SCORE) names it; without the table it is "none"
    rec = lumped_scenarios.record("sensor_lag:T_out", seed=2313103, level=0.2, duration=60.0)
    cands = ("sensor_lag:T_out", "tendon_stiffening", "sensor_offset:x_in")
    res = diagnose(rec.data, effects=cands)
    assert res["cause"] == "sensor_lag:T_out", (res["structure"], {k: c["score"] for k, c in res["candidates"].items()})
    base = res["structure"]["base"]
    s = res["candidates"]["sensor_lag:T_out"]["score"]
    assert max(base.values()) <= res["settings"]["structure_ratio"]
    assert res["settings"]["strong_score"] < s < res["settings"]["floor_score"]["sensor_lag:T_out"]
    assert sum(v * v for v in base.values()) * (1.0 - s) < res["settings"]["excess_min"]
    assert res["parameters"]["tau_T_out"]["value"] == pytest.approx(rec.truth["parameters"]["delay"], rel=0.25)
    monkeypatch.setattr(th, "FLOOR_SCORE", {})
    assert diagnose(rec.data, effects=cands)["causes"] == []


def _moves_and_holds(rate=500.0, seed=0, chatter=0.0):
    """Trapezoid moves (5 mm/s) between holds, T_in following the travel, white load-cell noise of 20 mN; with
    ``chatter`` a saw-tooth of that amplitude [N] at 60 Hz on T_in while the proximal end moves."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 40.0, 1.0 / rate)
    phase = t % 4.0
    v = np.where(phase < 1.0, 5e-3, np.where((phase >= 2.0) & (phase < 3.0), -5e-3, 0.0))
    x = np.cumsum(v) / rate
    T = 1.0 + 800.0 * x + 0.02 * rng.standard_normal(t.size)
    if chatter:
        T = T + chatter * np.where(v != 0.0, (t * 60.0) % 1.0 - 0.5, 0.0)
    return t, x, T


def test_stick_slip_ratio_is_about_one_for_sensor_noise_and_large_for_a_saw_tooth():
    from estimator.offline.diagnosis.thresholds import STICK_SLIP_RATIO
    for rate in (200.0, 1000.0):
        t, x, T = _moves_and_holds(rate)
        assert 0.8 < diagnosis_readings.stick_slip_ratio(t, x, T) < 1.2
        t, x, T = _moves_and_holds(rate, chatter=0.15)
        assert diagnosis_readings.stick_slip_ratio(t, x, T) > STICK_SLIP_RATIO
    # holds only: nothing to compare
    assert diagnosis_readings.stick_slip_ratio(t, np.zeros_like(t), T) is None
    with pytest.raises(ValueError, match="differ in length"):
        diagnosis_readings.stick_slip_ratio(t, x[:-1], T)


def test_lumped_stick_slip_the_models_leave_at_the_floor_names_stiction(monkeypatch):
    # a Stribeck peak of 0.51 on a preloaded spring: the tendon sticks and slips on the slow moves, which no
    # quasi-static extension reproduces (the models alone say "none"). On the training block the proximal tension is
    # 1.8 x rougher in steady moves than in holds; on its clean twin about 1
    cands = ("stiction", "velocity_friction", "friction_offset")
    rec = lumped_scenarios.record("stiction", seed=2504111, level=0.8, duration=60.0)
    res = diagnose(rec.data, effects=cands)
    assert res["cause"] == "stiction", (res["stick_slip"], res["structure"])
    assert res["stick_slip"]["named"] and res["stick_slip"]["ratio"] >= res["settings"]["stick_slip_ratio"]
    assert res["stick_slip"]["samples"] == res["split"]["train"]
    from study.report import format_summary
    assert "stick-slip check" in format_summary(res)
    twin = lumped_scenarios.record(None, seed=2504111, level=0.8, duration=60.0)
    res_twin = diagnose(twin.data, effects=cands)
    assert res_twin["cause"] == "none" and res_twin["stick_slip"]["ratio"] < 1.2
    assert "stick-slip" not in format_summary(res_twin)
    # without the check (either rule) the models alone leave it at "none"
    monkeypatch.setattr(th, "STICK_SLIP_RATIO", math.inf)
    monkeypatch.setattr(th, "STICK_SLIP_WEAK", math.inf)
    assert diagnose(rec.data, effects=cands)["causes"] == []


def test_weak_stick_slip_with_a_stiction_fit_that_explains_a_tenth_names_stiction(monkeypatch):
    # a Stribeck peak of 0.51 on a soft joint: the tension is low and the saw-tooth small, T_in 1.2 x rougher in moves
    # than in holds (under STICK_SLIP_RATIO), and stiction's S 0.64 (the base at its floor). Two weak signs together
    # name it; its clean twin shows neither
    cands = ("stiction", "velocity_friction", "friction_offset")
    rec = lumped_scenarios.record("stiction", seed=3904113, level=0.8, duration=60.0)
    res = diagnose(rec.data, effects=cands)
    slip = res["stick_slip"]
    assert res["cause"] == "stiction", (slip, res["candidates"]["stiction"]["score"])
    assert slip["named"] and slip["weak"]
    assert th.STICK_SLIP_WEAK <= slip["ratio"] < th.STICK_SLIP_RATIO
    assert res["candidates"]["stiction"]["score"] < res["settings"]["stick_slip_weak_score"]
    from study.report import format_summary
    assert "two weak signs" in format_summary(res)
    twin = diagnose(lumped_scenarios.record(None, seed=3904113, level=0.8, duration=60.0).data, effects=cands)
    assert twin["cause"] == "none" and not twin["stick_slip"]["named"]
    # either sign alone is not enough
    monkeypatch.setattr(th, "STICK_SLIP_WEAK_SCORE", 0.5)
    assert diagnose(rec.data, effects=cands)["causes"] == []


def test_a_clear_saw_tooth_overrules_a_named_effect_that_leaves_structure(monkeypatch):
    # a Stribeck peak of 0.51 on a constant force: T_in is 6.5 x rougher in steady moves than in holds, and the models
    # name a T_in lag that leaves 3.7 x the floor. A sensor lag has no stick-slip: stiction is named, the lag set
    # aside, the structure still said
    cands = ("stiction", "sensor_lag:T_in", "velocity_friction")
    rec = lumped_scenarios.record("stiction", seed=4604111, level=0.8, duration=60.0)
    res = diagnose(rec.data, effects=cands)
    slip = res["stick_slip"]
    assert res["causes"] == ["stiction", "unknown"], slip
    assert slip["named"] and not slip["weak"] and slip["overruled"] == ["sensor_lag:T_in"]
    assert slip["ratio"] >= 3 * th.STICK_SLIP_RATIO
    from study.report import format_summary
    assert "the models named sensor_lag:T_in, which left structure" in format_summary(res)
    twin = diagnose(lumped_scenarios.record(None, seed=4604111, level=0.8, duration=60.0).data, effects=cands)
    assert twin["causes"] == [] and twin["stick_slip"]["overruled"] == []
    # without the check the lag stands, with the structure it leaves
    monkeypatch.setattr(th, "STICK_SLIP_RATIO", math.inf)
    assert diagnose(rec.data, effects=cands)["causes"] == ["sensor_lag:T_in", "unknown"]


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


class _StubFit:
    """A fitted model as the rules see it: its effects, its score S and its structure ratio on T_out (floor 1)."""

    def __init__(self, ids: tuple[str, ...], S: float = 1.0, ratio: float = 1.0):
        self.effects = [CATALOGUE[i] for i in ids]
        self.S, self._ratio = S, ratio

    @property
    def ids(self) -> list[str]:
        return [e.id for e in self.effects]

    def val_mse(self) -> dict[str, float]:
        return {"T_out": self._ratio ** 2}


def test_the_stick_slip_rule_names_stiction_only_on_a_rough_proximal_tension():
    from types import SimpleNamespace

    from estimator.offline.diagnosis.rules import stick_slip_rule
    ctx = SimpleNamespace(floor={"T_out": 1.0})
    base, stiction = _StubFit(()), _StubFit(("stiction",), S=0.95)
    singles = {"stiction": stiction}
    # a clear saw-tooth where the models named nothing: stiction
    assert stick_slip_rule(ctx, base, singles, 2.0) == (stiction, True, False, [])
    # sensor noise (a ratio near 1), or no reading: nothing
    assert stick_slip_rule(ctx, base, singles, 1.0) == (base, False, False, [])
    assert stick_slip_rule(ctx, base, singles, None) == (base, False, False, [])
    # a weak roughness names it only with a stiction fit that explains a tenth of what the base leaves
    assert stick_slip_rule(ctx, base, singles, 1.2)[1] is False
    explains = _StubFit(("stiction",), S=0.8)
    assert stick_slip_rule(ctx, base, {"stiction": explains}, 1.2) == (explains, True, True, [])
    # a clear saw-tooth overrules a lag that leaves structure, not one that explains the recording
    lag_left = _StubFit(("sensor_lag:T_in",), S=0.3, ratio=2.0 * th.STRUCTURE_RATIO)
    assert stick_slip_rule(ctx, lag_left, singles, 2.0) == (stiction, True, False, ["sensor_lag:T_in"])
    lag_ok = _StubFit(("sensor_lag:T_in",), S=0.05, ratio=1.0)
    assert stick_slip_rule(ctx, lag_ok, singles, 2.0) == (lag_ok, False, False, [])


def test_the_rest_rule_names_an_encoder_offset_only_when_the_models_named_nothing():
    from estimator.offline.diagnosis.rules import rest_rule
    base, offset = _StubFit(()), _StubFit(("sensor_offset:x_in",), S=0.4)
    singles = {"sensor_offset:x_in": offset}
    assert rest_rule(base, singles, "sensor_offset:x_in") == (offset, True)
    # an x_out reading is named through its equivalent (x_in offset -b), the one fitted
    assert rest_rule(base, singles, "sensor_offset:x_out") == (offset, True)
    # no reading, or an effect the models named: unchanged
    assert rest_rule(base, singles, None) == (base, False)
    named = _StubFit(("pretension",), S=0.1)
    assert rest_rule(named, singles, "sensor_offset:x_in") == (named, False)


def test_the_verdict_puts_unknown_first_only_when_the_catalogue_missed_most_of_the_structure():
    from estimator.offline.diagnosis.rules import verdict
    r = th.STRUCTURE_RATIO
    side = _StubFit(("sensor_offset:T_in",), S=0.5)
    # more than twice the threshold left after an effect that explains only part of it: unknown first
    assert verdict(["sensor_offset:T_in"], {"T_out": 2.5 * r}, side, False) == ["unknown", "sensor_offset:T_in"]
    # ... unless it removed nearly all of the base's excess, or a model-free reading named it
    cause = _StubFit(("sensor_offset:T_in",), S=0.5 * th.DOMINANT_SCORE)
    assert verdict(["sensor_offset:T_in"], {"T_out": 2.5 * r}, cause, False) == ["sensor_offset:T_in", "unknown"]
    assert verdict(["sensor_offset:T_in"], {"T_out": 2.5 * r}, side, True) == ["sensor_offset:T_in", "unknown"]
    # structure between the threshold and twice it: unknown after; none left: the effect alone; nothing: none
    assert verdict(["sensor_offset:T_in"], {"T_out": 1.5 * r}, side, False) == ["sensor_offset:T_in", "unknown"]
    assert verdict(["sensor_offset:T_in"], {"T_out": 0.5 * r}, side, False) == ["sensor_offset:T_in"]
    assert verdict([], {"T_out": 0.5 * r}, _StubFit(()), False) == []


def test_at_the_floor_an_effect_is_named_by_its_bar_or_by_the_excess_it_removes():
    from types import SimpleNamespace

    from estimator.offline.diagnosis.rules import shown_at_floor
    ctx = SimpleNamespace(floor={"T_out": 1.0}, subset_floor={}, excess_min=th.EXCESS_MIN)
    base = _StubFit((), ratio=1.0)                          # at its floor: B = 1 squared floor
    # an effect without its own bound: STRONG_SCORE
    assert shown_at_floor(ctx, base, "sensor_gain:T_out", _StubFit(("sensor_gain:T_out",), S=0.1))
    assert not shown_at_floor(ctx, base, "sensor_gain:T_out", _StubFit(("sensor_gain:T_out",), S=0.2))
    # an effect that cannot bend to noise has its own, looser bound (FLOOR_SCORE)
    vf = th.FLOOR_SCORE["velocity_friction"]
    assert shown_at_floor(ctx, base, "velocity_friction", _StubFit(("velocity_friction",), S=0.9 * vf))
    assert not shown_at_floor(ctx, base, "velocity_friction", _StubFit(("velocity_friction",), S=1.1 * vf))
    # a base near the threshold: what an effect removes, B (1 - S), names it above EXCESS_MIN
    near = _StubFit((), ratio=1.9)                          # B = 3.61, still under WEAK_STRUCTURE
    assert shown_at_floor(ctx, near, "sensor_gain:T_out", _StubFit(("sensor_gain:T_out",), S=0.16))
    assert not shown_at_floor(ctx, base, "sensor_gain:T_out", _StubFit(("sensor_gain:T_out",), S=0.16))
    # made without T_out: the bounds of clean recordings made that way
    alone = SimpleNamespace(floor={"T_out": 1.0}, subset_floor=th.FLOOR_SCORE_WITHOUT["T_out"],
                            excess_min=th.EXCESS_MIN_WITHOUT["T_out"])
    backlash = _StubFit(("distal_backlash",), S=0.1)
    assert shown_at_floor(ctx, base, "distal_backlash", backlash)
    assert not shown_at_floor(alone, base, "distal_backlash", backlash)


def test_a_long_recording_is_chosen_on_a_coarser_series_and_judged_at_the_full_rate(monkeypatch, clean_result):
    """Above SELECTION_SAMPLES the model choice runs on a series averaged further (not below SELECTION_RATE_MIN);
    the chosen model is refitted and tested at the full rate: the cause is the same, the settings say both rates."""
    _, clean = clean_result
    assert clean["settings"]["selection_rate_hz"] == pytest.approx(250.0, rel=1e-3)    # 500 Hz in pairs: below it
    rec = record("velocity_friction", seed=11, duration=DUR, rate_hz=RATE)
    monkeypatch.setattr(selection, "SELECTION_SAMPLES", 3000)        # 45 s at 250 Hz: 11250 samples
    res = diagnose(rec.data)
    assert res["settings"]["selection_rate_hz"] == pytest.approx(100.0, rel=1e-3)   # 66.7 Hz raised to the floor
    assert res["settings"]["target_rate_hz"] == 200.0
    check_named("velocity_friction", rec, res)
    pred = predictions(res, rec.data)               # the model re-runs at the rate it was refitted at
    held = rec.data.time >= res["split"]["time_s"]
    rmse = float(np.sqrt(np.mean((pred["T_out_ext"][held] - rec.data.T_out[held]) ** 2)))
    assert rmse == pytest.approx(res["extended"]["rmse_T_out_N"], rel=1e-6)
