"""The estimators of every joint of an instrument stepped in one compiled call per sample.

:class:`PairBank` takes over the :class:`~estimator.online.pair.PairEstimator` of each joint once each
has had its first sample (zero pose set, previous sample known). Per sample it runs, joint after joint in
one compiled loop, the same compiled step as :meth:`PairEstimator.step`
(:func:`estimator.online.pair_coupling.step_pair`, equations (J1)-(J5) in :mod:`estimator.online.pair`)
on the same numbers, so every estimate is the joint's own step's, bit for bit. What it saves is the Python
around each joint's call (its tendons' state packed in and unpacked again, ~10 us a joint on a 2-core
machine): at 8 joints (16 tendons) a tenth of a 1 kHz period.

While the bank steps them, the estimators' arrays (tension profiles, readable-phase states, coupling
state, slide state, the compiled step's parameters) are views into the bank's stacked arrays; their
scalar state (previous sample and its time, smoothed rate and velocity, T_out, elongation, phase) lives
in the bank and :meth:`PairBank.release` writes it back. An estimator of a bank that is stepped, reset
or zeroed on its own releases its bank first (:meth:`PairEstimator.step`), so its own step always
starts from its current state.
"""
from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numba import njit

from estimator.online.pair import PairEstimator
from estimator.online.pair_coupling import step_pair
from estimator.phase import Phase

__all__ = ["PairBank", "can_bank"]

_PHASES = tuple(Phase(k) for k in range(len(Phase)))


def can_bank(est: PairEstimator) -> bool:
    """Whether ``est``'s next sample takes the compiled step (what a bank runs): its phases are banded, its
    zero pose is set and both tendons have a previous sample."""
    ta, tb = est.tendons
    return bool(est._compiled and est._x0 is not None and ta._t_prev is not None and tb._t_prev is not None)


@njit(cache=True, nogil=True)
def _step_all(P, C, PS, prm, state, N, T_in, x_in, t, out, ok):  # pragma: no cover - compiled
    """:func:`step_pair` for every joint i (row i of every array; T_in, x_in of shape (n_joints, 2)), then the
    previous sample, its time and the rates of an updated joint into its parameters, as the estimator does."""
    for i in range(P.shape[0]):
        ok[i] = step_pair(P[i, 0], C[i, 0], PS[i, 0], P[i, 1], C[i, 1], PS[i, 1], prm[i], state[i], N[i],
                          T_in[i, 0], x_in[i, 0], T_in[i, 1], x_in[i, 1], t, out[i])
        if ok[i]:
            prm[i, 14] = T_in[i, 0]
            prm[i, 15] = T_in[i, 1]
            prm[i, 16] = t
            prm[i, 17] = t
            prm[i, 18] = out[i, 12]
            prm[i, 19] = out[i, 13]


