"""Compiled kernels of :mod:`estimator.online.pair`: the pair coupling (J4)/(J5), the slack-weighted
angle (J3) and one whole sample of :class:`~estimator.online.pair.PairEstimator` (both tendons'
profile-memory updates, smoothed rates and readable phases, the coupling, (J1)-(J3)) in one call.
The equations are in :mod:`estimator.online.pair`'s docstring.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from estimator.band import band_update
from estimator.distal_slip import distal_clip, distal_tension, elongation
from estimator.online.distal import velocity_step
from estimator.readable_phase import readable_step
from estimator.sheath import profile_update

__all__ = ["couple", "weighted_angle", "step_pair"]


@njit(cache=True, nogil=True)
def _stretch(T, dlo, dhi, w, K, de):  # pragma: no cover - compiled
    """Distal end of one tendon moved: elongation change ``de`` [m], proximal node held (J4)."""
    e = elongation(T, w)
    Td = distal_tension(T, dlo, dhi, w, e, e + de)
    lo = T[0] * math.exp(-K)
    hi = T[0] * math.exp(K)
    distal_clip(T, dlo, dhi, min(max(Td, lo), hi))


@njit(cache=True, nogil=True)
def _hold(T, dlo, dhi, K, Td):  # pragma: no cover - compiled
    """Set one tendon's distal tension to ``Td`` [N] within its sliding bounds (J5)."""
    lo = T[0] * math.exp(-K)
    hi = T[0] * math.exp(K)
    distal_clip(T, dlo, dhi, min(max(Td, lo), hi))


@njit(cache=True, nogil=True)
def couple(Pa, dloa, dhia, wa, Ka, Pb, dlob, dhib, wb, Kb, Ta_prev, Tb_prev, ua, ub, r, hw,
           state):  # pragma: no cover - compiled
    """Pair coupling (J4)/(J5) after the proximal updates of one sample; profiles updated in place.

    Pa, Pb : float64[n + 1] profiles [N]; dlo*, dhi*, w*: distal gains and weights; K*: friction
    exponents. Ta_prev, Tb_prev: distal tensions before this sample's proximal updates [N];
    ua, ub: kinematic angles (J1) after them [rad]; r [m]; hw: play half-width [rad].
    state : float64[5] (driver 0/1, play output [rad], tau_lock [N m], elongation (J5) gave the
    driven tendon [m], direction of the last play move), updated in place; driver -1 means not
    started (the call only sets it).
    """
    Ta_in = Pa[0]
    Tb_in = Pb[0]
    d = int(state[0])
    if d < 0:
        d = 0 if Ta_in >= Tb_in else 1
        state[0] = d
        state[1] = ua if d == 0 else ub
        state[2] = r * (Pa[Pa.shape[0] - 1] - Pb[Pb.shape[0] - 1])
        state[3] = 0.0
        state[4] = 0.0
        return
    # driver: the tendon with the higher proximal tension, with hysteresis
    if d == 0 and Tb_in > 1.1 * Ta_in + 0.2:
        d = 1
        state[1] = ub
        state[3] = 0.0
        state[4] = 0.0
    elif d == 1 and Ta_in > 1.1 * Tb_in + 0.2:
        d = 0
        state[1] = ua
        state[3] = 0.0
        state[4] = 0.0
    state[0] = d
    u = ua if d == 0 else ub
    y = state[1]
    y_new = min(max(y, u - hw), u + hw)
    delta = y_new - y
    state[1] = y_new
    na = Pa.shape[0] - 1
    nb = Pb.shape[0] - 1
    if delta != 0.0:
        # (J4): the joint turned by delta: e_q -= s_q r delta (x_out,a = +r theta, x_out,b = -r theta),
        # less what (J5) already gave in that direction
        de = r * delta if d == 0 else -r * delta
        sgn = 1.0 if delta > 0.0 else -1.0
        # the play had to be taken up before it moved: none after a move the same way, its whole
        # width after a reversal, half of it from the start; (J5) gave that part already
        take = 0.0 if sgn == state[4] else (2.0 * r * hw if state[4] != 0.0 else r * hw)
        state[4] = sgn
        done = state[3]
        if done * de > 0.0:
            usable = max(0.0, abs(done) - take)
            used = min(abs(de), usable)
            sd = 1.0 if de > 0.0 else -1.0
            de -= sd * used
            state[3] = 0.0 if usable == 0.0 else done - sd * (used + take)
        else:
            state[3] = 0.0
        if de != 0.0:
            if d == 0:
                _stretch(Pb, dlob, dhib, wb, Kb, de)
            else:
                _stretch(Pa, dloa, dhia, wa, Ka, de)
    else:
        # (J5): joint still, torque held; the tendon whose distal tension did not move absorbs
        moved_a = Pa[na] != Ta_prev
        moved_b = Pb[nb] != Tb_prev
        tau = state[2]
        if moved_a and not moved_b:
            e0 = elongation(Pb, wb)
            _hold(Pb, dlob, dhib, Kb, Pa[na] - tau / r)
            if d == 0:
                state[3] += elongation(Pb, wb) - e0
        elif moved_b and not moved_a:
            e0 = elongation(Pa, wa)
            _hold(Pa, dloa, dhia, Ka, Pb[nb] + tau / r)
            if d == 1:
                state[3] += elongation(Pa, wa) - e0
    state[2] = r * (Pa[na] - Pb[nb])


