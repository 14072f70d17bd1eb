"""The friction exponent observed online from the width of the proximal hysteresis loop: friction that changes during a
session (a sheath reshaped, a drift) tracked from the proximal readings alone.

While the whole tendon slides (the profile memory's full slip, direction s = +1 pulling, -1 releasing) the capstan law
holds end to end: Y_in = Y_out e^{s K f} with Y = T + a (the tension-independent friction a) and f = 1 + c_v |v| the
speed factor of velocity friction (E1, E5 of docs/concepts/effects.md). For a distal load that is elastic (its tension
a function of the distal position only) the distal tension is the same at the same distal position on both branches,
so over the distal positions x_out both branches cover

    ln( sum Y_in(x_out; s = +1) / sum Y_in(x_out; s = -1) ) = K (f_+ + f_-)

(f the mean speed factors) and the friction exponent is the loop's width in ln Y_in, with nothing distal measured (the
sums weigh each position by its tension, so the few newtons near rest, where noise and slack dominate, weigh little):
x_out is the estimator's own distal end (x_in minus the estimated elongation). :class:`FrictionObserver` keeps each
branch of full slip (the samples between two reversals where the estimator says the whole tendon slides), decimated to
points at least ``spacing`` apart in x_out. A branch ends where the slide turns, or where Y_in has turned back from its
extreme by more than e^K; it is then compared with the last branch of the other direction over the distal positions
both cover (at least :data:`OVERLAP` of the longer one's span): one estimate of K per branch (half-cycle). The first
branch after a change of friction compares the new level with a branch of the old one and sees their mean; the next
sees the new level.

A load with hysteresis of its own (viscoelastic tissue) adds 1/2 ln(T_out+ / T_out-) to every estimate: the loop width
of the load reads as friction. :class:`FrictionTracker` takes the estimates as they are by default (an elastic load:
the simulated rig's loads, springs and stiffening tissue, bias the estimate by less than 0.03), so a session that starts
with another friction than the model's first level (a sheath already reshaped, a level fitted off by a start
transient) is corrected from its first estimates. With ``reference`` n > 0 it reads the first n estimates as the
model's own K instead (the session then has to start with the fitted friction) and subtracts their mean difference,
the load's bias, from every later one.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["FrictionObserver", "FrictionTracker", "OVERLAP"]

#: the least share of the longer branch's distal span two branches must share for an estimate [-]: a loop, not the
#: sliver where a short branch (a part-way reversal, the session's last move) meets a long one
OVERLAP = 0.5


class FrictionObserver:
    """Per-branch estimates of the friction exponent K [-] from the proximal loop width (module docstring).

    Parameters
    ----------
    a : the tension-independent friction [N] >= 0 (Y = T + a)
    T_min : proximal tension [N] below which a sample is not used (noise and slack dominate it), >= 0
    spacing : the least distal travel [m] between two kept points of a branch, > 0
    min_points : the least number of points of a branch, and of the positions two branches share, for an estimate

    Raises
    ------
    ValueError
        a setting that is not finite or out of range.
    """

    def __init__(self, a: float = 0.0, T_min: float = 0.0, spacing: float = 2e-6, min_points: int = 20):
        if not (math.isfinite(a) and a >= 0.0 and math.isfinite(T_min) and T_min >= 0.0
                and math.isfinite(spacing) and spacing > 0.0 and min_points >= 2):
            raise ValueError(f"friction observer settings out of range: a={a!r} N, T_min={T_min!r} N, "
                             f"spacing={spacing!r} m, min_points={min_points!r}")
        self.a, self.T_min, self.spacing, self.min_points = float(a), float(T_min), float(spacing), int(min_points)
        self.direction = 0
        self._extreme = 0.0                 # the branch's largest (pulling) or smallest (releasing) Y_in [N]
        self._x: list[float] = []
        self._Y: list[float] = []
        self._f: list[float] = []
        #: the last complete branch of each direction: (x sorted, Y [N], f), by direction +1 / -1
        self._last: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}

    def observe(self, T_in: float, x_out: float, sliding: int, speed_factor: float = 1.0,
                K: float | None = None) -> float | None:
        """One sample: proximal tension T_in [N], the estimated distal end x_out [m], the estimator's slide direction
        (+1, -1, 0: stuck), the speed factor f [-] >= 1 of the sample's friction and the estimator's friction exponent
        K [-] (None: not known). Returns a branch's estimate of K when this sample ends a branch, else None.

        A branch ends when the estimator slides the other way, or when Y_in has turned back from the branch's
        extreme by more than e^K (a reversal beyond half the friction band, which a wobble does not reach): an
        estimator whose K is too high sees the release as stuck until its end, and the turn still closes the branch.
        """
        Y = T_in + self.a
        estimate = None
        s = self.direction
        if s != 0:
            if s * (Y - self._extreme) > 0.0:
                self._extreme = Y
            turned = (K is not None and Y > 0.0 and self._extreme > 0.0
                      and s * math.log(Y / self._extreme) < -K)
            if sliding == -s or turned:
                estimate = self._close()
                self.direction, self._extreme = -s, Y
        elif sliding != 0:
            self.direction, self._extreme = sliding, Y
        if (sliding != 0 and sliding == self.direction and T_in >= self.T_min
                and (not self._x or abs(x_out - self._x[-1]) >= self.spacing)):
            self._x.append(x_out)
            self._Y.append(Y)
            self._f.append(speed_factor)
        return estimate

    def _close(self) -> float | None:
        """End the current branch: keep it as its direction's last, and estimate K against the other direction's."""
        s = self.direction
        x, Y, f = np.asarray(self._x), np.asarray(self._Y), np.asarray(self._f)
        self._x, self._Y, self._f = [], [], []
        if s == 0 or x.size < self.min_points:
            return None
        order = np.argsort(x, kind="stable")
        branch = (x[order], Y[order], f[order])
        self._last[s] = branch
        other = self._last.get(-s)
        if other is None:
            return None
        xo, yo, fo = other
        inside = (branch[0] >= xo[0]) & (branch[0] <= xo[-1])
        span = max(branch[0][-1] - branch[0][0], xo[-1] - xo[0])
        if int(np.count_nonzero(inside)) < self.min_points or np.ptp(branch[0][inside]) < OVERLAP * span:
            return None
        xs = branch[0][inside]
        here, there = float(np.sum(branch[1][inside])), float(np.sum(np.interp(xs, xo, yo)))
        if not (here > 0.0 and there > 0.0):
            return None
        factors = float(np.mean(branch[2][inside]) + np.mean(np.interp(xs, xo, fo)))
        return s * math.log(here / there) / factors


class FrictionTracker:
    """The friction exponent K [-] of a session tracked from the branch estimates of a :class:`FrictionObserver`
    (module docstring). Each estimate, less the bias, clamped to [0, ``K_max``], enters the median of the last
    ``median`` of them, the tracked K: one branch far off (a part-way loop, a load that moved) is held out, a step is
    followed once two branches agree. The bias is 0 (``reference`` 0: the estimates as they are), or, with
    ``reference`` n > 0, the mean difference between the first n estimates and the model's K at their instants (the
    load's own hysteresis, the session starting with the friction the model was fitted on).

    Raises ValueError: ``reference`` < 0, ``median`` < 1, K_max not finite or < 0.
    """

    def __init__(self, reference: int = 0, K_max: float = 5.0, median: int = 3):
        if not (reference >= 0 and math.isfinite(K_max) and K_max >= 0.0 and median >= 1):
            raise ValueError(f"friction tracker settings out of range: reference={reference!r}, K_max={K_max!r}, "
                             f"median={median!r}")
        self.reference, self.K_max, self.median = int(reference), float(K_max), int(median)
        self.estimates = 0
        self._bias: list[float] = []
        self._recent: list[float] = []

    @property
    def bias(self) -> float | None:
        """The observer's bias [-] (the mean of the first ``reference`` estimates less the model's K; 0 without a
        reference), None before they have come."""
        if self.reference == 0:
            return 0.0
        return float(np.mean(self._bias)) if len(self._bias) >= self.reference else None

    def update(self, K_branch: float, K_model: float) -> float | None:
        """Take one branch estimate ``K_branch`` [-] and the model's K [-] at its instant; returns the tracked K, or
        None while the bias is being read (or for an estimate that is not finite)."""
        if not math.isfinite(K_branch):
            return None
        self.estimates += 1
        if len(self._bias) < self.reference:
            self._bias.append(K_branch - K_model)
            return None
        bias = self.bias
        assert bias is not None
        keep = self._recent[max(len(self._recent) - self.median + 1, 0):]
        self._recent = [*keep, min(max(K_branch - bias, 0.0), self.K_max)]
        return float(np.median(self._recent))