class PairBank:
    """Joint estimators stepped together (module docstring).

    Parameters
    ----------
    estimators : sequence of PairEstimator
        One per joint, in the row order of the samples given to :meth:`step`; each ready for the compiled
        step (:func:`can_bank`), all with profiles of the same number of nodes.

    Attributes
    ----------
    estimators : tuple of PairEstimator
    active : bool
        True until :meth:`release`.

    Raises
    ------
    ValueError
        No estimator, one not ready for the compiled step, one already in a bank, or profiles of different
        lengths (named).
    """

    def __init__(self, estimators: Sequence[PairEstimator]):
        ests = tuple(estimators)
        if not ests:
            raise ValueError("PairBank: expected at least one joint estimator")
        n1 = ests[0].tendons[0].profile.size
        for i, est in enumerate(ests):
            if not can_bank(est) or est._bank is not None:
                raise ValueError(f"PairBank: estimator {i} is not ready for the compiled step (banded phases, zero "
                                 f"pose and a first sample needed) or already in a bank")
            if any(e.profile.size != n1 for e in est.tendons):
                raise ValueError(f"PairBank: estimator {i} has profiles of {est.tendons[0].profile.size} nodes, "
                                 f"estimator 0 of {n1}")
        nj = len(ests)
        self.estimators = ests
        self.P = np.empty((nj, 2, n1))
        self.C = np.stack([np.stack(est._const) for est in ests])
        self.PS = np.empty((nj, 2, ests[0].tendons[0]._phase_state.size))
        self.prm = np.empty((nj, ests[0]._prm.size))
        self.state = np.empty((nj, ests[0]._state.size))
        self.N = np.empty((nj, 2, 6))
        self.out = np.zeros((nj, 14))
        self.ok = np.zeros(nj, dtype=np.bool_)
        self.stepped = np.zeros(nj, dtype=np.bool_)
        for i, est in enumerate(ests):
            self._take(i, est)
        self.active = True

    def _take(self, i: int, est: PairEstimator) -> None:
        """Row ``i`` from ``est``'s state; its arrays become views of the row."""
        for k, e in enumerate(est.tendons):
            self.P[i, k] = e.profile
            e.profile = self.P[i, k]
            self.PS[i, k] = e._phase_state
            e._phase_state = self.PS[i, k]
            self.N[i, k] = (e.band, e.tension_noise, e._x_prev, e.velocity, e._slide[0], e._slide[1])
            e._slide = self.N[i, k, 4:6]
        ta, tb = est.tendons
        self.prm[i] = est._prm
        self.prm[i, 14:20] = (ta._T_prev, tb._T_prev, ta._t_prev, tb._t_prev, ta._rate, tb._rate)
        est._prm = self.prm[i]
        self.state[i] = est._state
        est._state = self.state[i]
        est._bank = self

    def step(self, T_in: np.ndarray, x_in: np.ndarray, t: float) -> np.ndarray:
        """Update every joint with one proximal sample: load cells ``T_in`` [N] and encoders ``x_in`` [m] of
        shape (n_joints, 2) (tendons a, b), time ``t`` [s].

        Returns
        -------
        ndarray, shape (n_joints, 14)
            Per joint: torque [N m], angle [rad], T_out a/b [N], elongation a/b [m], x_out a/b [m], the
            kinematic angles a/b [rad], the phase codes a/b (:class:`~estimator.phase.Phase`), the rates
            a/b [N/s]. The bank's own array: read it before the next step.

        Raises
        ------
        ValueError
            A non-finite sample: the bank is released and the joint's own step raises its error.
        """
        if not self.active:
            raise ValueError("PairBank.step: the bank was released")
        _step_all(self.P, self.C, self.PS, self.prm, self.state, self.N, T_in, x_in, float(t), self.out, self.ok)
        if not self.ok.all():
            bad = int(np.argmin(self.ok))
            self.stepped |= self.ok
            self.release()
            self.estimators[bad].step(float(T_in[bad, 0]), float(x_in[bad, 0]), float(T_in[bad, 1]),
                                      float(x_in[bad, 1]), t)
            raise ValueError(f"PairBank.step: joint {bad}'s sample is not finite")   # its own step raised first
        self.stepped[:] = True
        return self.out

    def release(self) -> None:
        """Give every estimator its state back (copies of the rows, scalars written back); idempotent."""
        if not self.active:
            return
        self.active = False
        for i, est in enumerate(self.estimators):
            for k, e in enumerate(est.tendons):
                e.profile = self.P[i, k].copy()
                e._phase_state = self.PS[i, k].copy()
                e._slide = self.N[i, k, 4:6].copy()
                x_prev = float(self.N[i, k, 2])
                e._x_prev, e.velocity = (None if math.isnan(x_prev) else x_prev), float(self.N[i, k, 3])
                e._T_prev, e._t_prev, e._rate = (float(self.prm[i, 14 + k]), float(self.prm[i, 16 + k]),
                                                 float(self.prm[i, 18 + k]))
                if self.stepped[i]:
                    o = self.out[i]
                    e.T_out, e.elongation, e.phase = float(o[2 + k]), float(o[4 + k]), _PHASES[int(o[10 + k])]
            est._prm = self.prm[i].copy()
            est._state = self.state[i].copy()
            est._bank = None
