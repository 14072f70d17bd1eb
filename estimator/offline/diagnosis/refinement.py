"""Refinements of a diagnosis fit from its starts: the least costly of several, a retry with K held where K sits on
the edge of a step in the residual, and a refit below a plateau of K where a step crossed a narrow minimum onto it.

Used by :func:`estimator.offline.diagnosis.fit.fit_model`, whose ``refine`` (scipy's ``least_squares`` within the
parameters' bounds, in variables scaled to O(1), K first) and ``residual`` they take; the thresholds are
:data:`estimator.offline.diagnosis.thresholds.PLATEAU_BISECTIONS` (docs/concepts/diagnosis.md).
"""
from __future__ import annotations

import numpy as np

from estimator.offline.diagnosis import thresholds as th

__all__ = ["refine_best", "below_plateau"]


def below_plateau(sol, z0: np.ndarray, residual, refine, lo: np.ndarray, hi: np.ndarray):
    """``sol`` (scipy's OptimizeResult from the scaled start ``z0``, K first), or a refinement with K bounded below the
    plateau ``sol`` ended on, when that costs less.

    Above the K at which the model's tendon never slides (a pretension larger than every pull can lift through the
    friction, for one) the outputs are the same whatever K is: K's column of the Jacobian is zero there. A minimum
    just below that edge is a narrow valley, and a trust-region step from below can cross it onto the plateau, which
    costs less than the start and has no gradient back. The edge is found by bisection between the start (off the
    plateau) and the solution (on it), PLATEAU_BISECTIONS halvings, and the start refined again with K bounded by it.
    """
    jac = getattr(sol, "jac", None)
    if jac is None or np.any(jac[:, 0] != 0.0) or not z0[0] < sol.x[0]:
        return sol
    flat = sol.fun          # the residual at the solution, on the plateau
    off, on = float(z0[0]), float(sol.x[0])
    if np.array_equal(residual(np.concatenate([[off], sol.x[1:]])), flat):
        return sol          # the start's K is on the plateau too (with the solution's other parameters)
    for _ in range(th.PLATEAU_BISECTIONS):
        mid = 0.5 * (off + on)
        if np.array_equal(residual(np.concatenate([[mid], sol.x[1:]])), flat):
            on = mid
        else:
            off = mid
    top = hi.copy()
    top[0] = off
    below = refine(residual, np.clip(z0, lo, top), lo, top)
    return below if below.cost < sol.cost else sol


def refine_best(starts: list[np.ndarray], residual, refine, lo: np.ndarray, hi: np.ndarray, own: slice):
    """The least-cost refinement (scipy's OptimizeResult) from each of ``starts`` (scaled parameter vectors, K
    first); ``own`` the effects' parameters within them.

    A refinement that takes not a single step means K sits on the edge of a step in the residual (the memory or
    slack rule of some sample flips just below it): every trial step lowers K and fails, and the trust region
    shrinks to nothing. The others are then refitted with K held, then all from there - kept only when an effect's
    parameters stay inside their bounds (a parameter run to its bound from there bends to noise and displaces the
    effect that is there). A refinement that ends where K does not act is tried again below that plateau
    (:func:`below_plateau`).
    """
    span = 1e-3 * (hi[own] - lo[own])
    best = None
    for z0 in starts:
        sol = refine(residual, z0, lo, hi)
        if np.array_equal(sol.x, z0) and len(z0) > 1:
            def rest_of(y, z0=z0):
                return residual(np.concatenate([z0[:1], y]))
            sub = refine(rest_of, z0[1:], lo[1:], hi[1:])
            again = refine(residual, np.concatenate([z0[:1], sub.x]), lo, hi)
            inside = bool(np.all((again.x[own] > lo[own] + span) & (again.x[own] < hi[own] - span)))
            if again.cost < sol.cost and inside:
                sol = again
        sol = below_plateau(sol, z0, residual, refine, lo, hi)
        if best is None or sol.cost < best.cost:
            best = sol
    if best is None:
        raise ValueError("fit_model: no start to refine from (max_starts >= 1 and at least one start)")
    return best
