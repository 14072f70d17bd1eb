"""PairBank: the estimators of several joints stepped in one compiled call give each joint's own step's
numbers bit for bit, hand their state back on release, and release themselves when stepped on their own."""
from __future__ import annotations

import copy
import math

import numpy as np
import pytest

from estimator.online.pair import PairEstimator
from estimator.online.pair_bank import PairBank, can_bank
from estimator.sheath import SheathModel


def _joints() -> list[PairEstimator]:
    """Three joints of different tendons, pretensions and noise bands (the envelope rule on one)."""
    out = []
    for k, (Ka, Kb, noise, pre) in enumerate(((0.5, 0.6, 0.02, 0.0), (0.8, 0.7, 0.0, 1.0), (0.3, 0.9, 0.05, 0.5))):
        ma = SheathModel(K=Ka, compliance=1e-4 * (1 + k), wrap_shape=np.linspace(0.0, 1.0, 33) ** 2)
        mb = SheathModel(K=Kb, compliance=1.2e-4)
        out.append(PairEstimator(ma, mb, 0.003 + 0.001 * k, n_nodes=40, pretension=pre, tension_noise=noise))
    return out


def _samples(n: int, nj: int, seed: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Load cells [N] and encoders [m], shape (n, nj, 2): pulls and releases of both tendons, with noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(n)[:, None] * 1e-3
    ph = np.arange(nj)[None, :]
    Ta = 5.0 + 4.0 * np.sin(2 * math.pi * 1.3 * t + ph) + rng.normal(0, 0.02, (n, nj))
    Tb = 5.0 - 4.0 * np.sin(2 * math.pi * 1.3 * t + ph) + rng.normal(0, 0.02, (n, nj))
    xa = 1e-3 * np.sin(2 * math.pi * 0.7 * t + ph)
    return np.stack((Ta, Tb), axis=-1), np.stack((xa, -xa), axis=-1)


def _own(est: PairEstimator, T, x, t) -> tuple:
    s = est.step(float(T[0]), float(x[0]), float(T[1]), float(x[1]), t)
    return (s.torque, s.angle, *s.T_out, *s.elongation, *s.x_out, s.angle_a, s.angle_b, *(int(p) for p in s.phase))


def test_the_bank_gives_each_joints_own_step_bit_for_bit_and_its_state_back():
    T, X = _samples(1500, 3)
    banked, alone = _joints(), _joints()
    for ests in (banked, alone):          # the first sample of each (zero pose), on its own
        for i, e in enumerate(ests):
            _own(e, T[0, i], X[0, i], 0.0)
    assert all(can_bank(e) for e in banked)
    bank = PairBank(banked)
    for k in range(1, 1000):
        out = bank.step(T[k], X[k], k * 1e-3)
        for i, e in enumerate(alone):
            assert tuple(out[i, :12]) == _own(e, T[k, i], X[k, i], k * 1e-3)
    bank.release()
    assert not bank.active and all(e._bank is None for e in banked)
    for a, b in zip(banked, alone, strict=False):
        for ta, tb in zip(a.tendons, b.tendons, strict=False):
            assert np.array_equal(ta.profile, tb.profile) and np.array_equal(ta._phase_state, tb._phase_state)
            assert (ta.T_out, ta.elongation, ta.phase, ta._T_prev, ta._t_prev, ta._rate, ta.velocity, ta._x_prev) == \
                (tb.T_out, tb.elongation, tb.phase, tb._T_prev, tb._t_prev, tb._rate, tb.velocity, tb._x_prev)
    for k in range(1000, 1500):            # and on their own again, still the same
        for i in range(3):
            assert _own(banked[i], T[k, i], X[k, i], k * 1e-3) == _own(alone[i], T[k, i], X[k, i], k * 1e-3)


def test_an_estimator_stepped_on_its_own_releases_its_bank_first():
    T, X = _samples(300, 3)
    banked, alone = _joints(), _joints()
    for ests in (banked, alone):
        for i, e in enumerate(ests):
            _own(e, T[0, i], X[0, i], 0.0)
    bank = PairBank(banked)
    for k in range(1, 200):
        bank.step(T[k], X[k], k * 1e-3)
        for i in range(3):
            _own(alone[i], T[k, i], X[k, i], k * 1e-3)
    assert _own(banked[1], T[200, 1], X[200, 1], 0.2) == _own(alone[1], T[200, 1], X[200, 1], 0.2)
    assert not bank.active and banked[0]._bank is None
    with pytest.raises(ValueError, match="released"):
        bank.step(T[201], X[201], 0.201)


def test_refusals_not_ready_already_banked_and_a_non_finite_sample():
    fresh = _joints()
    with pytest.raises(ValueError, match="estimator 0 is not ready"):
        PairBank(fresh)
    T, X = _samples(3, 3)
    for i, e in enumerate(fresh):
        _own(e, T[0, i], X[0, i], 0.0)
    bank = PairBank(copy.copy(fresh))
    with pytest.raises(ValueError, match="already in a bank"):
        PairBank(fresh[:1])
    bad = T[1].copy()
    bad[2, 1] = math.nan
    with pytest.raises(ValueError, match="must be finite"):
        bank.step(bad, X[1], 1e-3)
    assert not bank.active and all(e._bank is None for e in fresh)
