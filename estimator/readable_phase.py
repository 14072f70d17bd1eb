"""The readable phase of a tendon-sheath transmission (:class:`estimator.phase.Phase`, Phee et al. 2009, Sec. III).

The readable phase (:func:`readable_step`, used by :class:`estimator.online.distal.DistalEstimator` and
:func:`estimator.online.distal.estimate_batch`) changes only when the proximal tension has moved past the
noise: with a band ``delta`` [N] (a few load-cell noise sigmas),

* the direction turns from rising to falling once ``T_in < max_since_last_turn - delta`` (and back
  once ``T_in > min_since_last_turn + delta``): a reversal needs the tension to come back by delta;
* HOLD once T_in has stayed within delta of where it last moved for ``delta / (2 hold_rate)`` seconds
  (0.2 s at 0.2 N and 0.5 N/s);
* within a direction, PULL (RELEASE) while the distal tension sits on the slip line of the extreme,
  ``T_out = T_ext e^{-K}`` (``T_ext e^{+K}``) within ``0.005 T_out + 1 mN``, else the
  transition phase RELEASE_TO_PULL (PULL_TO_RELEASE): the distal end is stuck.

A sample-to-sample classifier on a smoothed rate flickers with the noise (3263 changes in 10014
rows of a demo); this one changes a few times per reversal.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["new_phase_state", "readable_step"]


def new_phase_state(T_in: float = 0.0, t: float = 0.0) -> np.ndarray:
    """State of :func:`readable_step`: [direction, extreme T_in, anchor T_in, anchor time, phase]."""
    return np.array([0.0, T_in, T_in, t, 0.0])


@njit(cache=True)
def readable_step(state, T_in, T_out, t, K, band, hold_rate):  # pragma: no cover - compiled
    """One sample of the readable phase (module docstring); updates ``state`` in place, returns the
    phase code. T_in, T_out [N], t [s], K [-], band [N] > 0, hold_rate [N/s] > 0."""
    d, ext = state[0], state[1]
    if abs(T_in - state[2]) > band:          # moved past the noise: new anchor
        state[2], state[3] = T_in, t
    if d > 0:
        ext = max(ext, T_in)
        if T_in < ext - band:
            d, ext = -1.0, T_in
    elif d < 0:
        ext = min(ext, T_in)
        if T_in > ext + band:
            d, ext = 1.0, T_in
    else:
        if T_in > ext + band:
            d, ext = 1.0, T_in
        elif T_in < ext - band:
            d, ext = -1.0, T_in
    state[0], state[1] = d, ext
    hold_time = 0.5 * band / hold_rate if hold_rate > 0 else 1e30
    if d == 0 or t - state[3] > hold_time:
        ph = 0                                # HOLD
    else:
        # slipping: the distal node sits on the slip line of the extreme (the profile's envelope)
        tol = 0.005 * abs(T_out) + 1e-3
        if d > 0:
            ph = 1 if abs(T_out - ext * math.exp(-K)) <= tol else 4
        else:
            ph = 2 if abs(T_out - ext * math.exp(K)) <= tol else 3
    state[4] = ph
    return ph
