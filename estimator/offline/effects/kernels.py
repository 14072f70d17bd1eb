"""Compiled kernel of the extended profile-memory model: the base estimator plus every effect's knob.

One kernel runs the tension-profile memory of :mod:`estimator.sheath` with all extensions of
:mod:`estimator.offline.effects.catalogue` at once; an extension that is off sits at its neutral value, so the base
model is the kernel with every knob neutral and extensions compose. Per sample k, with the node
shape u_i = theta_i / theta_L in [0, 1] and weights w_i (sum 1):

    K_k   = max(K + K_rate t_k, 0) (1 + c_v v_k)             drift and viscous friction   (E6, E3),
            v_k the sliding speed (|dx_in/dt|, or a held mix with the distal speed)
    Y_p   = max(T_in,k, 0) + a                                 tension-independent friction (E8)
    T_out = Y_n - a
    E1    = sum_i w_i phi(Y_i - a) - phi(T0),   phi(T) = T + beta T_c (1 - e^{-T/T_c})       (E9, E5)

and x_out = x_in - (L/EA) E1 (a taut tendon). The profile Y_i = T_i + a starts uniform at T0
(pretension, E5; the encoders are zeroed there) - or, given the distal rest reading T0_out, at T0 within the
friction band above it, min(T0, T0_out e^{K (1 - u_i)}) (a load that holds less than the preload lets the
distal part slide back) - and is updated in one of two ways:

* stuck distal end (the memory rule of the base model):
      Y_i <- clip(Y_i, (Y_p - h) e^{-b u_i}, (Y_p + h) e^{+b u_i}), Y_i >= a,
  node by node from the proximal end until a node does not change, with b = K_k, or
  K_k (1 + r_s) with static friction (E4: the tendon is stuck whenever it does not slide).
  h [N] is the noise band of the reading T_in (``band``; 0 on exact data): the rule latches
  extremes, and on a noisy reading it would latch the noise's own (a hold of a few hundred
  samples reaches about 3 sigma), so the profile moves only for what exceeds h; on exact data h
  is a dead zone (estimator.offline.effects.catalogue.NOISE_BAND).
  When the update reaches the distal node the whole tendon slides in that direction s. It slides too where the
  measured distal end is seen moving the way the proximal end moves while T_in has not turned back by more than
  2 sigma (``slide``; at a reversal the averaged T_in turns before the distal end stops): a stuck distal
  part holds the distal end, so a moving distal end means the slip has reached it, whatever the memory with
  the fitted K holds (with a constant-force load the release sits on the edge of the band, and the memory
  alone matches the load's constant T_out for any K that is too large);
* sliding (s != 0, while the proximal end keeps moving that way faster than V_STOP):
      Y_i = Y_p e^{-s K_k f u_i},  f = 1 + r_s e^{-(t - t_b)/t_slip}
  the whole profile follows T_in at the present sliding friction (so it follows a change of
  speed or K at once); f > 1 only after a breakaway at t_b (static friction relaxing to kinetic).
  The distal end of a sliding tendon only moves on, so a T_out that would turn back by more than
  the noise ends the slide too (a reversal shows in the averaged T_in before x_in turns), except
  within 5 t_slip of a breakaway, where the averaging blunts the turn of T_in, and except on the sample
  where a distal end seen moving starts the slide (the full-slip T_out may then jump either way, which
  is how a K that only the memory's band allowed shows).
  A breakaway is also taken when T_in turns back within BREAK_MARGIN of the static threshold
  while the proximal end keeps going (the breakaway peak, blunted by the averaging of the data),
  and below T_min it is too small to see and gets no relaxation.

The simulated rig (slave/simulated.py) follows the same rules, there driven by displacement.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = [
    "run_extended", "distal_slide", "stiffening_strain", "travel_lag", "backlash_play", "V_STOP", "BREAK_MARGIN",
]

V_STOP = 2e-4        # proximal speed below which a slide ends (the tendon sticks) [m/s]
BREAK_MARGIN = 0.35  # share of the kinetic-static gap within which a turn of T_in counts as breakaway [-]


@njit(cache=True, nogil=True)
def stiffening_strain(T, beta, Tc):  # pragma: no cover - compiled
    """phi(T) [N]: tension-equivalent strain of a stiffening tendon, T + beta T_c (1 - e^{-T/T_c})
    (T when beta = 0); elongation = (L/EA) int phi(T) ds. Used by the estimator and the simulated rig."""
    if beta == 0.0:
        return T
    return T - beta * Tc * math.expm1(-T / Tc)


@njit(cache=True, nogil=True)
def _stribeck_bound(Y, Yp, a, u, w, Kk, r_s, v_st, vp, dY, G):  # pragma: no cover - compiled
    """Cumulative friction exponent G_i of a stuck tendon whose nodes near the proximal end slip (Stribeck form).

    A kinetic trial update gives the slip zone and each node's change of tension dY_i; a node's sliding
    speed is the proximal speed vp times the share of the slip zone's stretch change beyond it (the
    distal part of the zone feeds the node's travel; 0 at the slip front and beyond). Node i's bound is
    K (1 + r_s e^-(v_i/v_st)^2) per unit of wrap angle: static at rest, kinetic well above v_st."""
    m1 = u.shape[0]
    tot = 0.0
    nf = -1
    for i in range(m1):
        g = math.exp(-Kk * u[i])
        y = Y[i]
        lo = Yp * g
        hi = Yp / g
        if hi < a:
            hi = a
        if y < lo:
            d = lo - y
        elif y > hi:
            d = y - hi
        else:
            break
        dY[i] = w[i] * d
        tot += dY[i]
        nf = i
    beyond = 0.0
    for i in range(m1 - 1, -1, -1):
        vi = 0.0
        if i <= nf and tot > 0.0:       # in the slip zone; the proximal node moves with the proximal end
            vi = vp if i == 0 else vp * beyond / tot
            beyond += dY[i]
        G[i] = Kk * (1.0 + r_s * math.exp(-(vi / v_st) ** 2))     # the node's bound, per wrap angle
    acc = 0.0
    prev = G[0]
    for i in range(m1):
        if i > 0:
            acc += 0.5 * (G[i] + prev) * (u[i] - u[i - 1])
        prev = G[i]
        G[i] = acc if i > 0 else 0.0
    return nf


@njit(cache=True, nogil=True)
def _kernel(T_in, v, spd, t, u, w, K, a, T0, K_rate, c_v, r_s, t_slip, T_min, sigma, beta, Tc, v_st,
            T0_out, band, slide, T_out, E1):  # pragma: no cover - compiled
    m1 = u.shape[0]
    Y = np.full(m1, T0 + a)
    E0 = stiffening_strain(T0, beta, Tc)
    if T0 > 0.0 and T0_out >= 0.0:
        # a load that holds less than the preload let the distal part slide back to what it holds: T0 capped by
        # the friction band above the distal rest reading T0_out (a distal reading above T0 leaves it uniform)
        E0 = 0.0
        for i in range(m1):
            y = min(T0, T0_out * math.exp(K * (1.0 - u[i])))
            Y[i] = y + a
            E0 += w[i] * stiffening_strain(y, beta, Tc)
    E = E0
    varying = K_rate != 0.0 or c_v != 0.0
    stiction = r_s > 0.0
    stribeck = stiction and v_st > 0.0    # the Stribeck form: static-kinetic by each node's own speed
    dY = np.zeros(m1)
    G = np.zeros(m1)
    g_kin = np.exp(-K * u)
    g_kin_inv = 1.0 / g_kin
    g_sta = np.exp(-K * (1.0 + r_s) * u)
    sliding = 0                     # direction of the whole-tendon slide, 0 when the distal end sticks
    t_b = -math.inf
    Yp_prev = Y[0]
    seen = slide.shape[0] > 0
    for k in range(T_in.shape[0]):
        tk = t[k]
        Kk = K
        if varying:
            Kk = K + K_rate * (tk - t[0])
            if Kk < 0.0:
                Kk = 0.0
            Kk *= 1.0 + c_v * spd[k]
        Yp = T_in[k]
        if Yp < 0.0:
            Yp = 0.0
        Yp += a
        if sliding != 0 and v[k] * sliding <= V_STOP:
            sliding = 0             # the proximal end stopped or turned: the tendon sticks
            t_b = -math.inf
        forced = 0
        if seen and slide[k] != 0 and v[k] * slide[k] > V_STOP and (Yp - Yp_prev) * slide[k] >= -2.0 * sigma:
            forced = slide[k]       # both ends seen moving one way, T_in not turned back: the whole tendon slides
        stuck = stiction and sliding == 0
        if stuck and not stribeck and k > 0 and Yp_prev - a >= T_min and abs(v[k]) > V_STOP:
            # breakaway seen as a turn of T_in near the static threshold while the proximal end goes on
            dm = 1 if v[k] > 0.0 else -1
            yn = Y[m1 - 1]
            gk = math.exp(-Kk * u[m1 - 1] * dm)
            gs = math.exp(-Kk * (1.0 + r_s) * u[m1 - 1] * dm)
            near = yn / gk + (1.0 - BREAK_MARGIN) * (yn / gs - yn / gk)
            if (Yp_prev - near) * dm >= 0.0 and (Yp_prev - Yp) * dm > 2.0 * sigma:
                sliding = dm
                t_b = t[k - 1]
        Yp_prev = Yp
        entered = forced != 0 and sliding != forced
        if entered:
            if stuck and not stribeck and Yp - a >= T_min:
                t_b = tk            # breakaway from static friction
            sliding = forced
        if sliding != 0:
            f = Kk
            if stribeck:
                f *= 1.0 + r_s * math.exp(-(v[k] / v_st) ** 2)
            elif t_b > -math.inf:
                f *= 1.0 + r_s * math.exp(-(tk - t_b) / t_slip)
            g_n = math.exp(-f * sliding * u[m1 - 1])
            if not entered and tk - t_b > 5.0 * t_slip and (Yp * g_n - Y[m1 - 1]) * sliding < -2.0 * sigma * g_n:
                # a sliding distal end only moves on (T_out rises pulling, falls releasing): T_in
                # turned back beyond the noise, the tendon sticks (the averaged T_in turns before x_in)
                sliding = 0
                t_b = -math.inf
        if sliding != 0:
            E = 0.0
            fixed = not varying and not stribeck and t_b == -math.inf      # the kinetic bound: tabulated
            for i in range(m1):
                if fixed:
                    y = Yp * (g_kin[i] if sliding > 0 else g_kin_inv[i])
                else:
                    y = Yp * math.exp(-f * sliding * u[i])
                if y < a:
                    y = a
                Y[i] = y
                E += w[i] * stiffening_strain(y - a, beta, Tc)
        else:
            bound = Kk * (1.0 + r_s) if stuck else Kk
            if stribeck:
                _stribeck_bound(Y, Yp, a, u, w, Kk, r_s, v_st, abs(v[k]), dY, G)
            for i in range(m1):
                if stribeck:
                    g = math.exp(-G[i])
                elif varying:
                    g = math.exp(-bound * u[i])
                elif stuck:
                    g = g_sta[i]
                else:
                    g = g_kin[i]
                y = Y[i]
                lo = (Yp - band) * g
                hi = (Yp + band) / g
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
                E += w[i] * (stiffening_strain(ny - a, beta, Tc) - stiffening_strain(y - a, beta, Tc))
                Y[i] = ny
                if i == m1 - 1:         # the slip reached the distal end: the whole tendon slides
                    sliding = d
                    if stuck and not stribeck and Yp - a >= T_min:
                        t_b = tk        # breakaway from static friction
        T_out[k] = Y[m1 - 1] - a
        E1[k] = E - E0


@njit(cache=True, nogil=True)
def _travel_lag(F, x, x_p, out):  # pragma: no cover - compiled
    y = F[0]
    out[0] = y
    for k in range(1, F.shape[0]):
        y = F[k] + (y - F[k]) * math.exp(-abs(x[k] - x[k - 1]) / x_p)
        out[k] = y


def travel_lag(F: np.ndarray, x: np.ndarray, x_p: float) -> np.ndarray:
    """Pre-sliding (E2, a Dahl element): F lagged in travel, dF_lag/d|x| = (F - F_lag) / x_p.

    F [N] the friction T_in - T_out of the memory model, x [m] the proximal position, shape (n,);
    x_p [m] > 0 the pre-sliding travel. Rate-independent: the friction reverses over about x_p of
    travel after a reversal instead of at once (rounded loop corners). Returns shape (n,)."""
    out = np.empty(F.shape[0])
    _travel_lag(np.ascontiguousarray(F, dtype=np.float64), np.ascontiguousarray(x, dtype=np.float64), float(x_p),
                out)
    return out


@njit(cache=True, nogil=True)
def _play(x, half, out):  # pragma: no cover - compiled
    p = x[0]
    for k in range(x.shape[0]):
        if x[k] - p > half:
            p = x[k] - half
        elif p - x[k] > half:
            p = x[k] + half
        out[k] = p


def backlash_play(x: np.ndarray, width: float) -> np.ndarray:
    """Backlash (play) operator (E12): the joint position [m], shape (n,), that follows the tendon end
    ``x`` [m] only once it has crossed a gap of total ``width`` [m] >= 0; starts at x[0] (mid-gap)."""
    out = np.empty(x.shape[0])
    _play(np.ascontiguousarray(x, dtype=np.float64), 0.5 * float(width), out)
    return out


def run_extended(T_in: np.ndarray, velocity: np.ndarray, time: np.ndarray, u: np.ndarray, w: np.ndarray, *,
                 K: float, a: float = 0.0, T0: float = 0.0, K_rate: float = 0.0, c_v: float = 0.0,
                 r_s: float = 0.0, t_slip: float = 0.02, T_min: float = 0.0,
                 sigma: float = 0.0, beta: float = 0.0, Tc: float = 1.0,
                 speed: np.ndarray | None = None, v_st: float = 0.0,
                 T0_out: float = -1.0, band: float = 0.0,
                 slide: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Run the extended profile-memory model over a recording (module docstring for the equations).

    Parameters
    ----------
    T_in, velocity, time : ndarray, shape (n,)
        Proximal tension [N] (after any sensor correction), proximal velocity dx_in/dt [m/s] (|v| is the sliding
        speed), sample times [s], increasing.
    u, w : ndarray, shape (m + 1,)
        Normalised wrap angle of the nodes, 0 (proximal) to 1 (distal), non-decreasing; trapezoid weights, sum 1.
    K, a, T0, K_rate, c_v : float
        Friction exponent [-] >= 0; tension offset [N] >= 0 (E8); initial uniform tension [N] >= 0 (E5);
        dK/dt [1/s] (E6); viscous coefficient [s/m] >= 0 (E3).
    r_s, t_slip, T_min, sigma : float
        mu_static / mu_kinetic - 1 [-] >= 0 (E4) and its relaxation time [s] after breakaway; breakaways below
        the proximal tension T_min [N] switch to kinetic without the relaxation; the noise of T_in [N] (a turn
        of T_in must exceed 2 sigma to count as breakaway).
    beta, Tc : float
        Stiffening: extra compliance at zero tension [-] and its tension scale [N], > 0 (E9).
    speed : ndarray, shape (n,), optional
        Sliding speed [m/s] >= 0 in K (1 + c_v speed) (default |velocity|, the proximal speed).
    v_st, T0_out, band : float
        Stiction in its Stribeck form when > 0 [m/s] (each node's bound K (1 + r_s e^-(v_i/v_st)^2) by its own
        sliding speed, no breakaway rule; 0: the breakaway form); the distal tension at rest [N] that caps the
        initial profile with T0 > 0 (< 0: uniform T0); the noise band h [N] >= 0 of the stuck rule (0: exact).
    slide : ndarray of int8, shape (n,), optional
        Direction in which the measured distal end is seen moving (+1, -1, 0; :func:`distal_slide`): where it
        moves the way the proximal end does (faster than V_STOP) the whole tendon slides that way. None: unused.

    Raises
    ------
    ValueError
        ``band`` negative or not finite.

    Returns
    -------
    T_out : ndarray, shape (n,)
        Distal tension [N].
    E1 : ndarray, shape (n,)
        Elongation per compliance [N]: elongation = (L/EA) E1, zero in the initial state.
    """
    if not (math.isfinite(band) and band >= 0.0):
        raise ValueError(f"run_extended: band must be a finite number >= 0 N, got {band!r}")
    T_in = np.ascontiguousarray(T_in, dtype=np.float64)
    T_out = np.empty_like(T_in)
    E1 = np.empty_like(T_in)
    vel = np.ascontiguousarray(velocity, dtype=np.float64)
    spd = np.abs(vel) if speed is None else np.ascontiguousarray(speed, dtype=np.float64)
    _kernel(T_in, vel, spd, np.ascontiguousarray(time, dtype=np.float64),
            np.ascontiguousarray(u, dtype=np.float64), np.ascontiguousarray(w, dtype=np.float64), float(K),
            float(a), float(T0), float(K_rate), float(c_v), float(r_s), float(t_slip), float(T_min),
            float(sigma), float(beta), float(Tc), float(v_st), float(T0_out), float(band),
            np.zeros(0, dtype=np.int8) if slide is None else np.ascontiguousarray(slide, dtype=np.int8), T_out, E1)
    return T_out, E1


