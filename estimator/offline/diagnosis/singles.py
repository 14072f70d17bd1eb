"""The single candidates (step 4 of :func:`estimator.offline.diagnosis.selection.diagnose_recording`): every
extension fitted alone on the base's route, except those a linearised screen at the base shows cannot pay for their
parameters; those are fitted on demand, by the step that needs them.

Most extensions explain nothing on a given recording, and fitting each alone is most of a diagnosis's cost. The base
sits at the minimum of its own parameters on the forward fold's fit block; linearised there
(:class:`estimator.offline.diagnosis.screen.Linearised`, with K the base's only free parameter as in the singles'
fits, the route held), a candidate removes the share rho of the block's cost (the largest over its forms). A candidate
is screened (not fitted up front) when rho is below SCREEN_SHARE times its price (PENALTY per parameter) and it is not
among the POLISH largest shares. Never screened: an effect with a discrete parameter (a step's instant is not
linearised), and those a model-free reading names before any fit (stiction when the stick-slip ratio is at least
STICK_SLIP_WEAK; the offset of an encoder reading off its zero at the initial rest, and its equivalents).

A screened candidate is fitted when a step needs it, so that the steps see what they would see with every candidate
fitted:

* all of them, when none fitted up front is acceptable (S + PENALTY x parameters < 1) while the base leaves structure,
  or when none brings the structure under STRUCTURE_RATIO after the route refits
  (:func:`estimator.offline.diagnosis.rules.refit_routes`, which then refits them with the route free), or when the
  forward selection's model leaves structure (the pairs then rank every single);
* one at a time where a rule reads it (:meth:`Singles.need`).

Beside a first effect at its floor (:func:`estimator.offline.diagnosis.pairs.second_at_floor`) a screened candidate
is not fitted alone: it has no form of its own, and is tried in each form whose share beside the first model passes
the second-cause screen.

The diagnosis lists the screened candidates that stayed unfitted, with their share and price (``screened`` in the
JSON).
"""
from __future__ import annotations

from typing import TYPE_CHECKING

from estimator.offline.diagnosis import thresholds as th
from estimator.offline.diagnosis.fit import start_points
from estimator.offline.diagnosis.folds import Fit
from estimator.offline.diagnosis.screen import Linearised
from estimator.offline.effects.catalogue import Effect
from estimator.offline.effects.types import ROUTE_KEYS

if TYPE_CHECKING:
    from estimator.offline.diagnosis.rules import Context

__all__ = ["Singles", "fit_single", "forms"]


def forms(ctx: Context, e: Effect) -> list[dict]:
    """The held forms of ``e`` that the recording's signals allow (its ``variants``; ``[{}]`` for one form)."""
    return [v for v in e.variants if e.variant_ok(v, ctx.signals)] or [{}]


def fit_single(ctx: Context, e: Effect, base: Fit) -> Fit:
    """``e`` fitted alone on the base's route (held), scored against the base; an effect with several forms (its held
    ``variants``, e.g. where pre-sliding sits) keeps its best (lowest S)."""
    shape = [{k: v[k] for k in ROUTE_KEYS if k in v} for v in base.values]
    best = None
    for var in forms(ctx, e):
        f = Fit([e], ctx.folds, start_points([e], base.values[0], ctx.s, var),
                fixed=[{**sh, **var} for sh in shape], base=base, floor=ctx.floor,
                need=1.0 - th.PENALTY * len(e.parameters))
        if best is None or f.S < best.S:
            best = f
    assert best is not None
    return best


class Singles(dict[str, Fit]):
    """The single candidates fitted so far (id -> :class:`Fit`), and those screened (``screened``: id -> {share,
    price}, both [-]). Iterating yields the fitted ones; :meth:`need` and :meth:`complete` fit screened ones."""

    def __init__(self, ctx: Context, base: Fit, cands: list[Effect]):
        super().__init__()
        self.ctx, self.base = ctx, base
        self.effects = {e.id: e for e in cands}
        self.screened: dict[str, dict[str, float]] = {}

    def fit(self, eid: str) -> Fit:
        """Fit the candidate ``eid`` (fitted or screened) alone, keep and return it."""
        self[eid] = fit_single(self.ctx, self.effects[eid], self.base)
        self.screened.pop(eid, None)
        return self[eid]

    def has(self, eid: str) -> bool:
        """Whether ``eid`` is a candidate of this recording (fitted or screened)."""
        return eid in self.effects

    def need(self, eid: str) -> Fit | None:
        """The single fit of ``eid``, fitted now when it was screened; None when it is not a candidate."""
        if eid in self:
            return self[eid]
        return self.fit(eid) if eid in self.screened else None

    def complete(self) -> list[str]:
        """Fit every screened candidate; returns their ids."""
        ids = list(self.screened)
        for eid in ids:
            self.fit(eid)
        return ids

    @classmethod
    def screen(cls, ctx: Context, base: Fit, cands: list[Effect], keep: set[str]) -> Singles:
        """The candidates fitted up front and those screened at the base (module docstring); ``keep``: ids a
        model-free reading names, never screened."""
        singles = cls(ctx, base, cands)
        lin = Linearised([], base.values[0], ctx.folds.train, ctx.folds.fit[0])
        shares: dict[str, float] = {}
        for e in cands:
            rhos = [lin.share(e, var) for var in forms(ctx, e)] if e.id not in keep else [None]
            if all(r is not None for r in rhos):
                shares[e.id] = max(r for r in rhos if r is not None)
        largest = set(sorted(shares, key=lambda k: -shares[k])[:th.POLISH])
        for e in cands:
            price = th.PENALTY * len(e.parameters)
            if e.id in shares and e.id not in largest and shares[e.id] < th.SCREEN_SHARE * price:
                singles.screened[e.id] = {"share": shares[e.id], "price": price}
                ctx.bar(f"{e.id} screened")
            else:
                singles[e.id] = fit_single(ctx, e, base)
                ctx.bar(e.id)
        return singles
