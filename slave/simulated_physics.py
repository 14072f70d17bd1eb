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

import numpy as np
from numba import njit

__all__ = ["advance_proximal", "settle_distal", "load_inverse", "load_on_line", "elongation", "strain",
           "elongation_general", "full_slip", "advance_general"]


@njit(cache=True, nogil=True)
def elongation(T, w):  # pragma: no cover - compiled
    """sum(w * T) [m]."""
    e = 0.0
    for i in range(T.shape[0]):
        e += w[i] * T[i]
    return e


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


# ---- general step for the effect switches (friction offset, stiffening, varying bounds) -----------
#
# With a tension offset a (friction that does not scale with tension, dT/dtheta = -mu (T + a)) the
# envelope rule holds for Y = T + a instead of T, with T >= 0 (Y >= a) where the tendon goes slack.
# With a stiffening tendon the strain of an element is phi(T) / EA,
#     phi(T) = T + beta T_c (1 - exp(-T / T_c))       (tangent compliance (1 + beta e^{-T/T_c}) / EA)
# so the elongation sum(w phi(T_i)) is no longer linear in the proximal tension and each step is
# solved by a bracketed root search instead of the breakpoint scan. G is lo (pull, s = +1) or hi
# (release, s = -1): node i slips to Y_p G_i once Y_p passes the running max (min) of Y_j / G_j.
# When the bounds narrowed since a stuck part was laid down (speed or K dropped), that part is
# steeper than the new envelope and the slip front crosses it at one proximal tension: the step
# then ends with the front inside it (its nodes blended between old and new so that the
# elongation matches x_in - x_out exactly).


@njit(cache=True, nogil=True)
def strain(T, beta, Tc):  # pragma: no cover - compiled
    """phi(T) [N]: tension-equivalent strain of a stiffening tendon (T when beta = 0)."""
    if beta == 0.0:
        return T
    return T - beta * Tc * math.expm1(-T / Tc)


@njit(cache=True, nogil=True)
def elongation_general(T, w, beta, Tc):  # pragma: no cover - compiled
    """sum(w * phi(T)) [m]."""
    e = 0.0
    for i in range(T.shape[0]):
        e += w[i] * strain(T[i], beta, Tc)
    return e


@njit(cache=True, nogil=True)
def _prefix(T, S, G, w, a, beta, Tc, Yp, s, out):  # pragma: no cover - compiled
    """Elongation change [m] if the proximal end goes to Y_p with slip spreading from it.

    S = phi(T) of the old profile. Writes the new node tensions into ``out`` (its first k entries)
    and returns (dE, k), k = number of slipping nodes."""
    n1 = T.shape[0]
    dE = 0.0
    run = -math.inf if s > 0 else math.inf
    for i in range(n1):
        b = (T[i] + a) / G[i]
        if s > 0:
            if b > run:
                run = b
            if Yp < run:
                return dE, i
        else:
            if b < run:
                run = b
            if Yp > run:
                return dE, i
        t = Yp * G[i] - a
        if t < 0.0:
            t = 0.0
        out[i] = t
        dE += w[i] * (strain(t, beta, Tc) - S[i])
    return dE, n1


@njit(cache=True, nogil=True)
def _full(G, w, a, beta, Tc, Td, out):  # pragma: no cover - compiled
    """Elongation [m] of the whole tendon sliding with distal tension T_d (Y_i = Y_d G_i / G_n)."""
    n1 = G.shape[0]
    Yd = (Td + a) / G[n1 - 1]
    e = 0.0
    for i in range(n1):
        t = Yd * G[i] - a
        if t < 0.0:
            t = 0.0
        out[i] = t
        e += w[i] * strain(t, beta, Tc)
    return e


@njit(cache=True, nogil=True)
def _root(lo, f_lo, hi, f_hi, T, S, G, w, a, beta, Tc, s, x_in, target, bx, bF, bs, out, mode):  # pragma: no cover
    """Bracketed root of a non-decreasing f with f(lo) < 0 <= f(hi) (Anderson-Bjorck regula falsi,
    bisection whenever the bracket does not halve). mode 0: f = E(Y_p) - target (prefix slip);
    mode 1: f = x_hi(T_d) + E_full(T_d) - x_in (whole tendon sliding). Returns the final bracket."""
    side = 0
    for it in range(200):
        width = hi - lo
        if width <= 1e-15 * max(1.0, abs(hi)):
            break
        x = hi - f_hi * width / (f_hi - f_lo) if f_hi > f_lo else 0.5 * (lo + hi)
        if it % 3 == 2 or not (lo < x < hi):
            x = 0.5 * (lo + hi)
        if mode == 0:
            fx = _prefix(T, S, G, w, a, beta, Tc, x, s, out)[0] - target
        else:
            fx = load_inverse(x, bx, bF, bs)[1] + _full(G, w, a, beta, Tc, x, out) - x_in
        if fx < 0.0:
            lo, f_lo = x, fx
            if side == -1:
                f_hi *= 0.5
            side = -1
        else:
            if fx == 0.0:
                return x, x
            hi, f_hi = x, fx
            if side == 1:
                f_lo *= 0.5
            side = 1
    return lo, hi


