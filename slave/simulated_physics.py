"""Compiled kernels of the simulated rig: quasi-static distributed Coulomb tendon and distal load.

Everything here is pure numerics on float64 arrays; :class:`slave.simulated.SimulatedRig` owns the
state and explains the model. Notation (all per node ``i = 0..n``, proximal to distal):

    T[i]      node tension [N] (the tension-profile memory, modified in place)
    lo[i]     exp(-mu theta_i),  hi[i] = exp(+mu theta_i)  [-], theta_i cumulative wrap angle [rad]
    w[i]      trapezoid weight [m/N], elongation = sum(w * T)

The distal load is a monotone graph between the distal displacement x >= 0 [m] and the distal
tension T_d [N], stored as a piecewise-linear curve ``F(x)`` for x > 0:

    bx[j]     start of segment j [m] (bx[0] = 0, increasing)
    bF[j]     F(bx[j]+) [N]
    bs[j]     slope of F on segment j [N/m] (> 0 on the last segment)

plus the vertical segment x = 0, T_d in [0, bF[0]] (the lower stop holds the joint while the tendon
pulls less than the set force). The tendon cannot push: T_d >= 0.
"""
from __future__ import annotations

import math

from numba import njit

from estimator.distal_slip import elongation  # the one sum(w * T) kernel, shared with the estimator

__all__ = ["advance_proximal", "settle_distal", "load_inverse", "load_on_line", "elongation"]


@njit(cache=True, nogil=True)
def load_on_line(r, c, bx, bF, bs):  # pragma: no cover - compiled
    """The point (x, T_d) of the load graph where x + c * T_d = r.

    The left side increases strictly along the graph, so the point is unique; ``r < 0`` cannot be
    reached with T_d >= 0 and gives the slack point (0, 0). Returns (x [m], T_d [N]).
    """
    if r <= 0.0:
        return 0.0, 0.0
    if r <= c * bF[0]:
        return 0.0, r / c
    m = bx.shape[0]
    for j in range(m):
        v = bx[j] + c * bF[j]
        x = bx[j] + (r - v) / (1.0 + c * bs[j])
        if j == m - 1 or x <= bx[j + 1]:
            return x, bF[j] + bs[j] * (x - bx[j])
    return 0.0, 0.0  # unreachable


@njit(cache=True, nogil=True)
def load_inverse(Td, bx, bF, bs):  # pragma: no cover - compiled
    """The interval [x_lo, x_hi] [m] of distal positions where the load holds tension ``Td`` [N].

    A single point where F is strictly increasing; an interval on a flat segment of F.
    """
    if Td < bF[0]:
        return 0.0, 0.0
    m = bx.shape[0]
    x_lo = 0.0
    found = False
    for j in range(m):
        end_F = math.inf if j == m - 1 else bF[j + 1]
        if bs[j] == 0.0:
            if Td == bF[j]:
                if not found:
                    x_lo = bx[j]
                    found = True
                if j == m - 1:
                    return x_lo, math.inf
                continue
            if found:
                return x_lo, bx[j]
            continue
        if found:
            return x_lo, bx[j]
        if Td <= end_F:
            x = bx[j] + (Td - bF[j]) / bs[j]
            return x, x
    return x_lo, x_lo


