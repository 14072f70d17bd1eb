"""PairControlBank: the pair controllers of several joints stepped in one compiled call give each controller's
own motor commands bit for bit (modes, hysteresis, feedforward, travel clip, no command), hand their state
back on release, and release themselves when stepped on their own."""
from __future__ import annotations

import math

import numpy as np
import pytest

from slave.pair_control import PairController
from slave.pair_control_bank import PairControlBank


def _controllers() -> list[PairController]:
    """Four joints: with and without feedforward, travel limits and backlash compensation, different gains and
    bands."""
    return [PairController(0.004, 0.25, 0.01, 0.01, 0.05, (0.001, -0.002), x_limits=((-0.004, 0.006), (-0.01, 0.01)),
                           band_compliance=(4e-5, 6e-5), band_width=0.004, friction_exponent=(0.6, 0.7)),
            PairController(0.003, 0.5, 0.02, 0.0, 0.04, (0.0, 0.0), feedforward=False),
            PairController(0.002, 1.0, 0.005, 0.05, 0.02, (-0.003, 0.003), play=0.0, band_compliance=(1e-4, 0.0)),
            PairController(0.005, 0.3, 0.01, 0.02, 0.05, (0.0, 0.001), x_limits=((-1e-3, 1e-3), (-1e-3, 2e-3)))]


def _inputs(n: int, nj: int, seed: int = 5):
    """Commands [rad] crossing the bands both ways with gaps (NaN: none), load cells [N], distal displacements [m]
    with gaps (NaN), each (n, nj) or (n, nj, 2)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n)[:, None] * 1e-3
    theta = 0.4 * np.sin(2 * math.pi * 2.0 * t + np.arange(nj)) + rng.normal(0, 0.003, (n, nj))
    theta[rng.random((n, nj)) < 0.03] = math.nan
    T = np.abs(2.0 + rng.normal(0, 1.0, (n, nj, 2)))
    x_out = 1e-3 * np.sin(2 * math.pi * 1.5 * t)[..., None] + rng.normal(0, 3e-5, (n, nj, 2))
    x_out[rng.random((n, nj, 2)) < 0.02] = math.nan
    return theta, T, x_out


def _own(c: PairController, theta, T, x_out, none: bool = True) -> tuple[float, float]:
    """The controller's own step; a missing command as None (``none``) or as NaN, the same to it."""
    return c.step(None if none and math.isnan(theta) else float(theta), (float(T[0]), float(T[1])), 1e-3,
                  (float(x_out[0]), float(x_out[1])))


def test_the_bank_gives_each_controllers_own_commands_bit_for_bit_and_its_state_back():
    theta, T, X = _inputs(3000, 4)
    banked, alone = _controllers(), _controllers()
    bank = PairControlBank(banked)
    for k in range(2500):
        out = bank.step(theta[k], T[k], 1e-3, X[k])
        for i, c in enumerate(alone):
            assert tuple(out[i]) == _own(c, theta[k, i], T[k, i], X[k, i], none=i % 2 == 0)
    assert bank.switches.tolist() == [c.switches for c in alone] and min(bank.switches) > 10
    assert alone[0]._T_eq != alone[0]._T0 and alone[2]._T_eq != alone[2]._T0      # the compensation was at work
    assert bank.mode.tolist() == [int(c.mode) for c in alone]
    bank.release()
    for a, b in zip(banked, alone, strict=False):
        assert (a.x_cmd, a.mode, a.switches, a._x_ref, a._c_ref, a._ff) == (b.x_cmd, b.mode, b.switches, b._x_ref,
                                                                            b._c_ref, b._ff)
        assert (a._y, a._T0, a._T_eq) == (b._y, b._T0, b._T_eq)
        assert a._bank is None
    for k in range(2500, 3000):             # and on their own again, still the same
        for i in range(4):
            assert _own(banked[i], theta[k, i], T[k, i], X[k, i]) == _own(alone[i], theta[k, i], T[k, i], X[k, i])


def test_a_controller_stepped_on_its_own_releases_its_bank_and_a_banked_one_is_refused():
    ctls = _controllers()
    bank = PairControlBank(ctls)
    bank.step(np.full(4, 0.3), np.ones((4, 2)), 1e-3, np.zeros((4, 2)))
    with pytest.raises(ValueError, match="already in a bank"):
        PairControlBank(ctls[:1])
    ctls[2].step(0.3, (1.0, 1.0), 1e-3, (0.0, 0.0))
    assert not bank.active and all(c._bank is None for c in ctls) and ctls[0].switches == 1
    with pytest.raises(ValueError, match="released"):
        bank.step(np.zeros(4), np.ones((4, 2)), 1e-3, np.zeros((4, 2)))

