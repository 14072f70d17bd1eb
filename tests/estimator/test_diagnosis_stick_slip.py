"""Stick-slip: static friction above kinetic with a falling branch makes the tendon stick and slip, and the
proximal load cell reads a saw-tooth that no quasi-static extension reproduces. The ratio of T_in's roughness in
steady moves to that in holds is about 1 for sensor noise; a clear ratio names stiction where the models named
nothing and overrules a named effect that leaves structure (a sensor lag has no stick-slip), a weak one names it
only beside a stiction fit that explains a tenth of what the base leaves. Each clean twin (the same seed without
the effect) shows neither.

The ratio is checked on synthetic 40 s moves and holds at 200 Hz and 1 kHz, the diagnosis on the lumped
simulator's recordings, 60 s at its own rate; seeds are development seeds (the benchmark's final seeds are never used
in tests).
"""
import math

import numpy as np
import pytest

from estimator.offline.diagnosis import readings as diagnosis_readings
from estimator.offline.diagnosis import thresholds as th
from estimator.offline.diagnosis.selection import diagnose
from study.lumped import scenarios as lumped_scenarios
from tests.estimator.diagnosis_support import _StubFit


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
