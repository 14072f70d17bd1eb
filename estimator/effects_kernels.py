"""Compiled kernel of the extended profile-memory model: the base estimator plus every effect's knob.

One kernel runs the tension-profile memory of :mod:`estimator.sheath` with all extensions of
:mod:`estimator.effects` at once; an extension that is off sits at its neutral value, so the base
model is the kernel with every knob neutral and extensions compose. Per sample k, with the node
shape u_i = theta_i / theta_L in [0, 1] and weights w_i (sum 1):

    K_k   = max(K + K_rate t_k, 0) (1 + c_v |v_k|)           drift and viscous friction   (E6, E3)
    bound = K_k (1 + r_s) while stuck, else K_k               static friction              (E4)
    Y_p   = max(T_in,k, 0) + a                                 tension-independent friction (E8)
    Y_i  <- clip(Y_i, Y_p e^{-bound u_i}, Y_p e^{+bound u_i}), Y_i >= a, node by node from the
            proximal end until a node does not change (slip spreads from the proximal end)
    T_out = Y_n - a
    E1    = sum_i w_i phi(Y_i - a) - phi(T0),   phi(T) = T + beta T_c (1 - e^{-T/T_c})       (E9, E5)

and x_out = x_in - (L/EA) E1 (a taut tendon). The profile starts uniform at T0 (pretension, E5; the encoders are
zeroed there). Stiction: the tendon starts stuck; when the slip front reaches the distal node at the
static bound it breaks away and the whole profile follows Y_p e^{-+K_k f u_i} with
f = 1 + r_s e^{-(t - t_b)/t_slip} for 5 t_slip (or until the proximal end turns back faster than
V_STOP); it sticks again after t_stick without distal slip.
The same rules drive the simulated rig (slave/simulated.py), there in displacement instead of T_in.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["run_extended", "V_STOP"]

V_STOP = 2e-4   # proximal speed against the breakaway direction that ends the slide [m/s]


@njit(cache=True, nogil=True)
def _phi(T, beta, Tc):  # pragma: no cover - compiled
    if beta == 0.0:
        return T
    return T - beta * Tc * math.expm1(-T / Tc)


@njit(cache=True, nogil=True)
def _kernel(T_in, v, t, u, w, K, a, T0, K_rate, c_v, r_s, t_stick, t_slip, T_min, beta, Tc,
            T_out, E1):  # pragma: no cover - compiled
    m1 = u.shape[0]
    Y = np.full(m1, T0 + a)
    E0 = _phi(T0, beta, Tc)
    E = E0
    varying = K_rate != 0.0 or c_v != 0.0
    stiction = r_s > 0.0
    g_kin = np.exp(-K * u)
    g_sta = np.exp(-K * (1.0 + r_s) * u)
    stuck = True
    t_last = t[0] if t.shape[0] else 0.0
    t_b = -math.inf
    direction = 0
    for k in range(T_in.shape[0]):
        tk = t[k]
        Kk = K
        if varying:
            Kk = K + K_rate * (tk - t[0])
            if Kk < 0.0:
                Kk = 0.0
            Kk *= 1.0 + c_v * abs(v[k])
        Yp = T_in[k]
        if Yp < 0.0:
            Yp = 0.0
        Yp += a
        if stiction and not stuck and tk - t_b < 5.0 * t_slip and v[k] * direction < -V_STOP:
            t_b = -math.inf     # the proximal end turned back: the breakaway slide is over
        if stiction and not stuck and tk - t_b < 5.0 * t_slip:
            # after breakaway: the whole tendon slides while mu relaxes to kinetic
            f = Kk * (1.0 + r_s * math.exp(-(tk - t_b) / t_slip)) * direction
            E = 0.0
            for i in range(m1):
                y = Yp * math.exp(-f * u[i])
                if y < a:
                    y = a
                Y[i] = y
                E += w[i] * _phi(y - a, beta, Tc)
            t_last = tk
        else:
            use_static = stiction and stuck
            bound = Kk * (1.0 + r_s) if use_static else Kk
            slid = 0
            for i in range(m1):
                if varying:
                    g = math.exp(-bound * u[i])
                elif use_static:
                    g = g_sta[i]
                else:
                    g = g_kin[i]
                y = Y[i]
                lo = Yp * g
                hi = Yp / g
                if y < lo:
                    ny = lo
                    d = 1
                elif y > hi:
                    ny = hi if hi > a else a
                    d = -1
                else:
                    break
                if ny == y:
                    break
                E += w[i] * (_phi(ny - a, beta, Tc) - _phi(y - a, beta, Tc))
                Y[i] = ny
                if i == m1 - 1:
                    slid = d
            if stiction:
                if slid != 0 and stuck:
                    stuck = False
                    if Yp - a >= T_min:  # a breakaway below T_min is lost in the noise
                        t_b = tk
                        direction = slid
                if slid != 0:
                    t_last = tk
                elif tk - t_last >= t_stick:
                    stuck = True
        T_out[k] = Y[m1 - 1] - a
        E1[k] = E - E0


def run_extended(T_in: np.ndarray, velocity: np.ndarray, time: np.ndarray, u: np.ndarray, w: np.ndarray, *,
                 K: float, a: float = 0.0, T0: float = 0.0, K_rate: float = 0.0, c_v: float = 0.0,
                 r_s: float = 0.0, t_stick: float = 0.03, t_slip: float = 0.02, T_min: float = 0.0,
                 beta: float = 0.0, Tc: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Run the extended profile-memory model over a recording (module docstring for the equations).

    Parameters
    ----------
    T_in : ndarray, shape (n,)
        Proximal tension [N] (after any sensor correction).
    velocity : ndarray, shape (n,)
        Proximal velocity dx_in/dt [m/s]; |v| is the sliding speed.
    time : ndarray, shape (n,)
        Sample times [s], increasing.
    u : ndarray, shape (m + 1,)
        Normalised wrap angle of the nodes, 0 (proximal) to 1 (distal), non-decreasing.
    w : ndarray, shape (m + 1,)
        Trapezoid weights, sum 1.
    K : float
        Friction exponent [-], >= 0.
    a : float
        Tension offset [N], >= 0 (E8). T0 : initial uniform tension [N], >= 0 (E5).
    K_rate : float
        dK/dt [1/s] (E6). c_v : viscous coefficient [s/m], >= 0 (E3).
    r_s : float
        mu_static / mu_kinetic - 1 [-], >= 0 (E4); t_stick, t_slip [s] its stick and relaxation times;
        breakaways below the proximal tension T_min [N] switch to kinetic without the relaxation.
    beta, Tc : float
        Stiffening: extra compliance at zero tension [-] and its tension scale [N], > 0 (E9).

    Returns
    -------
    T_out : ndarray, shape (n,)
        Distal tension [N].
    E1 : ndarray, shape (n,)
        Elongation per compliance [N]: elongation = (L/EA) E1, zero in the initial state.
    """
    T_in = np.ascontiguousarray(T_in, dtype=np.float64)
    T_out = np.empty_like(T_in)
    E1 = np.empty_like(T_in)
    _kernel(T_in, np.ascontiguousarray(velocity, dtype=np.float64), np.ascontiguousarray(time, dtype=np.float64),
            np.ascontiguousarray(u, dtype=np.float64), np.ascontiguousarray(w, dtype=np.float64), float(K),
            float(a), float(T0), float(K_rate), float(c_v), float(r_s), float(t_stick), float(t_slip), float(T_min),
            float(beta), float(Tc), T_out, E1)
    return T_out, E1
