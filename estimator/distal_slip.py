"""Slip spreading from the distal end of a tendon: the exact distal tension for a given elongation.

When the distal end of a tendon moves while its proximal end is held (a joint turned by something
else: the other tendon of an antagonistic pair, the tissue, the joint spring), friction lets the
change spread from the distal end only. With the distal tension T_d as the unknown, every node
follows the distal envelope rule (Phee et al. 2009, eq. (1) in differential form, applied from the
tip; Agrawal et al. 2010)

    T_i <- min( max(T_i, T_d dlo_i), T_d dhi_i ),    dlo_i = e^{-(K - g_i)},  dhi_i = 1 / dlo_i      (D)

with g_i = mu theta(s_i) the node's log gain from the proximal end (K = g_n). The elongation
e(T_d) = sum_i w_i T_i(T_d) is non-decreasing and piecewise linear in T_d, so the T_d that gives a
wanted elongation is found exactly by one scan over the breakpoints (the mirror image of the
proximal scan in :func:`estimator.kernels.advance_proximal`):

* stretching (wanted e above the present one): node i joins once T_d > p_i = T_i dhi_i. The stored
  profile is mu-Lipschitz in log T over theta, so p_i does not decrease toward the proximal end:
  the slipping nodes are a suffix, scanned from the tip.
* relaxing: node i joins once T_d < q_i = T_i dlo_i, q_i non-increasing toward the proximal end.

A tendon cannot push: a wanted elongation <= 0 gives T_d = 0 (slack). If the slip reaches the
proximal node it changes too (a position-held motor takes whatever tension the tendon needs).

All kernels are compiled (numba) and work on float64 arrays of the n + 1 nodes, proximal to distal.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from estimator.sheath import envelope_clip

__all__ = ["distal_gains", "distal_tension", "distal_clip", "elongation"]


def distal_gains(log_gain: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(dlo, dhi), each shape (n + 1,): e^{-(K - g_i)} and e^{+(K - g_i)} from the node log gains g_i [-]."""
    g = np.asarray(log_gain, dtype=np.float64)
    dlo = np.exp(-(g[-1] - g))
    return dlo, 1.0 / dlo


@njit(cache=True, nogil=True)
def elongation(T, w):  # pragma: no cover - compiled
    """sum(w * T) [m] (trapezoid weights w [m/N])."""
    e = 0.0
    for i in range(T.shape[0]):
        e += w[i] * T[i]
    return e


@njit(cache=True, nogil=True)
def distal_tension(T, dlo, dhi, w, e_old, target):  # pragma: no cover - compiled
    """The distal tension T_d [N] at which rule (D) applied to ``T`` gives elongation ``target`` [m].

    T : float64[n + 1] node tensions [N], proximal to distal (not modified).
    dlo, dhi : float64[n + 1] from :func:`distal_gains`.
    w : float64[n + 1] trapezoid weights [m/N].
    e_old : elongation of ``T`` [m] (sum(w * T), passed in to save a pass).
    target : wanted elongation [m]; <= 0 gives 0 (slack).
    """
    n1 = T.shape[0]
    if target <= 0.0:
        return 0.0
    if target == e_old:
        return T[n1 - 1]
    A = 0.0
    B = e_old
    if target > e_old:
        pmax = 0.0
        for k in range(n1 - 1, -1, -1):
            p = T[k] * dhi[k]
            if p > pmax:
                pmax = p
            if A > 0.0 and A * pmax + B >= target:
                return (target - B) / A
            A += w[k] * dlo[k]
            B -= w[k] * T[k]
        return (target - B) / A
    qmin = np.inf
    for k in range(n1 - 1, -1, -1):
        q = T[k] * dlo[k]
        if q < qmin:
            qmin = q
        if A > 0.0 and A * qmin + B <= target:
            Td = (target - B) / A
            return Td if Td > 0.0 else 0.0
        A += w[k] * dhi[k]
        B -= w[k] * T[k]
    Td = (target - B) / A
    return Td if Td > 0.0 else 0.0


@njit(cache=True, nogil=True)
def distal_clip(T, dlo, dhi, Td):  # pragma: no cover - compiled
    """Apply rule (D) with distal tension ``Td`` [N] to the node tensions ``T`` [N] in place."""
    for i in range(T.shape[0]):
        T[i] = envelope_clip(T[i], Td * dlo[i], Td * dhi[i])