@njit(cache=True, nogil=True)
def _rate_phase(k, T_in, T_out, t, PS, prm, out):  # pragma: no cover - compiled
    """Tendon k's smoothed rate and readable phase, as :meth:`DistalEstimator.step` (step_pair's arrays)."""
    dt = max(t - prm[16 + k], 1e-6)
    a = dt / (prm[6 + k] + dt)
    out[12 + k] = prm[18 + k] + a * ((T_in - prm[14 + k]) / dt - prm[18 + k])
    out[10 + k] = readable_step(PS, max(T_in, 0.0), T_out, t, prm[k], prm[2 + k], prm[4 + k])


@njit(cache=True, nogil=True)
def _tendon_update(P, C, N, k, T_in, x_in, t, prm):  # pragma: no cover - compiled
    """Tendon k's proximal update, as :meth:`DistalEstimator.step`: the smoothed velocity, then the envelope rule
    or (N[k, 0] > 0) the banded update with a slack release side; returns T_out [N]."""
    if not math.isnan(N[k, 2]):
        N[k, 3] = velocity_step(N[k, 3], x_in, N[k, 2], max(t - prm[16 + k], 1e-6), prm[6 + k])
    N[k, 2] = x_in
    if N[k, 0] > 0.0:
        return band_update(P, C[4], C[5], T_in, N[k, 3], N[k, 0], N[k, 1], N[k, 4:6], True)
    return profile_update(P, C[0], T_in)


@njit(cache=True, nogil=True)
def step_pair(Pa, Ca, PSa, Pb, Cb, PSb, prm, state, N, T_in_a, x_in_a, T_in_b, x_in_b, t,
               out):  # pragma: no cover - compiled
    """One sample of :meth:`PairEstimator.step` after the first (both tendons, coupling, (J1)-(J3)).

    Ca, Cb : float64[6, n + 1] log gain, weight, distal gains dlo, dhi, and the gains exp(-+mu theta) of each
    tendon. PSa, PSb: readable phase states. prm : float64[20] K a/b, band a/b, hold rate a/b, tau a/b, x0 a/b, r,
    play half-width, taut tension, coupling flag, previous T_in a/b, previous t a/b, rate a/b.
    N : float64[2, 6] per tendon the noise band h [N] (0: the envelope rule), its sigma [N], the previous x_in [m]
    (NaN: none), the smoothed velocity [m/s] and the banded update's slide state (direction, extreme), updated.
    out : float64[14] torque, angle, T_out a/b, e a/b, x_out a/b, angle a/b, phase a/b, rate a/b.
    Returns False (nothing changed) for a non-finite sample.
    """
    if not (math.isfinite(T_in_a) and math.isfinite(x_in_a) and math.isfinite(T_in_b) and math.isfinite(x_in_b)):
        return False
    Ta_prev = Pa[Pa.shape[0] - 1]
    Tb_prev = Pb[Pb.shape[0] - 1]
    wa = Ca[1]
    wb = Cb[1]
    Ta_out = _tendon_update(Pa, Ca, N, 0, T_in_a, x_in_a, t, prm)
    Tb_out = _tendon_update(Pb, Cb, N, 1, T_in_b, x_in_b, t, prm)
    ea = np.dot(wa, Pa)
    eb = np.dot(wb, Pb)
    _rate_phase(0, T_in_a, Ta_out, t, PSa, prm, out)
    _rate_phase(1, T_in_b, Tb_out, t, PSb, prm, out)
    r = prm[10]
    if prm[13] != 0.0:
        ua = (x_in_a - ea - prm[8]) / r
        ub = -(x_in_b - eb - prm[9]) / r
        couple(Pa, Ca[2], Ca[3], wa, prm[0], Pb, Cb[2], Cb[3], wb, prm[1], Ta_prev, Tb_prev, ua, ub, r, prm[11],
               state)
        if N[0, 0] > 0.0 and Pa[Pa.shape[0] - 1] != Ta_out:
            N[0, 4] = 0.0          # the coupling moved the distal end: the slide is over
        if N[1, 0] > 0.0 and Pb[Pb.shape[0] - 1] != Tb_out:
            N[1, 4] = 0.0
        Ta_out = Pa[Pa.shape[0] - 1]
        Tb_out = Pb[Pb.shape[0] - 1]
        ea = np.dot(wa, Pa)
        eb = np.dot(wb, Pb)
    ang_a = (x_in_a - ea - prm[8]) / r
    ang_b = -(x_in_b - eb - prm[9]) / r
    out[0] = r * (Ta_out - Tb_out)
    out[1] = weighted_angle(ang_a, ang_b, T_in_a, T_in_b, prm[12])
    out[2], out[3], out[4], out[5] = Ta_out, Tb_out, ea, eb
    out[6], out[7], out[8], out[9] = x_in_a - ea, x_in_b - eb, ang_a, ang_b
    return True


@njit(cache=True, nogil=True)
def weighted_angle(ang_a, ang_b, T_a, T_b, taut):  # pragma: no cover - compiled
    """(J3) with the slack weights w_j = min(1, max(T_in,j, 0) / taut)."""
    wa = min(1.0, max(T_a, 0.0) / taut)
    wb = min(1.0, max(T_b, 0.0) / taut)
    if wa + wb <= 0.0:
        return 0.5 * (ang_a + ang_b)
    return (wa * ang_a + wb * ang_b) / (wa + wb)
