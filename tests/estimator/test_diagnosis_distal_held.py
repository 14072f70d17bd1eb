"""A distal end held on its stop. An x_out that stands within its resolution while x_in travels shows nothing of
the tendon and is set aside (fitted, it would bend K and let a play explain the standing distal end); a distal end
barely moving on a stop a pretension presses (the stop's deflection and the tendon's pre-sliding) is kept when the
pretension explains both signals; a distal end on its stop for nearly all of the proximal travel cannot show a lag
of x_out, and the result and the printed summary say so.

The readings are checked on the clean rig recording (45 s at 500 Hz) with x_out replaced; the lumped simulator's
recordings are 60 s at its own rate; seeds are development seeds (the benchmark's final seeds are never used in
tests).
"""
from dataclasses import replace

import numpy as np
import pytest

from estimator.offline.diagnosis.fit import (
    predictions,
)
from estimator.offline.diagnosis.selection import diagnose
from study.lumped import scenarios as lumped_scenarios
from study.scenarios import record
from tests.estimator.diagnosis_support import DUR, RATE


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
    assert "distal_backlash" not in res["candidates"] and "distal_backlash" not in res["screened"]
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
