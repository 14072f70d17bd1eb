"""The pair controllers of every joint of an instrument stepped in one compiled call per cycle.

:class:`PairControlBank` takes over the :class:`~slave.pair_control.PairController` of each joint and runs
:meth:`PairController.step`'s arithmetic (modes with hysteresis, the puller's position from its bumpless
reference and its backlash compensation, the antagonist's feedforward through the play and its rate-limited
tension loop, the travel clip; :mod:`slave.pair_control`) for all of them in one compiled loop: the same operations in
the same order, ``min``/``max`` with Python's tie rule, so every motor command is the controller's own, bit for bit.
What it saves is the Python of each joint's call (~5 us a joint on a 2-core machine).

While the bank steps them the controllers' state (motor commands, mode, switch count, references, the
plays' outputs, the compensation's tensions) lives in the bank's arrays; :meth:`PairControlBank.release` writes it back,
and a controller of a bank that is stepped on its own releases its bank first.
"""
from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numba import njit

from slave.backlash import BAND_TIME
from slave.pair_control import PairController, PairMode

__all__ = ["PairControlBank"]

_MODES = tuple(PairMode(k) for k in range(len(PairMode)))


@njit(cache=True, nogil=True, inline="always")
def _max(a, b):  # pragma: no cover - compiled
    """Python's ``max(a, b)``: the first unless the second is greater."""
    return b if b > a else a


@njit(cache=True, nogil=True, inline="always")
def _min(a, b):  # pragma: no cover - compiled
    """Python's ``min(a, b)``: the first unless the second is smaller."""
    return b if b < a else a


@njit(cache=True, nogil=True, inline="always")
def _mode_for(mode, c, band):  # pragma: no cover - compiled
    """:meth:`PairController._mode_for`: 0 IDLE, 1 PULL_A, 2 PULL_B."""
    if not math.isfinite(c):
        return 0
    if mode == 1 and c > 0.5 * band:
        return 1
    if mode == 2 and c < -0.5 * band:
        return 2
    if c > band:
        return 1
    if c < -band:
        return 2
    return 0


@njit(cache=True, nogil=True)
def _payout(i, p, s, c, T, dt, ref, prm):  # pragma: no cover - compiled
    """:meth:`PairController._payout` of joint i (its play, T0 and T_eq in ref[i, 3:6])."""
    w = prm[i, 12]
    ref[i, 3] = _min(_max(ref[i, 3], c - w), c + w)
    u = _min(1.0, s * (c - ref[i, 3]) / w)
    if u > 1.0 - 1e-9:
        ref[i, 4] = T
        ref[i, 5] = T
        return 0.0
    target = _min(ref[i, 4], T * math.exp(2.0 * prm[i, 10 + p]))
    ref[i, 5] += -math.expm1(-dt / BAND_TIME) * (target - ref[i, 5])
    return prm[i, 8 + p] * _max(ref[i, 5], 0.0) * 0.5 * (1.0 - u)


@njit(cache=True, nogil=True)
def _step_all(theta, T_in, dt, x_out, X, mode, switches, ref, prm, lim):  # pragma: no cover - compiled
    """:meth:`PairController.step` of every joint i. theta (n,) commands [rad] (NaN: none); T_in, x_out (n, 2)
    load cells [N] and estimated distal displacements [m] (NaN: none); X (n, 2) motor commands [m], updated;
    mode, switches (n,) int64; ref (n, 6) the puller's reference x_ref [m], c_ref [rad], the feedforward play's
    output [m] (NaN: none), the compensation's play output [rad], T0 and T_eq [N]; prm (n, 14) r, T_set, gain,
    band, max speed, feedforward (0/1), play, travel limits (0/1), c_rev a, b [m/N], K a, b, the compensation's
    play half-width [rad] and backlash compensation (0/1); lim (n, 2, 2) per tendon (low, high) [m]."""
    for i in range(X.shape[0]):
        c = theta[i]
        new = _mode_for(mode[i], c, prm[i, 3])
        if new != mode[i]:
            mode[i] = new
            switches[i] += 1
            ref[i, 2] = math.nan
            if new != 0:
                ref[i, 0] = X[i, new - 1]
                ref[i, 1] = c
                ref[i, 3] = c - (1.0 if new == 1 else -1.0) * prm[i, 12]
                ref[i, 4] = T_in[i, new - 1]
                ref[i, 5] = T_in[i, new - 1]
        p = mode[i] - 1
        vlim = prm[i, 4] * dt
        if p < 0:
            for j in range(2):
                X[i, j] += _max(-vlim, _min(vlim, prm[i, 2] * (prm[i, 1] - T_in[i, j]) * dt))
        else:
            s = 1.0 if p == 0 else -1.0
            x_new = ref[i, 0] + s * prm[i, 0] * (c - ref[i, 1])
            if prm[i, 13] != 0.0:
                x_new -= _payout(i, p, s, c, T_in[i, p], dt, ref, prm)
            X[i, p] = x_new
            q = 1 - p
            u = x_out[i, p]
            if prm[i, 5] != 0.0 and math.isfinite(u):
                if math.isnan(ref[i, 2]):
                    ref[i, 2] = u
                y = _min(_max(ref[i, 2], u - prm[i, 6]), u + prm[i, 6])
                X[i, q] -= y - ref[i, 2]
                ref[i, 2] = y
            X[i, q] += _max(-vlim, _min(vlim, prm[i, 2] * (prm[i, 1] - T_in[i, q]) * dt))
        if prm[i, 7] != 0.0:
            for j in range(2):
                X[i, j] = _min(_max(X[i, j], lim[i, j, 0]), lim[i, j, 1])


