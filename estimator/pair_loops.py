"""The compiled time loop of the capstan-joint pair model (:mod:`estimator.pair_kernels`, (P1)-(P4)).

One loop, :func:`run_pair`, over the samples [i0, i1) of a command, with ``substeps`` steps per sample, on a
state passed in and updated in place: the batch model runs it once over a recorded command, the per-cycle
form (:class:`estimator.online.pair_model.PairModelEstimator`) once per sample on the same state layout, so both
run the same compiled sample step. Its variants (``kind``):

* :data:`KIND_PLAIN`     the mechanism with the series compliance, joint friction and stiffening joint;
* :data:`KIND_TOE`       with the toe tendon (E9 of docs/concepts/effects.md): node weights that change
  from step to step;
* :data:`KIND_BEND`      with friction in the bending section, whose wrap is the joint angle (E7);
* :data:`KIND_OBSERVED`  the drive-side observer, reading the measured proximal tensions.

Each substep moves the motors with the joint held (slip spreads from each proximal end,
:func:`estimator.kernels.advance_proximal`), then settles the joint with the motors held
(:func:`estimator.kernels.settle_joint`).

State layout (m nodes per tendon, proximal to distal; :func:`start_pair` fills it):

* ``nodes``  float64 (2, 5, m): per tendon (a, b) the rows lo, hi, dlo, dhi, w of
  :func:`estimator.pair_kernels.tendon_arrays` (read only);
* ``par``    float64 (:data:`N_PAR`,): the parameters at the ``P_*`` indices (read only);
* ``prof``   float64 (2, m): the tension profiles of tendons a and b [N] (P2);
* ``st``     float64 (:data:`N_ST`,): the scalars at the ``ST_*`` indices (joint angle, previous command,
  references of (P1) and (P4));
* ``band``   float64 (3, 1): the rigid distal stop of :func:`estimator.kernels.advance_proximal` (x, F, slope;
  read only).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from estimator.distal_slip import distal_clip, distal_tension, elongation
from estimator.kernels import advance_proximal, joint_torque_balance, settle_joint

__all__ = ["BIG", "KIND_PLAIN", "KIND_TOE", "KIND_BEND", "KIND_OBSERVED", "N_PAR", "N_ST", "P_G", "P_K", "P_TAU_C",
           "P_K2", "P_THC", "P_RHO", "P_TC", "P_MUB", "P_LAM_D", "P_CPA", "P_CRA", "P_CPB", "P_CRB", "ST_TH",
           "ST_PREV", "ST_C0", "ST_XA0", "ST_XB0", "ST_TAU0", "ST_SLOPE", "ST_PA", "ST_PB", "ST_MA0", "ST_MB0",
           "start_pair", "run_pair"]

#: an angle bound no joint reaches [rad]: no stiffening, no end stop
BIG = 1e200

#: variants of the model (module docstring)
KIND_PLAIN, KIND_TOE, KIND_BEND, KIND_OBSERVED = 0, 1, 2, 3

#: indices of ``par``: G [-], k [N/rad], tau_c [N], k2 [N/rad], theta_c [rad] (BIG without k2), toe ratio rho [-],
#: toe tension T_c [N], mu_b [1/rad], lam_d [rad/N], c_pull and c_rel of tendons a and b [rad/N]
P_G, P_K, P_TAU_C, P_K2, P_THC, P_RHO, P_TC, P_MUB, P_LAM_D, P_CPA, P_CRA, P_CPB, P_CRB = range(13)
N_PAR = 13

#: indices of ``st``: joint angle theta [rad] (from the start), previous command [rad], first command c_0 [rad],
#: initial elongations x_a0, x_b0 [rad], rest torque tau_0 [N], balance slope [N/rad], previous measured proximal
#: tensions [N] and their first values T_m,a(0), T_m,b(0) [N] (observer)
ST_TH, ST_PREV, ST_C0, ST_XA0, ST_XB0, ST_TAU0, ST_SLOPE, ST_PA, ST_PB, ST_MA0, ST_MB0 = range(11)
N_ST = 11


@njit(cache=True)
def start_pair(c0, ma0, mb0, P, nodes, par, prof, st, band):  # pragma: no cover - compiled
    """Fill the state for a run starting at command ``c0`` [rad] with measured proximal tensions ``ma0``,
    ``mb0`` [N] (the observer's references; any value otherwise): the profiles from ``P`` (2, m) [N], theta = 0,
    the elongations, the rest torque tau_0 = T_d,a - T_d,b (so the rest is an equilibrium, (P4)), the rigid stop
    and the joint's balance slope (k + k2 + both tendons' stiffness at their lower envelopes)."""
    Ta = prof[0]
    Tb = prof[1]
    Ta[:] = P[0]
    Tb[:] = P[1]
    wa = nodes[0, 4]
    wb = nodes[1, 4]
    st[ST_TH] = 0.0
    st[ST_PREV] = c0
    st[ST_C0] = c0
    st[ST_XA0] = elongation(Ta, wa)
    st[ST_XB0] = elongation(Tb, wb)
    st[ST_TAU0] = Ta[Ta.shape[0] - 1] - Tb[Tb.shape[0] - 1]
    st[ST_SLOPE] = (par[P_K] + par[P_K2] + 1.0 / max(elongation(nodes[0, 0], wa), 1e-9)
                    + 1.0 / max(elongation(nodes[1, 0], wb), 1e-9))
    st[ST_PA] = ma0
    st[ST_PB] = mb0
    st[ST_MA0] = ma0
    st[ST_MB0] = mb0
    band[0, 0] = 0.0
    band[1, 0] = 1e200
    band[2, 0] = 1.0


@njit(cache=True)
def run_pair(kind, c, Tm, i0, i1, substeps, nodes, par, prof, st, band, theta, T_in):  # pragma: no cover
    """Run the samples [i0, i1) of the command ``c`` [rad] (shape (n,)) on the state (module docstring), with
    ``substeps`` >= 1 steps per sample; ``Tm`` [N] (shape (n, 2)) the measured proximal tensions
    (:data:`KIND_OBSERVED` only; any (0, 2) array otherwise). Writes the joint angle ``theta[i]`` [rad] and the
    proximal tensions ``T_in[i, :]`` [N] of every sample run."""
    # the loop runs on arrays of its own, copied in and (the profiles) out: on views into the packed state the
    # compiled kernels run about 1.5 times slower
    Ta, Tb = prof[0].copy(), prof[1].copy()
    lo_a, hi_a, dlo_a, dhi_a, wa = (nodes[0, 0].copy(), nodes[0, 1].copy(), nodes[0, 2].copy(), nodes[0, 3].copy(),
                                    nodes[0, 4].copy())
    lo_b, hi_b, dlo_b, dhi_b, wb = (nodes[1, 0].copy(), nodes[1, 1].copy(), nodes[1, 2].copy(), nodes[1, 3].copy(),
                                    nodes[1, 4].copy())
    sbx, sbF, sbs = band[0].copy(), band[1].copy(), band[2].copy()
    m = Ta.shape[0]
    va, vb, Ta0, Tb0 = np.empty(m), np.empty(m), np.empty(m), np.empty(m)
    G, k, cpa, cra, cpb, crb = par[P_G], par[P_K], par[P_CPA], par[P_CRA], par[P_CPB], par[P_CRB]
    for i in range(i0, i1):
        if kind == KIND_TOE:
            _toe_sample(c[i], substeps, Ta, Tb, lo_a, hi_a, dlo_a, dhi_a, wa, lo_b, hi_b, dlo_b, dhi_b, wb, par, st,
                        va, vb, Ta0, Tb0, sbx, sbF, sbs)
        elif kind == KIND_BEND:
            _bend_sample(c[i], substeps, Ta, Tb, lo_a, hi_a, dlo_a, dhi_a, wa, cpa, cra, lo_b, hi_b, dlo_b, dhi_b,
                         wb, cpb, crb, G, k, par[P_MUB], st, sbx, sbF, sbs)
        elif kind == KIND_OBSERVED:
            _observed_sample(c[i], Tm[i, 0], Tm[i, 1], substeps, Ta, Tb, lo_a, hi_a, dlo_a, dhi_a, wa, cpa, cra,
                             lo_b, hi_b, dlo_b, dhi_b, wb, cpb, crb, G, k, par[P_LAM_D], st, sbx, sbF, sbs)
            st[ST_PA] = Tm[i, 0]
            st[ST_PB] = Tm[i, 1]
        else:
            _plain_sample(c[i], substeps, Ta, Tb, lo_a, hi_a, dlo_a, dhi_a, wa, cpa, cra, lo_b, hi_b, dlo_b, dhi_b,
                          wb, cpb, crb, G, k, par[P_TAU_C], par[P_K2], par[P_THC], st, sbx, sbF, sbs)
        st[ST_PREV] = c[i]
        theta[i] = st[ST_TH]
        T_in[i, 0] = Ta[0]
        T_in[i, 1] = Tb[0]
    prof[0, :] = Ta
    prof[1, :] = Tb


@njit(cache=True, inline="always")
def _motor_substep(Ta, Tb, lo_a, hi_a, wa, cpa, cra, lo_b, hi_b, wb, cpb, crb, xa0, xb0, G, u, th, sbx, sbF,
                   sbs):  # pragma: no cover - compiled
    """One motor substep with the joint held at ``th`` [rad]: the motors' positions for the command offset
    ``u`` [rad] (``xa0 + G u``, ``xb0 - G u``, (P1)) and both proximal profiles advanced to them; returns
    (xa, xb)."""
    xa = xa0 + G * u
    xb = xb0 - G * u
    advance_proximal(Ta, lo_a, hi_a, wa, cpa, cra, xa - th, 0.0, sbx, sbF, sbs)
    advance_proximal(Tb, lo_b, hi_b, wb, cpb, crb, xb + th, 0.0, sbx, sbF, sbs)
    return xa, xb


@njit(cache=True, inline="always")
def _plain_sample(ci, substeps, Ta, Tb, lo_a, hi_a, dlo_a, dhi_a, wa, cpa, cra, lo_b, hi_b, dlo_b, dhi_b, wb, cpb,
                  crb, G, k, tau_c, k2, thc, st, sbx, sbF, sbs):  # pragma: no cover - compiled
    """One sample of the plain mechanism (:data:`KIND_PLAIN`): per substep the motors move with the joint held,
    then the joint stays while the torque imbalance lies within tau_c and otherwise settles (P4)."""
    th, prev, c0, tau0, xa0, xb0 = st[ST_TH], st[ST_PREV], st[ST_C0], st[ST_TAU0], st[ST_XA0], st[ST_XB0]
    for s in range(substeps):
        xa, xb = _motor_substep(Ta, Tb, lo_a, hi_a, wa, cpa, cra, lo_b, hi_b, wb, cpb, crb, xa0, xb0, G,
                                prev + (ci - prev) * (s + 1) / substeps - c0, th, sbx, sbF, sbs)
        tau = tau0
        if tau_c > 0.0:
            f0 = joint_torque_balance(th, Ta, dlo_a, dhi_a, wa, elongation(Ta, wa), xa, Tb, dlo_b, dhi_b, wb,
                                      elongation(Tb, wb), xb, 1.0, th, k, 0.0, k2, thc, -BIG, BIG, 0.0, tau0)
            if abs(f0) <= tau_c:
                continue
            tau = tau0 + (tau_c if f0 > 0.0 else -tau_c)
        th = settle_joint(Ta, dlo_a, dhi_a, wa, xa, Tb, dlo_b, dhi_b, wb, xb, 1.0, th, k, 0.0, k2, thc,
                          -BIG, BIG, 0.0, tau, st[ST_SLOPE])
    st[ST_TH] = th


@njit(cache=True, inline="always")
def _observed_sample(ci, ma, mb, substeps, Ta, Tb, lo_a, hi_a, dlo_a, dhi_a, wa, cpa, cra, lo_b, hi_b, dlo_b, dhi_b,
                     wb, cpb, crb, G, k, lam_d, st, sbx, sbF, sbs):  # pragma: no cover - compiled
    """One sample of the drive-side observer (:data:`KIND_OBSERVED`, ``lam_d``): the sheath entries sit at
    x_a = x_a0 + G (c - c_0) - lam_d (T_m,a - T_m,a(0)), x_b = x_b0 - G (c - c_0) - lam_d (T_m,b - T_m,b(0)),
    with the measured proximal tensions ``ma``, ``mb`` [N] interpolated linearly in the substeps."""
    th, prev, c0, pa, pb = st[ST_TH], st[ST_PREV], st[ST_C0], st[ST_PA], st[ST_PB]
    for s in range(substeps):
        f = (s + 1) / substeps
        u = prev + (ci - prev) * f - c0
        ta = pa + (ma - pa) * f - st[ST_MA0]
        tb = pb + (mb - pb) * f - st[ST_MB0]
        # the motors' step with each entry's origin moved back by the drive's stretch
        xa, xb = _motor_substep(Ta, Tb, lo_a, hi_a, wa, cpa, cra, lo_b, hi_b, wb, cpb, crb, st[ST_XA0] - lam_d * ta,
                                st[ST_XB0] - lam_d * tb, G, u, th, sbx, sbF, sbs)
        th = settle_joint(Ta, dlo_a, dhi_a, wa, xa, Tb, dlo_b, dhi_b, wb, xb, 1.0, th, k, 0.0, 0.0, BIG,
                          -BIG, BIG, 0.0, st[ST_TAU0], st[ST_SLOPE])
    st[ST_TH] = th


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


@njit(cache=True, inline="always")
def _toe_sample(ci, substeps, Ta, Tb, lo_a, hi_a, dlo_a, dhi_a, wa, lo_b, hi_b, dlo_b, dhi_b, wb, par, st, va, vb,
                Ta0, Tb0, sbx, sbF, sbs):  # pragma: no cover - compiled
    """One sample with the toe tendon (:data:`KIND_TOE`, E9; node weights ``va``, ``vb`` and the profiles
    before the substep ``Ta0``, ``Tb0`` are scratch): each substep is predicted with the tangent compliance at
    the old profile, then redone with the secant compliance between the old and the predicted profile
    (second order in the step; exact when the profile does not move)."""
    rho, Tc, G, k, tau_c, k2, thc = par[P_RHO], par[P_TC], par[P_G], par[P_K], par[P_TAU_C], par[P_K2], par[P_THC]
    th, prev, tau0, slope = st[ST_TH], st[ST_PREV], st[ST_TAU0], st[ST_SLOPE]
    for _s in range(substeps):
        du = G * (ci - prev) / substeps
        Ta0[:] = Ta
        Tb0[:] = Tb
        cpa, cra = _toe_weights(Ta0, Ta0, wa, lo_a, hi_a, rho, Tc, va)
        cpb, crb = _toe_weights(Tb0, Tb0, wb, lo_b, hi_b, rho, Tc, vb)
        _toe_step(Ta, Tb, lo_a, hi_a, dlo_a, dhi_a, va, cpa, cra, lo_b, hi_b, dlo_b, dhi_b, vb, cpb, crb, du, th, k,
                  tau_c, tau0, k2, thc, slope, sbx, sbF, sbs)
        cpa, cra = _toe_weights(Ta0, Ta, wa, lo_a, hi_a, rho, Tc, va)
        cpb, crb = _toe_weights(Tb0, Tb, wb, lo_b, hi_b, rho, Tc, vb)
        Ta[:] = Ta0
        Tb[:] = Tb0
        th = _toe_step(Ta, Tb, lo_a, hi_a, dlo_a, dhi_a, va, cpa, cra, lo_b, hi_b, dlo_b, dhi_b, vb, cpb, crb, du,
                       th, k, tau_c, tau0, k2, thc, slope, sbx, sbF, sbs)
    st[ST_TH] = th


@njit(cache=True)
def _bend_balance(th, s, mub, Ta, dlo_a, dhi_a, wa, ea, xa, Tb, dlo_b, dhi_b, wb, eb, xb, k, tau0):  # pragma: no cover
    """Torque balance [N] of the joint moving in direction s (+1 / -1) at angle ``th`` [rad] with the
    motors held, the bending section's capstan factor e^{-+s mu_b |th|} on each distal tension."""
    tda = distal_tension(Ta, dlo_a, dhi_a, wa, ea, xa - th)
    tdb = distal_tension(Tb, dlo_b, dhi_b, wb, eb, xb + th)
    b = s * mub * abs(th)
    return tda * math.exp(-b) - tdb * math.exp(b) - k * th - tau0


@njit(cache=True)  # not inlined: inlined into run_pair the bend variant runs about 1.5 times slower
def _bend_sample(ci, substeps, Ta, Tb, lo_a, hi_a, dlo_a, dhi_a, wa, cpa, cra, lo_b, hi_b, dlo_b, dhi_b, wb, cpb,
                 crb, G, k, mub, st, sbx, sbF, sbs):  # pragma: no cover - compiled
    """One sample with friction in the bending section (:data:`KIND_BEND`, ``mu_b``): per substep the motors
    move with the joint held, then the joint stays while the balance lies in its band and otherwise moves to
    the first zero of the balance in the direction it points (bracket, bisection)."""
    th, prev, c0, tau0, slope = st[ST_TH], st[ST_PREV], st[ST_C0], st[ST_TAU0], st[ST_SLOPE]
    for j in range(substeps):
        xa, xb = _motor_substep(Ta, Tb, lo_a, hi_a, wa, cpa, cra, lo_b, hi_b, wb, cpb, crb, st[ST_XA0], st[ST_XB0],
                                G, prev + (ci - prev) * (j + 1) / substeps - c0, th, sbx, sbF, sbs)
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
    st[ST_TH] = th
