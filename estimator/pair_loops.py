"""The compiled time loops of the capstan-joint pair model (:mod:`estimator.pair_kernels`, (P1)-(P4)).

One loop per variant of the model, each over the samples of a recorded command with ``substeps`` steps
per sample, writing the joint angle ``theta`` [rad] (shape (n,)) and the proximal tensions ``T_in`` [N]
(shape (n, 2)) in place:

* :func:`simulate_plain`     the mechanism with the series compliance, joint friction and stiffening joint;
* :func:`simulate_toe`       with the toe tendon (E9 of docs/concepts/effects.md): node weights that change
  from step to step;
* :func:`simulate_bend`      with friction in the bending section, whose wrap is the joint angle (E7);
* :func:`simulate_observed`  the drive-side observer, reading the measured proximal tensions.

Each substep moves the motors with the joint held (slip spreads from each proximal end,
:func:`estimator.kernels.advance_proximal`), then settles the joint with the motors held
(:func:`estimator.kernels.settle_joint`). The arrays are those of :func:`estimator.pair_kernels.tendon_arrays`.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from estimator.distal_slip import distal_clip, distal_tension, elongation
from estimator.kernels import advance_proximal, joint_torque_balance, settle_joint

__all__ = ["BIG", "simulate_plain", "simulate_toe", "simulate_bend", "simulate_observed"]

#: an angle bound no joint reaches [rad]: no stiffening, no end stop
BIG = 1e200


@njit(cache=True)
def _toe_weights(T0, T1, w0, lo, hi, rho, Tc, out):  # pragma: no cover - compiled
    """Weights [rad/N] of the toe tendon (E9) for a step from profile T0 to T1: per node the secant
    compliance lam_i (phi(T1) - phi(T0)) / (T1 - T0) of phi(T) = T + rho Tc (1 - e^{-T/Tc}) (the
    tangent 1 + rho e^{-T0/Tc} where T1 = T0); returns (c_pull, c_rel) of those weights."""
    for i in range(T0.shape[0]):
        d = T1[i] - T0[i]
        e0 = math.exp(-T0[i] / Tc)
        if abs(d) > 1e-9 * (1.0 + T0[i]):
            out[i] = w0[i] * (1.0 + rho * Tc * (e0 - math.exp(-T1[i] / Tc)) / d)
        else:
            out[i] = w0[i] * (1.0 + rho * e0)
    n1 = T0.shape[0]
    cp = 0.0
    cr = 0.0
    for i in range(n1):
        cp += out[i] * lo[i]
        cr += out[i] * hi[i]
    return cp / lo[n1 - 1], cr / hi[n1 - 1]


@njit(cache=True)
def _toe_step(Ta, Tb, lo_a, hi_a, dlo_a, dhi_a, wa, cpa, cra, lo_b, hi_b, dlo_b, dhi_b, wb, cpb, crb, du, th, k,
              tau_c, tau0, k2, thc, slope, sbx, sbF, sbs):  # pragma: no cover - compiled
    """One substep of (P1)-(P4) in relative form (the toe tendon's weights change from step to step,
    so the motors' travel ``du`` (G times the command change) is added to the present elongation);
    returns the new angle [rad]; the profiles are updated in place."""
    advance_proximal(Ta, lo_a, hi_a, wa, cpa, cra, elongation(Ta, wa) + du, 0.0, sbx, sbF, sbs)
    advance_proximal(Tb, lo_b, hi_b, wb, cpb, crb, elongation(Tb, wb) - du, 0.0, sbx, sbF, sbs)
    xa = elongation(Ta, wa) + th
    xb = elongation(Tb, wb) - th
    tau = tau0
    if tau_c > 0.0:
        f0 = joint_torque_balance(th, Ta, dlo_a, dhi_a, wa, elongation(Ta, wa), xa, Tb, dlo_b, dhi_b, wb,
                                  elongation(Tb, wb), xb, 1.0, th, k, 0.0, k2, thc, -BIG, BIG, 0.0, tau0)
        if abs(f0) <= tau_c:
            return th
        tau = tau0 + (tau_c if f0 > 0.0 else -tau_c)
    return settle_joint(Ta, dlo_a, dhi_a, wa, xa, Tb, dlo_b, dhi_b, wb, xb, 1.0, th, k, 0.0, k2, thc,
                        -BIG, BIG, 0.0, tau, slope)


@njit(cache=True)
def _start(Pa, Pb, wa, wb, lo_a, lo_b, k_total):  # pragma: no cover - compiled
    """The simulation kernels' initial state: copies of the profiles, their elongations, the distal
    tension difference, the stick-band scratch arrays and the joint's balance slope (k_total + both
    tendons' stiffness at their lower envelopes)."""
    Ta = Pa.copy()
    Tb = Pb.copy()
    slope = k_total + 1.0 / max(elongation(lo_a, wa), 1e-9) + 1.0 / max(elongation(lo_b, wb), 1e-9)
    return (Ta, Tb, elongation(Ta, wa), elongation(Tb, wb), Ta[Ta.shape[0] - 1] - Tb[Tb.shape[0] - 1],
            np.zeros(1), np.full(1, 1e200), np.ones(1), slope)


@njit(cache=True)
def simulate_toe(c, G, Pa, Pb, lo_a, hi_a, dlo_a, dhi_a, wa, lo_b, hi_b, dlo_b, dhi_b, wb, k, tau_c, substeps,
                  theta, T_in, k2, thc, rho, Tc):  # pragma: no cover - compiled
    """:func:`simulate_plain` with the toe tendon (E9): each substep is predicted with the tangent
    compliance at the old profile, then redone with the secant compliance between the old and the
    predicted profile (second order in the step; exact when the profile does not move)."""
    Ta, Tb, _, _, tau0, sbx, sbF, sbs, slope = _start(Pa, Pb, wa, wb, lo_a, lo_b, k + k2)
    va = np.empty_like(wa)
    vb = np.empty_like(wb)
    th = 0.0
    prev = c[0]
    for i in range(c.shape[0]):
        for _s in range(substeps):
            du = G * (c[i] - prev) / substeps
            Ta0 = Ta.copy()
            Tb0 = Tb.copy()
            cpa, cra = _toe_weights(Ta0, Ta0, wa, lo_a, hi_a, rho, Tc, va)
            cpb, crb = _toe_weights(Tb0, Tb0, wb, lo_b, hi_b, rho, Tc, vb)
            _toe_step(Ta, Tb, lo_a, hi_a, dlo_a, dhi_a, va, cpa, cra, lo_b, hi_b, dlo_b, dhi_b, vb, cpb, crb, du,
                      th, k, tau_c, tau0, k2, thc, slope, sbx, sbF, sbs)
            cpa, cra = _toe_weights(Ta0, Ta, wa, lo_a, hi_a, rho, Tc, va)
            cpb, crb = _toe_weights(Tb0, Tb, wb, lo_b, hi_b, rho, Tc, vb)
            Ta[:] = Ta0
            Tb[:] = Tb0
            th = _toe_step(Ta, Tb, lo_a, hi_a, dlo_a, dhi_a, va, cpa, cra, lo_b, hi_b, dlo_b, dhi_b, vb, cpb, crb,
                           du, th, k, tau_c, tau0, k2, thc, slope, sbx, sbF, sbs)
        prev = c[i]
        theta[i] = th
        T_in[i, 0] = Ta[0]
        T_in[i, 1] = Tb[0]


@njit(cache=True)
def _motor_substep(Ta, Tb, lo_a, hi_a, wa, cpa, cra, lo_b, hi_b, wb, cpb, crb, xa0, xb0, G, u, th, sbx, sbF,
                   sbs):  # pragma: no cover - compiled
    """One motor substep with the joint held at ``th``: the motors' positions for the command offset
    ``u`` (``xa0 + G u``, ``xb0 - G u``) and both proximal profiles advanced to them; returns (xa, xb)."""
    xa = xa0 + G * u
    xb = xb0 - G * u
    advance_proximal(Ta, lo_a, hi_a, wa, cpa, cra, xa - th, 0.0, sbx, sbF, sbs)
    advance_proximal(Tb, lo_b, hi_b, wb, cpb, crb, xb + th, 0.0, sbx, sbF, sbs)
    return xa, xb


@njit(cache=True)
def simulate_plain(c, G, Pa, Pb, lo_a, hi_a, dlo_a, dhi_a, wa, cpa, cra, lo_b, hi_b, dlo_b, dhi_b, wb, cpb, crb,
              k, tau_c, substeps, theta, T_in, k2, thc):  # pragma: no cover - compiled
    Ta, Tb, xa0, xb0, tau0, sbx, sbF, sbs, slope = _start(Pa, Pb, wa, wb, lo_a, lo_b, k + k2)
    th = 0.0
    c0 = c[0]
    prev = c[0]
    for i in range(c.shape[0]):
        for s in range(substeps):
            xa, xb = _motor_substep(Ta, Tb, lo_a, hi_a, wa, cpa, cra, lo_b, hi_b, wb, cpb, crb, xa0, xb0, G,
                                    prev + (c[i] - prev) * (s + 1) / substeps - c0, th, sbx, sbF, sbs)
            tau = tau0
            if tau_c > 0.0:
                f0 = joint_torque_balance(th, Ta, dlo_a, dhi_a, wa, elongation(Ta, wa), xa, Tb, dlo_b, dhi_b, wb,
                                          elongation(Tb, wb), xb, 1.0, th, k, 0.0, k2, thc, -BIG, BIG, 0.0,
                                          tau0)
                if abs(f0) <= tau_c:
                    continue
                tau = tau0 + (tau_c if f0 > 0.0 else -tau_c)
            th = settle_joint(Ta, dlo_a, dhi_a, wa, xa, Tb, dlo_b, dhi_b, wb, xb, 1.0, th, k, 0.0, k2, thc,
                              -BIG, BIG, 0.0, tau, slope)
        prev = c[i]
        theta[i] = th
        T_in[i, 0] = Ta[0]
        T_in[i, 1] = Tb[0]


@njit(cache=True)
def simulate_observed(c, Tma, Tmb, lam_d, G, Pa, Pb, lo_a, hi_a, dlo_a, dhi_a, wa, cpa, cra, lo_b, hi_b, dlo_b,
                       dhi_b, wb, cpb, crb, k, substeps, theta, T_in):  # pragma: no cover - compiled
    """:func:`simulate_plain` with the drive-side observer (module docstring, ``lam_d``): the sheath entries sit at
    x_a = x_a0 + G (c - c_0) - lam_d (T_m,a - T_m,a(0)), x_b = x_b0 - G (c - c_0) - lam_d (T_m,b - T_m,b(0)),
    with the measured proximal tensions ``Tma``, ``Tmb`` [N] (shape (n,)) interpolated linearly in the substeps."""
    Ta, Tb, xa0, xb0, tau0, sbx, sbF, sbs, slope = _start(Pa, Pb, wa, wb, lo_a, lo_b, k)
    th = 0.0
    c0 = c[0]
    prev = c[0]
    pa = Tma[0]
    pb = Tmb[0]
    for i in range(c.shape[0]):
        for s in range(substeps):
            f = (s + 1) / substeps
            u = prev + (c[i] - prev) * f - c0
            ta = pa + (Tma[i] - pa) * f - Tma[0]
            tb = pb + (Tmb[i] - pb) * f - Tmb[0]
            # the motors' step with each entry's origin moved back by the drive's stretch
            xa, xb = _motor_substep(Ta, Tb, lo_a, hi_a, wa, cpa, cra, lo_b, hi_b, wb, cpb, crb, xa0 - lam_d * ta,
                                    xb0 - lam_d * tb, G, u, th, sbx, sbF, sbs)
            th = settle_joint(Ta, dlo_a, dhi_a, wa, xa, Tb, dlo_b, dhi_b, wb, xb, 1.0, th, k, 0.0, 0.0, BIG,
                              -BIG, BIG, 0.0, tau0, slope)
        prev = c[i]
        pa = Tma[i]
        pb = Tmb[i]
        theta[i] = th
        T_in[i, 0] = Ta[0]
        T_in[i, 1] = Tb[0]


@njit(cache=True)
def _bend_balance(th, s, mub, Ta, dlo_a, dhi_a, wa, ea, xa, Tb, dlo_b, dhi_b, wb, eb, xb, k, tau0):  # pragma: no cover
    """Torque balance [N] of the joint moving in direction s (+1 / -1) at angle ``th`` [rad] with the
    motors held, the bending section's capstan factor e^{-+s mu_b |th|} on each distal tension."""
    tda = distal_tension(Ta, dlo_a, dhi_a, wa, ea, xa - th)
    tdb = distal_tension(Tb, dlo_b, dhi_b, wb, eb, xb + th)
    b = s * mub * abs(th)
    return tda * math.exp(-b) - tdb * math.exp(b) - k * th - tau0


@njit(cache=True)
def simulate_bend(c, G, Pa, Pb, lo_a, hi_a, dlo_a, dhi_a, wa, cpa, cra, lo_b, hi_b, dlo_b, dhi_b, wb, cpb, crb, k,
                   mub, substeps, theta, T_in):  # pragma: no cover - compiled
    """:func:`simulate_plain` with friction in the bending section (``mu_b``, module docstring): per substep
    the motors move with the joint held, then the joint stays while the balance lies in its band and
    otherwise moves to the first zero of the balance in the direction it points (bracket, bisection)."""
    Ta, Tb, xa0, xb0, tau0, sbx, sbF, sbs, slope = _start(Pa, Pb, wa, wb, lo_a, lo_b, k)
    th = 0.0
    c0 = c[0]
    prev = c[0]
    for i in range(c.shape[0]):
        for j in range(substeps):
            xa, xb = _motor_substep(Ta, Tb, lo_a, hi_a, wa, cpa, cra, lo_b, hi_b, wb, cpb, crb, xa0, xb0, G,
                                    prev + (c[i] - prev) * (j + 1) / substeps - c0, th, sbx, sbF, sbs)
            ea = elongation(Ta, wa)
            eb = elongation(Tb, wb)
            s = 1.0
            f = _bend_balance(th, 1.0, mub, Ta, dlo_a, dhi_a, wa, ea, xa, Tb, dlo_b, dhi_b, wb, eb, xb, k, tau0)
            if f <= 0.0:
                s = -1.0
                f = _bend_balance(th, -1.0, mub, Ta, dlo_a, dhi_a, wa, ea, xa, Tb, dlo_b, dhi_b, wb, eb, xb, k, tau0)
                if f >= 0.0:
                    continue                              # inside the band: the joint stays
            x0 = th
            h = s * max(abs(f) / slope, 1e-12)
            x1 = th + h
            for _ in range(200):                          # expand until the balance changes sign
                if s * _bend_balance(x1, s, mub, Ta, dlo_a, dhi_a, wa, ea, xa, Tb, dlo_b, dhi_b, wb, eb, xb, k,
                                     tau0) <= 0.0:
                    break
                x0 = x1
                h *= 2.0
                x1 = th + h
            lo = min(x0, x1)
            hi = max(x0, x1)
            while hi - lo > 1e-13 * (1.0 + abs(hi)):       # the balance falls with theta on the bracket
                mid = 0.5 * (lo + hi)
                if _bend_balance(mid, s, mub, Ta, dlo_a, dhi_a, wa, ea, xa, Tb, dlo_b, dhi_b, wb, eb, xb, k,
                                 tau0) > 0.0:
                    lo = mid
                else:
                    hi = mid
            th = 0.5 * (lo + hi)
            distal_clip(Ta, dlo_a, dhi_a, distal_tension(Ta, dlo_a, dhi_a, wa, ea, xa - th))
            distal_clip(Tb, dlo_b, dhi_b, distal_tension(Tb, dlo_b, dhi_b, wb, eb, xb + th))
        prev = c[i]
        theta[i] = th
        T_in[i, 0] = Ta[0]
        T_in[i, 1] = Tb[0]
