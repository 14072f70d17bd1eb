"""The tendon-sheath kernels shared by the estimator's models and the simulated rigs (one copy).

Compiled (numba) numerics on float64 arrays of the n + 1 nodes of a tendon, proximal to distal.
The simulators (:mod:`slave.simulated`, :mod:`slave.pair_rig`) and the capstan-joint pair model of
the offline diagnosis (:mod:`estimator.pair_kernels`) call the same functions; the distal-slip
kernels of the online estimator are :mod:`estimator.distal_slip`. Notation (per node ``i = 0..n``):

    T[i]          node tension [N] (the tension-profile memory, modified in place)
    lo[i], hi[i]  exp(-mu theta_i), exp(+mu theta_i) [-], theta_i cumulative wrap angle [rad]
    dlo, dhi      e^{-(K - g_i)}, e^{+(K - g_i)}, g_i = mu theta_i                 (distal envelope)
    w[i]          trapezoid weight [m/N], elongation = sum(w * T)
    c_pull, c_rel e / T_d of the whole tendon sliding toward the actuator / the tip [m/N]

**Single tendon on a distal load.** The distal load is a monotone graph between the distal
displacement x >= 0 [m] and the distal tension T_d [N], stored as a piecewise-linear curve ``F(x)``
for x > 0:

    bx[j]     start of segment j [m] (bx[0] = 0, increasing)
    bF[j]     F(bx[j]+) [N]
    bs[j]     slope of F on segment j [N/m] (> 0 on the last segment)

plus the vertical segment x = 0, T_d in [0, bF[0]] (the lower stop holds the joint while the tendon
pulls less than the set force). The tendon cannot push: T_d >= 0.

**Antagonistic joint.** Rigid sheaths, both tendons on a pulley of radius r:

    x_out,a = + r theta,     x_out,b = - r theta,     e_j = x_in,j - x_out,j (taut)

One step is a Lie splitting of the quasi-static problem, first order in the step:

A. the motors move to their new x_in with the joint held: slip spreads from each proximal end
   (:func:`advance_proximal`, called with the rigid distal stop :data:`RIGID_STOP`);
B. the joint settles with the motors held: slip spreads from each distal end
   (:func:`estimator.distal_slip.distal_tension`) and theta solves the torque balance

       f(theta) = r (T_d,a(theta) - T_d,b(theta)) - tau(theta) = 0,
       tau(theta) = k theta + (b / dt) (theta - theta_prev) + tau_tissue + tau_limit + tau_ext

   (joint spring k, damping b by implicit Euler, tissue spring k_t beyond |theta| > theta_c, stiff
   limits k_lim outside [lo, hi], constant torque). T_d,a falls and T_d,b rises with theta and tau is
   non-decreasing, so f is monotone and piecewise linear: an expanding bracket and the Illinois
   regula falsi find the root to round-off in a few evaluations.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from estimator.distal_slip import distal_clip, distal_tension, elongation

__all__ = [
    "advance_proximal", "settle_distal", "load_inverse", "load_on_line", "RIGID_STOP", "load_torque",
    "joint_torque_balance", "settle_joint", "BALANCE_TOL", "step_joint",
]


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


#: Load graph of a rigid distal stop for advance_proximal (the distal end cannot move): x = 0 for any
#: tension below 1e200 N. With x_out = 0 and x_in = e wanted, the kernel returns the held profile.
RIGID_STOP = (np.zeros(1), np.full(1, 1e200), np.ones(1))

#: The joint's torque balance is solved to this fraction of its torque scale [-] (:func:`settle_joint`): a few
#: units of round-off of the sum r (T_d,a - T_d,b) - tau, well below any physical torque of the joint.
BALANCE_TOL = 1e-13


@njit(cache=True, nogil=True)
def load_torque(theta, k, tissue_k, tissue_c, lim_lo, lim_hi, k_lim, tau_ext):  # pragma: no cover - compiled
    """Static load torque on the joint [N m] at angle ``theta`` [rad] (spring, tissue, limits, external)."""
    tau = k * theta + tau_ext
    if theta > tissue_c:
        tau += tissue_k * (theta - tissue_c)
    elif theta < -tissue_c:
        tau += tissue_k * (theta + tissue_c)
    if theta > lim_hi:
        tau += k_lim * (theta - lim_hi)
    elif theta < lim_lo:
        tau += k_lim * (theta - lim_lo)
    return tau


@njit(cache=True, nogil=True)
def joint_torque_balance(theta, Ta, dlo_a, dhi_a, wa, ea, xa_in, Tb, dlo_b, dhi_b, wb, eb, xb_in, r,
                         theta_prev, k, damp_dt, tissue_k, tissue_c, lim_lo, lim_hi, k_lim,
                         tau_ext):  # pragma: no cover - compiled
    """f(theta) = r (T_d,a - T_d,b) - tau(theta) [N m] (module docstring), profiles not modified."""
    tda = distal_tension(Ta, dlo_a, dhi_a, wa, ea, xa_in - r * theta)
    tdb = distal_tension(Tb, dlo_b, dhi_b, wb, eb, xb_in + r * theta)
    tau = load_torque(theta, k, tissue_k, tissue_c, lim_lo, lim_hi, k_lim, tau_ext) + damp_dt * (theta - theta_prev)
    return r * (tda - tdb) - tau


@njit(cache=True, nogil=True)
def settle_joint(Ta, dlo_a, dhi_a, wa, xa_in, Tb, dlo_b, dhi_b, wb, xb_in, r, theta_prev, k, damp_dt,
                 tissue_k, tissue_c, lim_lo, lim_hi, k_lim, tau_ext, slope):  # pragma: no cover - compiled
    """Step B: the joint angle [rad] with the motors held; both profiles updated in place.

    ``slope`` [N m/rad] > 0 scales the first bracket step (an upper estimate of -df/dtheta). The root
    is taken where |f| <= :data:`BALANCE_TOL` times the torque scale r (T_d,a + T_d,b) + |tau(theta_prev)|
    of the profiles before the step, the round-off level of f (once both ends of the bracket lie on the
    root's linear piece, the secant lands there in one step).
    """
    ea = elongation(Ta, wa)
    eb = elongation(Tb, wb)
    args = (Ta, dlo_a, dhi_a, wa, ea, xa_in, Tb, dlo_b, dhi_b, wb, eb, xb_in, r, theta_prev, k, damp_dt,
            tissue_k, tissue_c, lim_lo, lim_hi, k_lim, tau_ext)
    f0 = joint_torque_balance(theta_prev, *args)
    tol = BALANCE_TOL * (r * (Ta[Ta.shape[0] - 1] + Tb[Tb.shape[0] - 1])
                         + abs(load_torque(theta_prev, k, tissue_k, tissue_c, lim_lo, lim_hi, k_lim, tau_ext)))
    theta = theta_prev
    if abs(f0) > tol:
        # expanding bracket from theta_prev in the direction of the torque imbalance
        h = f0 / slope
        x0, y0 = theta_prev, f0
        x1 = theta_prev + h
        y1 = joint_torque_balance(x1, *args)
        for _ in range(200):
            if (y1 > 0.0) != (f0 > 0.0) or abs(y1) <= tol:
                break
            x0, y0 = x1, y1
            h *= 2.0
            x1 = theta_prev + h
            y1 = joint_torque_balance(x1, *args)
        # Illinois regula falsi on [x0, x1] (y0 and y1 of opposite signs, or y1 == 0)
        if x0 > x1:
            x0, x1, y0, y1 = x1, x0, y1, y0
        side = 0
        theta = x1 if abs(y1) <= tol else x0
        for _ in range(200):
            if abs(y0) <= tol:
                theta = x0
                break
            if abs(y1) <= tol:
                theta = x1
                break
            if x1 - x0 <= 1e-15 * (1.0 + abs(x1)):
                theta = x0 if abs(y0) < abs(y1) else x1
                break
            x = x1 - y1 * (x1 - x0) / (y1 - y0)
            if not (x0 < x < x1):
                x = 0.5 * (x0 + x1)
            y = joint_torque_balance(x, *args)
            theta = x
            if abs(y) <= tol:
                break
            if (y > 0.0) == (y0 > 0.0):
                x0, y0 = x, y
                if side == -1:
                    y1 *= 0.5
                side = -1
            else:
                x1, y1 = x, y
                if side == 1:
                    y0 *= 0.5
                side = 1
    tda = distal_tension(Ta, dlo_a, dhi_a, wa, ea, xa_in - r * theta)
    tdb = distal_tension(Tb, dlo_b, dhi_b, wb, eb, xb_in + r * theta)
    distal_clip(Ta, dlo_a, dhi_a, tda)
    distal_clip(Tb, dlo_b, dhi_b, tdb)
    return theta


@njit(cache=True, nogil=True)
def step_joint(Ta, lo_a, hi_a, dlo_a, dhi_a, wa, cpa, cra, Tb, lo_b, hi_b, dlo_b, dhi_b, wb, cpb, crb,
               xa_in, xb_in, r, theta_prev, k, damp_dt, tissue_k, tissue_c, lim_lo, lim_hi, k_lim, tau_ext,
               slope, sbx, sbF, sbs):  # pragma: no cover - compiled
    """One step (A then B of the module docstring) to motor positions ``xa_in``, ``xb_in`` [m].

    Returns the new joint angle [rad]; both profiles are updated in place. (sbx, sbF, sbs) is
    :data:`RIGID_STOP`.
    """
    # A: proximal slip with the distal ends held at x_out,a = r theta, x_out,b = -r theta
    advance_proximal(Ta, lo_a, hi_a, wa, cpa, cra, xa_in - r * theta_prev, 0.0, sbx, sbF, sbs)
    advance_proximal(Tb, lo_b, hi_b, wb, cpb, crb, xb_in + r * theta_prev, 0.0, sbx, sbF, sbs)
    # B: distal slip and the torque balance with the motors held
    return settle_joint(Ta, dlo_a, dhi_a, wa, xa_in, Tb, dlo_b, dhi_b, wb, xb_in, r, theta_prev, k, damp_dt,
                        tissue_k, tissue_c, lim_lo, lim_hi, k_lim, tau_ext, slope)
