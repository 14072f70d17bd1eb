"""Compiled parts of the slack rule (:func:`estimator.offline.effects.predict.slack_hold`): where a tendon is taut.

A tendon carries no compression: while slack, its proximal end moves without it and its distal end stays where
the last taut sample left it. :func:`slack_index` follows the slack and taut phases sample by sample;
:func:`held_tension` gives the means of T_in around each sample that tell a low tension held above zero from the
noise on a zero.
"""
from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["slack_index", "held_tension"]


@njit(cache=True, nogil=True)
def slack_index(T_in, x_in, lo, hi, window, mean_lo, held, held_lo):  # pragma: no cover - compiled
    """Index of the last taut sample at every sample, shape (n,) (see
    :func:`estimator.offline.effects.predict.slack_hold`). The tendon goes slack when T_in < lo and held < held_lo.
    It is taut again when T_in >= lo and either the proximal end is back where it went slack (x_in >= its value at
    the last taut sample: the paid-out length taken up) or the mean of T_in over the last ``window`` samples is
    >= mean_lo (a tension above zero, not one noise sample on a zero), or at once when T_in >= hi or held >=
    held_lo (``held``, shape (n,): the smaller of the means of
    T_in over the samples before and after, a low tension the noise cannot give)."""
    n = T_in.shape[0]
    out = np.empty(n, np.int64)
    last = 0
    slack = True
    acc = 0.0
    for i in range(n):
        T = T_in[i]
        acc += T
        if i >= window:
            acc -= T_in[i - window]
        if slack:
            if T >= hi or held[i] >= held_lo or (
                    T >= lo and (i == 0 or x_in[i] >= x_in[last] or acc >= mean_lo * min(i + 1, window))):
                slack = False
                last = i
        elif T >= lo or held[i] >= held_lo:
            last = i
        else:
            slack = True
        out[i] = last
    return out


@njit(cache=True, nogil=True)
def held_tension(T_in, n):  # pragma: no cover - compiled
    """The smaller of the means of T_in over the ``n`` samples up to each sample and the ``n`` samples from it on
    (fewer at the ends), shape (n_samples,) [N]: a low tension held above zero that the noise cannot give
    (:func:`estimator.offline.effects.predict.slack_hold`)."""
    size = T_in.shape[0]
    c = np.empty(size + 1)
    c[0] = 0.0
    acc = 0.0
    for i in range(size):
        acc += T_in[i]
        c[i + 1] = acc
    out = np.empty(size)
    for i in range(size):
        lo = max(i + 1 - n, 0)
        hi = min(i + n, size)
        out[i] = min((c[i + 1] - c[lo]) / (i + 1 - lo), (c[hi] - c[i]) / (hi - i))
    return out
