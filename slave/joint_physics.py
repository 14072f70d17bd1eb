"""Compiled step of one simulated antagonistic joint: two distributed tendons coupled at a pulley.

:class:`slave.joint_rig.SimulatedInstrument` owns the state and explains the model; this module is
pure numerics on float64 arrays. Per tendon j (a, b), nodes i = 0..n proximal to distal:

    T[i]          node tension [N] (the tension-profile memory, modified in place)
    lo, hi        e^{-g_i}, e^{+g_i}, g_i = mu theta(s_i)                          (proximal envelope)
    dlo, dhi      e^{-(K - g_i)}, e^{+(K - g_i)}                                    (distal envelope)
    w             trapezoid weights [m/N], elongation e = sum(w T)
    c_pull, c_rel e / T_d of the whole tendon sliding toward the actuator / the tip [m/N]

Kinematics of the joint (rigid sheaths, both tendons on a pulley of radius r):

    x_out,a = + r theta,     x_out,b = - r theta,     e_j = x_in,j - x_out,j (taut)

One step is a Lie splitting of the quasi-static problem, first order in the step:

A. the motors move to their new x_in with the joint held: slip spreads from each proximal end
   (:func:`slave.simulated_physics.advance_proximal`, called with a rigid distal stop);
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
from slave.simulated_physics import advance_proximal

__all__ = ["RIGID_STOP", "load_torque", "joint_torque_balance", "settle_joint", "step_joint"]

#: Load graph of a rigid distal stop for advance_proximal (the distal end cannot move): x = 0 for any
#: tension below 1e200 N. With x_out = 0 and x_in = e wanted, the kernel returns the held profile.
RIGID_STOP = (np.zeros(1), np.full(1, 1e200), np.ones(1))


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

    ``slope`` [N m/rad] > 0 scales the first bracket step (an upper estimate of -df/dtheta).
    """
    ea = elongation(Ta, wa)
    eb = elongation(Tb, wb)
    args = (Ta, dlo_a, dhi_a, wa, ea, xa_in, Tb, dlo_b, dhi_b, wb, eb, xb_in, r, theta_prev, k, damp_dt,
            tissue_k, tissue_c, lim_lo, lim_hi, k_lim, tau_ext)
    f0 = joint_torque_balance(theta_prev, *args)
    theta = theta_prev
    if f0 != 0.0:
        # expanding bracket from theta_prev in the direction of the torque imbalance
        h = f0 / slope
        x0, y0 = theta_prev, f0
        x1 = theta_prev + h
        y1 = joint_torque_balance(x1, *args)
        for _ in range(200):
            if (y1 > 0.0) != (f0 > 0.0) or y1 == 0.0:
                break
            x0, y0 = x1, y1
            h *= 2.0
            x1 = theta_prev + h
            y1 = joint_torque_balance(x1, *args)
        # Illinois regula falsi on [x0, x1] (y0 and y1 of opposite signs, or y1 == 0)
        if x0 > x1:
            x0, x1, y0, y1 = x1, x0, y1, y0
        side = 0
        theta = x1 if y1 == 0.0 else x0
        for _ in range(200):
            if y0 == 0.0:
                theta = x0
                break
            if y1 == 0.0:
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
            if y == 0.0:
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
