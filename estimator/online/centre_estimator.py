"""The centre map of :mod:`estimator.online.spindle_centre`, one sample at a time (the slave's rate).

The same (SC1) band-centre reading and (SC2) torque map as the batch :func:`predict_centre_map` (with the
shape held outside the calibration's angle range, as :func:`estimator.offline.spindle.centre_fit.predict_held`),
carried forward one cycle with the state kept between calls: the last ``2 HALF_WINDOW`` spindle angles (the
rate), the running edge means of the stroke under way and the last completed stroke of each direction, and
the lagged direction state z.

The one difference from the batch model is causality. The batch rate is the central difference over
+-HALF_WINDOW samples (+-25 ms at 1 kHz); per cycle only the past is known, so the rate here is the
backward difference over the same 2 HALF_WINDOW samples: the batch rate of HALF_WINDOW samples ago.
Stroke cuts, the full-motion test and the direction state therefore switch 25 ms later than in the
batch model. At the reversals, where this matters, the spindle stands almost still (a sine turns
with zero speed), so the travel the direction state lags by is a fraction of a millirad; a stroke's
direction is the sign of the rate at its start (the batch model takes the sign of its mean rate: the
same on a stroke longer than the delay).

Inputs: spindle torque tau_p [N m] and angle theta_p [rad] at time t [s]; out: the jaw torque [N m].
"""
from __future__ import annotations

import math
from collections import deque

import numpy as np

from estimator.online.spindle import OMEGA_S
from estimator.online.spindle_centre import MIN_RATE, MIN_SAMPLES, CentreParams

__all__ = ["HALF_WINDOW", "CentreEstimator"]

#: Half the samples of the spindle-rate difference (the batch :func:`estimator.online.spindle.spindle_rate`'s).
HALF_WINDOW = 25


class CentreEstimator:
    """Online centre map (module docstring).

    Parameters
    ----------
    params : CentreParams
        The map's constants (``coef`` of shape (4, deg + 1), window, half-width, fallback centre, edge slopes;
        ``notes["shape_range"]`` ((lo, hi) rising, (lo, hi) falling) [rad] holds the shape outside the
        calibration's angles, absent: the plain polynomial).

    Raises
    ------
    ValueError
        ``coef`` not of shape (4, deg + 1), or a half-width slope |w1| >= 1.
    """

    def __init__(self, params: CentreParams):
        coef = np.asarray(params.coef, dtype=float)
        if coef.ndim != 2 or coef.shape[0] != 4:
            raise ValueError(f"centre map: coef must have shape (4, deg + 1), got {coef.shape}")
        if abs(params.half_width[1]) >= 1.0:
            raise ValueError(f"centre map: half-width slope w1 = {params.half_width[1]} must be below 1 in magnitude")
        self.p, self.coef = params, coef
        self.deg = coef.shape[1] - 1
        big = math.inf
        rng = params.notes.get("shape_range")
        self.ranges = ((-big, big), (-big, big)) if rng is None else (tuple(rng[0]), tuple(rng[1]))
        self.theta_z = max(float(params.theta_z), 1e-4)
        self._hist: deque[float] = deque(maxlen=2 * HALF_WINDOW + 1)
        self._dt = 0.0
        self._t: float | None = None
        self._sign = 0.0                 # sign of the last nonzero rate (the stroke under way)
        self._dir = 0                    # 0: high edge (falling angle), 1: low edge (rising angle)
        self._sum = 0.0
        self._n = 0
        self._last = [math.nan, math.nan]
        self._z: float | None = None
        self._theta_prev = 0.0
        self.centre = float(params.centre0)

    def rate(self, theta_p: float) -> float:
        """Push ``theta_p`` [rad] and return the backward-difference spindle rate [rad/s] (module docstring)."""
        h = self._hist
        h.append(theta_p)
        n = len(h) - 1
        if n == 0 or self._dt <= 0.0:
            return 0.0
        return (h[-1] - h[0]) / (n * self._dt)

    def step(self, tau_p: float, theta_p: float, t: float) -> float:
        """One sample: spindle torque ``tau_p`` [N m] and angle ``theta_p`` [rad] at time ``t`` [s]; the jaw
        torque [N m] (SC1, SC2)."""
        if self._t is not None and self._dt == 0.0 and t > self._t:
            self._dt = t - self._t       # the sample spacing: the first interval (a recording's or the loop's)
        self._t = t
        om = self.rate(theta_p)
        self._edges(tau_p, theta_p, om)
        x = math.tanh(om / OMEGA_S)
        if self._z is None:
            self._z = x
        else:
            self._z += (x - self._z) * (1.0 - math.exp(-abs(theta_p - self._theta_prev) / self.theta_z))
        self._theta_prev = theta_p
        return self._torque(theta_p, self.centre, self._z)

    def _edges(self, tau_p: float, theta_p: float, om: float) -> None:
        """(SC1): the running mean of the stroke under way, the last completed stroke of each direction."""
        p = self.p
        if om != 0.0 and math.copysign(1.0, om) != self._sign:
            if self._sign != 0.0 and self._n >= MIN_SAMPLES:
                self._last[self._dir] = self._sum / self._n
            self._sign = math.copysign(1.0, om)
            self._dir = 0 if om < 0 else 1
            self._sum, self._n = 0.0, 0
        lo, hi = p.window
        if lo <= theta_p <= hi and abs(om) > MIN_RATE:
            self._sum += tau_p - p.edge_slope[self._dir] * (theta_p - p.theta_ref)
            self._n += 1
        edge = list(self._last)
        if self._n >= MIN_SAMPLES:
            edge[self._dir] = self._sum / self._n
        w0, w1 = p.half_width
        e_hi, e_lo = edge
        if math.isnan(e_hi) and math.isnan(e_lo):
            self.centre = float(p.centre0)
        elif math.isnan(e_hi):
            self.centre = (e_lo + w0) / (1.0 - w1)
        elif math.isnan(e_lo):
            self.centre = (e_hi - w0) / (1.0 + w1)
        else:
            self.centre = 0.5 * (e_hi + e_lo)

    def _torque(self, theta_p: float, c: float, z: float) -> float:
        """(SC2) with the shape held outside the calibration's angles."""
        d = theta_p - self.p.theta_ref
        (ul, uh), (dl, dh) = self.ranges
        du, dd = min(max(d, ul), uh), min(max(d, dl), dh)
        wu, wd = 0.5 * (1.0 + z), 0.5 * (1.0 - z)
        k = self.coef
        a = cc = 0.0
        ca = ccc = 0.0
        pu = pd = 1.0
        for i in range(self.deg + 1):
            ai, ci = wu * pu + wd * pd, wu * pu - wd * pd
            a += ai * k[0, i]
            ca += ai * k[1, i]
            cc += ci * k[2, i]
            ccc += ci * k[3, i]
            pu *= du
            pd *= dd
        return float(a + c * ca + cc + c * ccc)
