"""A second cause screened before it is fitted: the share of the fit block's cost that a partner's parameters can
remove beside the first model, linearised at the first model's fit (no fit of the pair).

:func:`estimator.offline.diagnosis.pairs.second_at_floor` fits physical candidates beside the first effect, and most
of them add nothing. A pair fit converges within its first iterations, so a looser fit costs nearly as much as the
full one and cannot serve as a screen (docs/results/diagnosis.md). The first model sits at the minimum of its own
parameters on the forward fold's fit block, so its residual r (:func:`estimator.offline.diagnosis.fit.fit_residual`)
holds what they cannot explain. Linearised there, with J the residual's columns per parameter, a partner beside the
first model removes the share

    rho = (min_d |r + J_1 d|^2 - min_d |r + [J_1 J_p] d|^2) / |r|^2

of the cost, J_1 the columns of the first model's parameters (K and its effect's, by a step of 1 % of their scale, as
the fits' finite differences), J_p the partner's (the secant from the first model alone to the partner at the start
its fit would take, :func:`estimator.offline.diagnosis.fit.start_points`: an effect that acts through a play, a
threshold or a delay is read over the size it has, not at zero). A partner whose rho is below SCREEN_SHARE times its
price (PENALTY per parameter: the share of the validation error it must remove) is not fitted.
"""
from __future__ import annotations

import numpy as np

from estimator.offline.diagnosis import thresholds as th
from estimator.offline.diagnosis.fit import SCALE, fit_residual, start_points
from estimator.offline.effects.catalogue import Effect
from estimator.offline.effects.types import Series

__all__ = ["Linearised"]


def _least_cost(J: np.ndarray, r: np.ndarray) -> float:
    """min_d |r + J d|^2 (linear least squares; J shape (n, k), r shape (n,))."""
    d, *_ = np.linalg.lstsq(J, -r, rcond=None)
    e = r + J @ d
    return float(e @ e)


class Linearised:
    """The first model linearised on one fit block: its residual and its own parameters' columns, computed once and
    shared by every partner (:meth:`share`).

    ``effects``, ``values``: the first model and its fitted values on the block (K, the route, its parameters and
    held settings); ``train``: the prepared series; ``mask``: the fit block (a slice of ``train``).
    """

    def __init__(self, effects: list[Effect], values: dict[str, float], train: Series, mask: slice):
        self.effects, self.values, self.train, self.mask = effects, dict(values), train, mask
        self.r = fit_residual(effects, self.values, train, mask)
        self.cost = float(self.r @ self.r)
        names = ["K"] + [p.name for e in effects for p in e.parameters if not p.discrete]
        cols = []
        for name in names:
            h = 1e-2 * max(SCALE[name], abs(self.values[name]))
            cols.append((fit_residual(effects, {**self.values, name: self.values[name] + h}, train, mask) - self.r)
                        / h)
        self.J = np.array(cols).T
        self.left = _least_cost(self.J, self.r)

    def share(self, partner: Effect, held: dict[str, float]) -> float | None:
        """rho of ``partner`` beside the first model (module docstring) [-], in [0, 1]; ``held``: its held settings
        (its form, from its single fit). None when it has a discrete parameter (a step's instant: it is not
        linearised) or the first model leaves no cost."""
        if any(p.discrete for p in partner.parameters) or self.cost <= 0.0:
            return None
        fx = self.effects + [partner]
        start = start_points([partner], self.values, self.train, held)[0]
        cols = []
        for p in partner.parameters:
            h = start[p.name] - p.neutral
            if h == 0.0:
                h = SCALE[p.name]
            v = {**self.values, **held, **{q.name: q.neutral for q in partner.parameters}}
            v[p.name] = p.neutral + h
            cols.append((fit_residual(fx, v, self.train, self.mask) - self.r) / h)
        both = _least_cost(np.column_stack([self.J] + cols), self.r)
        return max(self.left - both, 0.0) / self.cost

    def skips(self, partner: Effect, held: dict[str, float]) -> bool:
        """Whether ``partner`` is not fitted: its :meth:`share` is below SCREEN_SHARE x PENALTY x its parameters."""
        rho = self.share(partner, held)
        return rho is not None and rho < th.SCREEN_SHARE * th.PENALTY * len(partner.parameters)
