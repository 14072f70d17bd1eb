"""The banded update of the tension-profile memory: the envelope rule of :mod:`estimator.sheath` on a noisy reading.

On a noisy reading the rule latches the noise's own extremes (a hold of a few hundred samples reaches about
3 sigma), and the distal estimate carries them: on 24 clean recordings of the independent lumped simulator,
with the true K, route and L/EA, the estimate from the noisy T_in was 14x further from the true T_out than
from the noise-free one (median rms 1.6 % against 0.12 % of full scale, biased low by 0.7 %). The banded
update (:func:`band_update`, the rule of the offline diagnosis and of the online estimators) moves a stuck
profile only for what exceeds a band h of a few noise sigmas,

    T_i <- min( max(T_i, (T_in - h) exp(-mu theta_i)), (T_in + h) exp(+mu theta_i) ),

and once the update reaches the distal node the whole tendon slides: the profile follows T_in exactly,
T_i = T_in exp(-+mu theta_i), while the proximal end keeps moving that way (faster than
:data:`SLIDE_STOP_SPEED`) and T_in does not turn back from the slide's extreme by more than 2 sigma. So the
band costs nothing in a slide, and at a reversal it is a dead zone of h on T_in.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["band_update", "band_batch", "SLIDE_STOP_SPEED", "NOISE_BAND_SIGMAS"]

#: proximal speed below which a whole-tendon slide ends: the proximal end stopped or turned [m/s]
SLIDE_STOP_SPEED = 2e-4
#: width of the noise band of the banded update, in noise sigmas of the T_in reading [-]
NOISE_BAND_SIGMAS = 3.0


@njit(cache=True, nogil=True)
def band_update(T, lo_gain, hi_gain, T_in, v, band, sigma, state, slack=False):  # pragma: no cover - compiled
    """In-place banded update of a tension profile (module docstring); returns the distal tension T[-1] [N].

    T : float64[n + 1] node tensions [N], modified in place.
    lo_gain, hi_gain : float64[n + 1] exp(-mu theta_i) and exp(+mu theta_i).
    T_in : proximal tension [N] (negative read as 0); v : proximal velocity [m/s].
    band : h [N] >= 0; sigma : noise of T_in [N] >= 0 (a slide ends when T_out would turn back by 2 sigma).
    state : float64[2], updated: the direction of the whole-tendon slide (+1 pulling, -1 releasing, 0 stuck) and
    the extreme of T_in in that slide so far [N] (the live data's velocity lags a reversal by its smoothing, so a
    turn of T_in by more than 2 sigma from the slide's extreme ends it too, not only a turn from the last sample).
    slack : a released tendon near zero tension is slack (an antagonistic pair's, whose true T_in and T_out are then
    zero): the release side's band shrinks to T_in, so that the profile falls to zero with the reading.
    With band = sigma = 0 and no slide it is the envelope rule of :func:`estimator.sheath.profile_update`.
    """
    n = T.shape[0]
    if T_in < 0.0:
        T_in = 0.0
    s = state[0]
    if s != 0.0 and v * s <= SLIDE_STOP_SPEED:
        s = 0.0                              # the proximal end stopped or turned: the tendon sticks
    if s != 0.0:
        if (T_in - state[1]) * s > 0.0:
            state[1] = T_in                  # the slide's extreme of T_in so far
        elif (state[1] - T_in) * s > 2.0 * sigma:
            s = 0.0                          # T_in turned back from it beyond the noise: the distal end stops
    if s != 0.0:
        for i in range(n):
            T[i] = T_in * (lo_gain[i] if s > 0.0 else hi_gain[i])
    else:
        h_up = T_in if slack and T_in < band else band
        for i in range(n):
            y = T[i]
            lo = (T_in - band) * lo_gain[i]
            hi = (T_in + h_up) * hi_gain[i]
            if y < lo:
                ny = lo
                d = 1.0
            elif y > hi:
                ny = hi if hi > 0.0 else 0.0
                d = -1.0
            else:
                break
            if ny == y:
                break
            T[i] = ny
            if i == n - 1:                   # the slip reached the distal end: the whole tendon slides
                s = d
                state[1] = T_in
    state[0] = s
    return T[n - 1]


@njit(cache=True, nogil=True)
def _band_batch(T, lo_gain, hi_gain, weight, T_in, v, band, sigma, state, slack, T_out, elong):  # pragma: no cover
    for k in range(T_in.shape[0]):
        T_out[k] = band_update(T, lo_gain, hi_gain, T_in[k], v[k], band, sigma, state, slack)
        e = 0.0
        for i in range(T.shape[0]):
            e += weight[i] * T[i]
        elong[k] = e


def band_batch(T0: np.ndarray, log_gain: np.ndarray, weight: np.ndarray, T_in: np.ndarray, velocity: np.ndarray,
               band: float, sigma: float, slide: tuple[float, float] = (0.0, 0.0), slack: bool = False):
    """Run the banded update (:func:`band_update`) over a recorded series.

    Parameters
    ----------
    T0 : ndarray, shape (n_nodes,)
        Initial profile [N]; not modified.
    log_gain, weight : ndarray, shape (n_nodes,)
        From :meth:`SheathModel.nodes`.
    T_in, velocity : ndarray, shape (n_samples,)
        Proximal tension [N] and proximal velocity [m/s].
    band, sigma : float
        Noise band h [N] and noise sigma [N] of T_in, both >= 0.
    slide : (float, float)
        Slide direction at the start (+1, -1, 0: stuck) and its extreme of T_in [N] (:func:`band_update`).
    slack : bool
        A released tendon near zero tension is slack (:func:`band_update`).

    Returns
    -------
    T_out : ndarray, shape (n_samples,)
        Distal tension [N].
    elongation : ndarray, shape (n_samples,)
        Tendon elongation int T/EA ds [m].
    T_final : ndarray, shape (n_nodes,)
        Profile after the last sample [N].
    slide : (float, float)
        The same after the last sample.

    Raises
    ------
    ValueError
        ``band`` or ``sigma`` negative or not finite, or T_in and velocity of different shapes.
    """
    if not (math.isfinite(band) and band >= 0.0 and math.isfinite(sigma) and sigma >= 0.0):
        raise ValueError(f"band_batch: band and sigma must be finite and >= 0 N, got {band!r}, {sigma!r}")
    T = np.array(T0, dtype=np.float64, copy=True)
    T_in = np.ascontiguousarray(T_in, dtype=np.float64)
    v = np.ascontiguousarray(velocity, dtype=np.float64)
    if v.shape != T_in.shape:
        raise ValueError(f"band_batch: T_in {T_in.shape} and velocity {v.shape} differ in shape")
    T_out = np.empty_like(T_in)
    elong = np.empty_like(T_in)
    g = np.exp(np.asarray(log_gain, dtype=np.float64))
    state = np.array([float(slide[0]), float(slide[1])])
    _band_batch(T, 1.0 / g, g, np.ascontiguousarray(weight, dtype=np.float64), T_in, v, float(band), float(sigma),
                state, bool(slack), T_out, elong)
    return T_out, elong, T, (float(state[0]), float(state[1]))
