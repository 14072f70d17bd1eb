"""Effects that look alike, told apart. Positions are zeroed at the initial rest and no physical effect moves a
reading there: an encoder read away from zero at that rest (beyond its resolution and noise) is an offset, not a
pretension, and names an offset the models leave at the floor; a recording that starts moving has no such rest.
Stiffening and a distal backlash both bend x_out at low tension: the better score names the cause, unless the toe
is a dead travel.

The readings are checked on noise-free 2 s records at 1 kHz (a rest, then a pull) and on the lumped simulator's
recordings, 60 s at its own rate; seeds are development seeds (the benchmark's final seeds are never used in tests).
"""
from dataclasses import replace

import numpy as np
import pytest

from estimator.data import MeasuredData
from estimator.offline.diagnosis import readings as diagnosis_readings
from estimator.offline.diagnosis.readings import look_alike, toe_or_play
from estimator.offline.diagnosis.selection import diagnose
from study.lumped import scenarios as lumped_scenarios
from tests.estimator.diagnosis_support import _StubFit


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
