"""At the noise floor: when the base leaves little structure, an effect is named by its score under the bar
(STRONG_SCORE, or its own bound FLOOR_SCORE, below what it reaches on clean recordings) or by the excess it removes,
B (1 - S) squared floors above EXCESS_MIN; a clean recording whose best extension removes less gives ``none``. A
recording with x_out alone is judged against clean recordings made that way. A tension offset below OFFSET_FLOORS x
the T_out floor is not resolved, unless it removes nearly all of a clear structure.

The bars are checked on stand-ins for fitted models and on the lumped simulator's recordings, 60 s at its own rate;
seeds are development seeds (the benchmark's final seeds are never used in tests).
"""
import math
from dataclasses import replace

import pytest

from estimator.offline.diagnosis import thresholds as th
from estimator.offline.diagnosis.selection import diagnose
from estimator.offline.diagnosis.thresholds import (
    EXCESS_MIN,
    EXCESS_MIN_WITHOUT,
    FLOOR_SCORE_WITHOUT,
    STRONG_SCORE,
)
from estimator.offline.effects.catalogue import CATALOGUE
from study.lumped import scenarios as lumped_scenarios
from tests.estimator.diagnosis_support import _StubFit


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