@njit(cache=True, nogil=True)
def advance_proximal(T, lo, hi, w, c_pull, c_rel, x_in, x_out, bx, bF, bs):  # pragma: no cover
    """Move the proximal end to ``x_in`` [m]; update ``T`` in place; return the new x_out [m].

    Solves x_in - x_out = sum(w * T(T_p)) for the proximal tension T_p, where T(T_p) is the envelope
    update of the old profile from the proximal end. Pulling, node i follows T_p lo[i] once T_p
    exceeds its breakpoint p_i = T[i] hi[i]; the old profile is mu-Lipschitz in log T over theta, so
    p_i is non-decreasing in i and the slipping nodes are a prefix. Between two breakpoints the
    elongation is linear in T_p, so a forward scan finds T_p exactly. If the scan passes the distal
    node, the whole tendon slips: T = T_d lo / lo[n] with elongation c_pull T_d, and (x_out, T_d)
    is the point of the load graph on the line x + c_pull T_d = x_in. Releasing is the mirror image
    (breakpoints q_i = T[i] lo[i], profile T_p hi[i], c_rel). Rounding that would break the order
    of the breakpoints is absorbed by a running max (min).
    """
    n1 = T.shape[0]
    e_old = elongation(T, w)
    target = x_in - x_out
    # a displacement change at the rounding level of the positions is no motion (no jitter)
    if abs(target - e_old) <= 4e-16 * (abs(x_in) + abs(x_out) + e_old):
        return x_out
    if target > e_old:
        A = 0.0
        B = e_old
        pmax = 0.0
        for k in range(n1):
            p = T[k] * hi[k]
            if p > pmax:
                pmax = p
            if k > 0 and A * pmax + B >= target:
                Tp = (target - B) / A
                for i in range(k):
                    T[i] = Tp * lo[i]
                return x_out
            A += w[k] * lo[k]
            B -= w[k] * T[k]
        x, Td = load_on_line(x_in, c_pull, bx, bF, bs)
        Tp = Td / lo[n1 - 1]
        for i in range(n1):
            T[i] = Tp * lo[i]
        return x
    if target < e_old:
        A = 0.0
        B = e_old
        qmin = math.inf
        for k in range(n1):
            q = T[k] * lo[k]
            if q < qmin:
                qmin = q
            if k > 0 and A * qmin + B <= target:
                Tp = (target - B) / A
                if Tp < 0.0:
                    Tp = 0.0
                for i in range(k):
                    T[i] = Tp * hi[i]
                return x_out
            A += w[k] * hi[k]
            B -= w[k] * T[k]
        x, Td = load_on_line(x_in, c_rel, bx, bF, bs)
        Tp = Td / hi[n1 - 1]
        for i in range(n1):
            T[i] = Tp * hi[i]
        return x
    return x_out


@njit(cache=True, nogil=True)
def _distal_clip_elongation(T, w, dlo, dhi, Td):  # pragma: no cover - compiled
    e = 0.0
    for i in range(T.shape[0]):
        t = T[i]
        a = Td * dlo[i]
        b = Td * dhi[i]
        if t < a:
            t = a
        elif t > b:
            t = b
        e += w[i] * t
    return e


@njit(cache=True, nogil=True)
def settle_distal(T, lo, hi, w, x_in, x_out, bx, bF, bs):  # pragma: no cover - compiled
    """Re-balance the distal end after the load law changed, proximal end held at ``x_in`` [m].

    Slip spreads from the distal end: with dlo[i] = exp(-mu (theta_n - theta_i)) and dhi = 1/dlo,
    T[i] <- min(max(T[i], T_d dlo[i]), T_d dhi[i]) (it may reach the clamped proximal node). The
    distal tension T_d is the smallest value with x_hi(T_d) + elongation(T_d) >= x_in, found by
    bisection to machine precision (both terms are monotone in T_d); x_out is x_in - elongation
    clipped to the graph interval [x_lo(T_d), x_hi(T_d)]. Returns the new x_out [m].
    """
    n1 = T.shape[0]
    Td_old = T[n1 - 1]
    xl, xh = load_inverse(Td_old, bx, bF, bs)
    tol = 1e-12 * (1.0 + abs(x_out))
    if xl - tol <= x_out <= xh + tol:
        return x_out  # the old distal state still satisfies the new load law
    dlo = lo[n1 - 1] / lo  # exp(-mu (theta_n - theta_i))
    dhi = 1.0 / dlo
    a = 0.0
    b = max(1.0, 2.0 * Td_old)
    for _ in range(200):
        if load_inverse(b, bx, bF, bs)[1] + _distal_clip_elongation(T, w, dlo, dhi, b) >= x_in:
            break
        b *= 2.0
    for _ in range(200):
        mid = 0.5 * (a + b)
        if mid <= a or mid >= b:
            break
        if load_inverse(mid, bx, bF, bs)[1] + _distal_clip_elongation(T, w, dlo, dhi, mid) >= x_in:
            b = mid
        else:
            a = mid
    Td = b
    for i in range(n1):
        t = T[i]
        lo_i = Td * dlo[i]
        hi_i = Td * dhi[i]
        if t < lo_i:
            t = lo_i
        elif t > hi_i:
            t = hi_i
        T[i] = t
    xl, xh = load_inverse(Td, bx, bF, bs)
    x = x_in - elongation(T, w)
    if x < xl:
        x = xl
    elif x > xh:
        x = xh
    return x