def distal_slide(x_out: np.ndarray, travel: float, window: int = 1) -> np.ndarray:
    """Direction in which a measured distal end moves, shape (n,) int8: +1 (toward the actuator), -1, or 0
    where it does not. ``x_out`` [m], shape (n,), is read through a play of half-width ``travel`` [m] > 0 (the
    encoder's resolution: a quantum or the noise), so that noise never counts as motion, and a sample moves
    where that play has moved by more than ``travel`` over the last ``window`` >= 1 samples (a noise maximum
    that creeps up during a hold moves the play by a fraction of the noise now and then, not by ``travel``).

    A distal end moves only when the slip has reached it (a stuck distal part holds it where it is; a
    spring load's x_out follows T_out, which the stuck part holds): where it moves, the whole tendon slides.

    Raises ValueError: ``travel`` not a finite number > 0 or ``window`` < 1."""
    if not (math.isfinite(travel) and travel > 0.0):
        raise ValueError(f"distal_slide: travel must be a finite number > 0 m, got {travel!r}")
    if window < 1:
        raise ValueError(f"distal_slide: window must be >= 1 sample, got {window!r}")
    p = backlash_play(np.asarray(x_out, dtype=np.float64), 2.0 * travel)
    step = np.zeros(p.shape[0])
    step[1:] = p[1:] - p[:-1]
    c = np.concatenate(([0.0], np.cumsum(step)))
    i = np.arange(p.shape[0])
    moved = c[i + 1] - c[np.maximum(i + 1 - window, 0)]
    d = np.where(moved > travel, 1, np.where(moved < -travel, -1, 0)).astype(np.int8)
    d[step * moved <= 0.0] = 0          # moving now, the way the window moved
    return d
