"""Master mapping: motion scaling about an anchor; force scaling, ramp-in, clamp, slew limit, safe zero."""
from __future__ import annotations

import math

import numpy as np
import pytest

from master.mapping import ForceMap, MotionMap, clamp_force
from teleop.config.schema import MappingConfig
from teleop.errors import ConfigError

DT = 1e-3


def engaged_map(**kw) -> ForceMap:
    args = dict(force_scale=0.2, force_limit=4.0, ramp_time=0.5, force_rate_limit=100.0)
    args.update(kw)
    fm = ForceMap(**args)
    fm.engage()
    return fm


def run(fm: ForceMap, T_out: float, t0: float, n: int, fresh: bool = True) -> tuple[list[float], float]:
    out, t = [], t0
    for _ in range(n):
        out.append(fm.step(T_out, t, fresh))
        t += DT
    return out, t


# ---- clamp_force ---------------------------------------------------------------------------------

@pytest.mark.parametrize("f, expected", [(1.0, 1.0), (-1.0, -1.0), (9.0, 4.0), (-9.0, -4.0), (4.0, 4.0),
                                         (math.nan, 0.0), (math.inf, 0.0), (-math.inf, 0.0)])
def test_clamp_force(f, expected):
    assert clamp_force(f, 4.0) == expected


# ---- ForceMap --------------------------------------------------------------------------------------

def test_force_opposes_the_pull_and_scales():
    fm = engaged_map(ramp_time=0.0, force_rate_limit=1e9)
    fm.step(10.0, 0.0)
    f = fm.step(10.0, DT)
    assert f == pytest.approx(-0.2 * 10.0)


def test_ramp_in_after_engage():
    fm = engaged_map(force_rate_limit=1e9)       # slew out of the way: the ramp alone
    forces, _ = run(fm, 10.0, 0.0, 751)
    # F = -0.2 * 10 * min(1, t / 0.5)
    assert forces[0] == 0.0
    assert forces[250] == pytest.approx(-1.0, rel=1e-9)
    assert forces[500] == pytest.approx(-2.0, rel=1e-9)
    assert forces[750] == pytest.approx(-2.0, rel=1e-9)
    assert np.all(np.diff(forces[:501]) <= 0)     # monotone build-up


def test_slew_rate_limit_on_a_step():
    fm = engaged_map(ramp_time=0.0, force_limit=100.0, force_rate_limit=100.0)
    forces, _ = run(fm, 100.0, 0.0, 300)         # target -20 N at once
    steps = np.abs(np.diff([0.0] + forces))
    assert steps.max() <= 100.0 * DT + 1e-12
    assert forces[99] == pytest.approx(-100.0 * 99 * DT)   # rising at exactly the limit
    assert forces[-1] == pytest.approx(-20.0)


def test_clamped_to_force_limit():
    fm = engaged_map(ramp_time=0.0, force_rate_limit=1e9)
    forces, _ = run(fm, 1e6, 0.0, 10)
    assert forces[-1] == -4.0
    assert min(forces) >= -4.0


def test_stale_estimate_zeroes_at_once_and_restarts_the_ramp():
    fm = engaged_map(force_rate_limit=1e9)
    forces, t = run(fm, 10.0, 0.0, 1000)
    assert forces[-1] == pytest.approx(-2.0)
    assert fm.step(10.0, t, fresh=False) == 0.0   # no slew on the way to safety
    t += DT
    after, _ = run(fm, 10.0, t, 251)
    assert after[0] == 0.0                         # ramp starts again from zero
    assert after[250] == pytest.approx(-1.0, rel=1e-9)


def test_disengage_zeroes_and_stays_zero():
    fm = engaged_map(ramp_time=0.0, force_rate_limit=1e9)
    run(fm, 10.0, 0.0, 10)
    fm.disengage()
    forces, _ = run(fm, 10.0, 1.0, 10)
    assert forces == [0.0] * 10


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_estimate_gives_zero(bad):
    fm = engaged_map(ramp_time=0.0, force_rate_limit=1e9)
    run(fm, 10.0, 0.0, 10)
    assert fm.step(bad, 0.02) == 0.0


def test_non_finite_time_gives_zero():
    fm = engaged_map(ramp_time=0.0)
    run(fm, 10.0, 0.0, 10)
    assert fm.step(10.0, math.nan) == 0.0


def test_never_beyond_the_limit_for_any_input():
    rng = np.random.default_rng(7)
    specials = np.array([math.nan, math.inf, -math.inf, 1e308, -1e308, 0.0])
    fm = engaged_map(force_scale=5.0, force_limit=3.0, ramp_time=0.05, force_rate_limit=1e4)
    t = 0.0
    for k in range(20000):
        T = rng.normal(0, 50) if rng.random() > 0.05 else rng.choice(specials)
        t_k = t if rng.random() > 0.01 else rng.choice(specials)
        f = fm.step(float(T), float(t_k), fresh=bool(rng.random() > 0.02))
        assert math.isfinite(f) and abs(f) <= 3.0, (k, T, t_k, f)
        if not math.isfinite(T) or not math.isfinite(t_k):
            assert f == 0.0
        t += DT * rng.choice([0.0, 1.0, 5.0])


def test_time_going_back_never_increases_the_force():
    fm = engaged_map(ramp_time=0.0, force_rate_limit=100.0)
    run(fm, 10.0, 0.0, 5)
    f_before = fm.force
    f = fm.step(1e6, -1.0)        # clock went back: dt = 0 -> no change allowed
    assert f == f_before


@pytest.mark.parametrize("kw, key", [(dict(force_limit=0.0), "force_limit"),
                                     (dict(force_rate_limit=-1.0), "force_rate_limit"),
                                     (dict(ramp_time=math.nan), "ramp_time"),
                                     (dict(force_scale=math.inf), "force_scale")])
def test_bad_parameters_name_the_key(kw, key):
    with pytest.raises(ConfigError, match=f"master.mapping.{key}"):
        engaged_map(**kw)


def test_from_config():
    fm = ForceMap.from_config(MappingConfig(force_scale=0.5, force_limit=2.0, ramp_time=0.1, force_rate_limit=50.0))
    assert (fm.scale, fm.limit, fm.ramp_time, fm.rate_limit) == (0.5, 2.0, 0.1, 50.0)


# ---- MotionMap ------------------------------------------------------------------------------------

def test_motion_scaling_about_the_anchor():
    mm = MotionMap(0.2)
    mm.anchor(position=0.05, x_in=0.003)
    assert mm.command(0.05) == pytest.approx(0.003)           # no jump at engage
    assert mm.command(0.10) == pytest.approx(0.003 + 0.2 * 0.05)
    assert mm.command(0.00) == pytest.approx(0.003 - 0.2 * 0.05)


def test_motion_holds_on_nan_and_with_clutch_open():
    mm = MotionMap(0.2)
    mm.anchor(0.0, 0.0)
    x = mm.command(0.01)
    assert mm.command(math.nan) == x
    mm.open_clutch()
    assert mm.command(0.5) == x                                # clutch open: hold
    mm.anchor(0.5, mm.last)                                    # close again: continue from the held value
    assert mm.command(0.51) == pytest.approx(x + 0.2 * 0.01)


def test_motion_before_anchor_holds_zero_and_bad_anchor_is_refused():
    mm = MotionMap(0.2)
    assert mm.command(1.0) == 0.0
    with pytest.raises(ValueError):
        mm.anchor(math.nan, 0.0)
    assert not mm.anchored
    with pytest.raises(ConfigError, match="motion_scale"):
        MotionMap(0.0)
