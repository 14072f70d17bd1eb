"""Compiled kernel of the extended profile-memory model: the base estimator plus every effect's knob.

One kernel runs the tension-profile memory of :mod:`estimator.sheath` with all extensions of
:mod:`estimator.offline.effects.catalogue` at once; an extension that is off sits at its neutral value, so the base
model is the kernel with every knob neutral and extensions compose. Per sample k, with the node
shape u_i = theta_i / theta_L in [0, 1] and weights w_i (sum 1):

    K_k   = max(K + K_rate t_k + dK [t_k >= t_s], 0) (1 + c_v v_k)   drift, step, viscous friction (E6, E3),
            v_k the sliding speed (|dx_in/dt|, or a held mix with the distal speed), t_k counted from the
            first sample, [.] 1 where true (the friction steps by dK at the instant t_s: a reshaped sheath)
    Y_p   = max(T_in,k, 0) + a                                 tension-independent friction (E8)
    T_out = Y_n - a
    E1    = sum_i w_i phi(Y_i - a) - phi(T0),   phi(T) = T + beta T_c (1 - e^{-T/T_c})       (E9, E5)

and x_out = x_in - (L/EA) E1 (a taut tendon). The profile Y_i = T_i + a starts uniform at T0
(pretension, E5; the encoders are zeroed there) - or, given the distal rest reading T0_out, at T0 within the
friction band above it, min(T0, T0_out e^{K (1 - u_i)}) (a load that holds less than the preload lets the
distal part slide back) - and is updated in one of two ways:

* stuck distal end (the memory rule of the base model):
      Y_i <- clip(Y_i, (Y_p - h) e^{-b u_i}, (Y_p + h) e^{+b u_i}), Y_i >= a,
  node by node from the proximal end until a node does not change (by more than NODE_ROUNDING of its tension: a
  node latched on its bound sits there to rounding), with b = K_k, or
  K_k (1 + r_s) with static friction (E4: the tendon is stuck whenever it does not slide).
  The early stop holds while b is at least the steepest exponent the profile was written with (K_prof: a slide's,
  or a bound that moved a node); a friction that has fallen below it by more than the band (K_prof - b) Y_p > h
  (a pull that slows under viscous friction, a drift or a step down) tightens the bounds beyond a node that holds,
  so every node is checked and the profile written at the higher friction relaxes to the lower one (the distal
  tension of a slowing pull rises as its friction falls); K_prof is then b.
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

The sample loop is :func:`estimator.extended_loop.run_span` (with V_STOP, BREAK_MARGIN and phi there), which the
per-cycle estimator (:class:`estimator.online.extended.ExtendedEstimator`) runs one sample at a time on the same
state. The simulated rig (slave/simulated.py) follows the same rules, there driven by displacement.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from estimator.extended_loop import (
    N_PAR,
    N_ST,
    P_A,
    P_BAND,
    P_BETA,
    P_C_V,
    P_K,
    P_K_RATE,
    P_K_STEP,
    P_R_S,
    P_SIGMA,
    P_T0,
    P_T_MIN,
    P_T_SLIP,
    P_T_STEP,
    P_TC,
    P_V_ST,
    run_span,
    start_extended,
)

__all__ = ["run_extended", "distal_slide", "travel_lag", "backlash_play"]


@njit(cache=True, nogil=True)
def _kernel(T_in, v, spd, t, u, w, K, a, T0, K_rate, c_v, r_s, t_slip, T_min, sigma, beta, Tc, v_st,
            T0_out, band, K_step, t_step, slide, T_out, E1):  # pragma: no cover - compiled
    """The whole recording through the shared sample loop (:func:`estimator.extended_loop.run_span`) from rest."""
    m1 = u.shape[0]
    par = np.empty(N_PAR)
    par[P_K], par[P_A], par[P_T0], par[P_K_RATE], par[P_C_V], par[P_R_S] = K, a, T0, K_rate, c_v, r_s
    par[P_T_SLIP], par[P_T_MIN], par[P_SIGMA], par[P_BETA], par[P_TC] = t_slip, T_min, sigma, beta, Tc
    par[P_V_ST], par[P_BAND], par[P_K_STEP], par[P_T_STEP] = v_st, band, K_step, t_step
    Y = np.empty(m1)
    st = np.empty(N_ST)
    tab = np.empty((3, m1))
    start_extended(u, w, par, T0_out, Y, st, tab)
    run_span(T_in, v, spd, t, slide, 0, T_in.shape[0], u, w, par, Y, st, tab, np.zeros(m1), np.zeros(m1), T_out, E1)


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
                 T0_out: float = -1.0, band: float = 0.0, K_step: float = 0.0, t_step: float = 0.0,
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
    K_step, t_step : float
        The friction step (a reshaped sheath): K is K + K_step [-] from ``t_step`` [s] after the first sample on.
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
            float(sigma), float(beta), float(Tc), float(v_st), float(T0_out), float(band), float(K_step),
            float(t_step),
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
    x = np.ascontiguousarray(x_out, dtype=np.float64)
    d = np.empty(x.shape[0], dtype=np.int8)
    _slide(x, float(travel), int(window), d)
    return d


@njit(cache=True, nogil=True)
def _slide(x, travel, window, d):  # pragma: no cover - compiled
    """distal_slide's loop: the play of half-width ``travel``, its travel summed from the start (c) and differenced
    over ``window`` samples, in the order numpy's cumulative sum adds."""
    n = x.shape[0]
    c = np.empty(n + 1)
    c[0] = 0.0
    p = x[0]                # the play starts on the first sample: its first step is 0
    for k in range(n):
        prev = p
        if x[k] - p > travel:
            p = x[k] - travel
        elif p - x[k] > travel:
            p = x[k] + travel
        step = p - prev
        c[k + 1] = c[k] + step
        moved = c[k + 1] - c[max(k + 1 - window, 0)]
        if step * moved <= 0.0:
            d[k] = 0
        elif moved > travel:
            d[k] = 1
        elif moved < -travel:
            d[k] = -1
        else:
            d[k] = 0