class PairControlBank:
    """Pair controllers stepped together (module docstring).

    Parameters
    ----------
    controllers : sequence of PairController
        One per joint, in the row order of :meth:`step`'s arrays; none already in a bank.

    Attributes
    ----------
    controllers : tuple of PairController
    mode, switches : ndarray of int64, shape (n,)
        Each controller's mode (:class:`~slave.pair_control.PairMode`) and switch count while it is banked.
    active : bool
        True until :meth:`release`.

    Raises
    ------
    ValueError
        No controller, or one already in a bank.
    """

    def __init__(self, controllers: Sequence[PairController]):
        ctls = tuple(controllers)
        if not ctls or any(c._bank is not None for c in ctls):
            raise ValueError("PairControlBank: expected one or more pair controllers, none already in a bank")
        n = len(ctls)
        self.controllers = ctls
        self.X = np.array([c.x_cmd for c in ctls], dtype=np.float64).reshape(n, 2)
        self.mode = np.array([int(c.mode) for c in ctls], dtype=np.int64)
        self.switches = np.array([c.switches for c in ctls], dtype=np.int64)
        self.ref = np.array([(c._x_ref, c._c_ref, math.nan if c._ff is None else c._ff, c._y, c._T0, c._T_eq)
                             for c in ctls], dtype=np.float64).reshape(n, 6)
        self.prm = np.array([(c.r, c.T_set, c.gain, c.band, c.vmax, float(c.feedforward), c.play,
                              float(c.x_limits is not None), *(c.band_compliance or (0.0, 0.0)),
                              *c.friction_exponent, c.band_width, float(c.band_compliance is not None))
                             for c in ctls], dtype=np.float64).reshape(n, 14)
        self.lim = np.array([c.x_limits if c.x_limits is not None else ((-math.inf, math.inf),) * 2 for c in ctls],
                            dtype=np.float64).reshape(n, 2, 2)
        for c in ctls:
            c._bank = self
        self.active = True

    def step(self, theta: np.ndarray, T_in: np.ndarray, dt: float, x_out: np.ndarray) -> np.ndarray:
        """Every controller's :meth:`~slave.pair_control.PairController.step`: commands ``theta`` [rad] of shape
        (n,) (NaN: none), load cells ``T_in`` [N] and estimated distal displacements ``x_out`` [m] (NaN: none)
        of shape (n, 2), period ``dt`` [s] > 0. Returns the motor commands [m], shape (n, 2) (the bank's own
        array: copy it to keep it).

        Raises
        ------
        ValueError
            The bank was released.
        """
        if not self.active:
            raise ValueError("PairControlBank.step: the bank was released")
        _step_all(theta, T_in, float(dt), x_out, self.X, self.mode, self.switches, self.ref, self.prm, self.lim)
        return self.X

    def release(self) -> None:
        """Give every controller its state back; idempotent."""
        if not self.active:
            return
        self.active = False
        for c, x, m, sw, (x_ref, c_ref, ff, y, T0, T_eq) in zip(self.controllers, self.X.tolist(), self.mode.tolist(),
                                                                self.switches.tolist(), self.ref.tolist(),
                                                                strict=False):
            c.x_cmd, c.mode, c.switches = [x[0], x[1]], _MODES[m], sw
            c._x_ref, c._c_ref, c._ff = x_ref, c_ref, None if math.isnan(ff) else ff
            c._y, c._T0, c._T_eq = y, T0, T_eq
            c._bank = None