@njit(cache=True, nogil=True)
def full_slip(T, G, w, a, beta, Tc, x_in, bx, bF, bs):  # pragma: no cover - compiled
    """Whole tendon sliding (G = lo pulling, hi releasing): the smallest distal tension T_d with
    x_hi(T_d) + e(T_d) >= x_in; writes the profile into T and returns x_out [m]."""
    out = np.empty_like(T)
    lo = 0.0
    f_lo = load_inverse(0.0, bx, bF, bs)[1] + _full(G, w, a, beta, Tc, 0.0, out) - x_in
    if f_lo >= 0.0:
        hi = 0.0
    else:
        hi = max(1.0, 2.0 * T[T.shape[0] - 1])
        for _ in range(200):
            f_hi = load_inverse(hi, bx, bF, bs)[1] + _full(G, w, a, beta, Tc, hi, out) - x_in
            if f_hi >= 0.0:
                break
            lo, f_lo, hi = hi, f_hi, 2.0 * hi
        lo, hi = _root(lo, f_lo, hi, f_hi, T, T, G, w, a, beta, Tc, 0, x_in, 0.0, bx, bF, bs, out, 1)
    e = _full(G, w, a, beta, Tc, hi, T)
    xl, xh = load_inverse(hi, bx, bF, bs)
    x = x_in - e
    if x < xl:
        x = xl
    elif x > xh:
        x = xh
    return x


@njit(cache=True, nogil=True)
def advance_general(T, lo, hi, w, a, beta, Tc, x_in, x_out, bx, bF, bs):  # pragma: no cover - compiled
    """Move the proximal end to ``x_in`` [m] with tension offset ``a`` [N] and stiffening (beta, T_c).

    Same physics as :func:`advance_proximal` (slip spreading from the proximal end, the distal end
    stuck until the slip front reaches it, then the whole tendon slides on the load graph), solved
    by a bracketed root search on the proximal tension. Returns (x_out [m], s) with s = +1 (-1) when
    the whole tendon slid toward the actuator (tip) in this step, else 0.
    """
    n1 = T.shape[0]
    S = np.empty_like(T)
    for i in range(n1):
        S[i] = strain(T[i], beta, Tc)
    e_old = 0.0
    for i in range(n1):
        e_old += w[i] * S[i]
    target = x_in - x_out
    if abs(target - e_old) <= 4e-16 * (abs(x_in) + abs(x_out) + e_old):
        return x_out, 0
    s = 1 if target > e_old else -1
    G = lo if s > 0 else hi
    # proximal Y at which the slip front reaches the distal node
    Ystar = (T[0] + a) / G[0]
    for i in range(1, n1):
        b = (T[i] + a) / G[i]
        if (s > 0 and b > Ystar) or (s < 0 and b < Ystar):
            Ystar = b
    Y0 = T[0] + a
    dt = target - e_old
    new = np.empty_like(T)
    if s > 0:
        f_hi = _prefix(T, S, G, w, a, beta, Tc, Ystar, s, new)[0] - dt
        if f_hi < 0.0:
            return full_slip(T, G, w, a, beta, Tc, x_in, bx, bF, bs), 1
        y_lo, y_hi = _root(Y0, -dt, Ystar, f_hi, T, S, G, w, a, beta, Tc, s, x_in, dt, bx, bF, bs, new, 0)
        y_in, y_out = y_lo, y_hi
    else:
        floor = max(Ystar, a)
        f_lo = _prefix(T, S, G, w, a, beta, Tc, floor, s, new)[0] - dt
        if f_lo > 0.0:
            if Ystar >= a:
                return full_slip(T, G, w, a, beta, Tc, x_in, bx, bF, bs), -1
            k = _prefix(T, S, G, w, a, beta, Tc, a, s, new)[1]  # slack: the proximal end cannot push
            T[:k] = new[:k]
            return x_out, 0
        y_lo, y_hi = _root(floor, f_lo, Y0, -dt, T, S, G, w, a, beta, Tc, s, x_in, dt, bx, bF, bs, new, 0)
        y_in, y_out = y_hi, y_lo
    # y_in: elongation short of (pull) / above (release) the target; y_out: at or past it
    d_lo, k_lo = _prefix(T, S, G, w, a, beta, Tc, y_in, s, new)
    if (d_lo - dt) * s > 0.0:
        # past the target already at y_in: the front jumps right at the start (a steeper part next to
        # the proximal end), so blend from the old profile
        d_hi, k_hi, d_lo, k_lo = d_lo, k_lo, 0.0, 0
    else:
        T[:k_lo] = new[:k_lo]
        d_hi, k_hi = _prefix(T, S, G, w, a, beta, Tc, y_out, s, new)
    if k_hi > k_lo and d_hi != d_lo:
        # the front crossed a steep stuck part: leave it inside, blending the nodes it passed
        lam = min(1.0, max(0.0, (dt - d_lo) / (d_hi - d_lo)))
        for i in range(k_lo, k_hi):
            new[i] = T[i] + lam * (new[i] - T[i])
    T[:k_hi] = new[:k_hi]
    return x_out, 0
