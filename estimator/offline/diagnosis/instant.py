"""The instant of a step, fitted by a profile over candidate instants (a discrete parameter, not by a gradient).

A model whose friction steps at an instant t_s (``friction_step`` of :mod:`estimator.offline.effects.catalogue`)
changes its residual only where a sample crosses t_s: the residual is piecewise constant in t_s and a least-squares
step in it sees no gradient. :func:`profile_instant` fits t_s by a profile instead. For each candidate instant c on a
grid over the fit block (:func:`candidate_instants`), one Gauss-Newton step from the start z0,

    delta(c) = argmin_d |r0 + J(c) d|^2,      J(c) = [J_0, (r(z0 + h e_k; c) - r0) / h for the instant's own k],

gives the cost the continuous parameters would reach with that instant (J_0, the columns of the parameters that do not
depend on the instant, and r0 are the same for every c: at the start the step's size is zero). The best few
candidates are evaluated at z0 + delta, the best of them is refined by halving the grid step around it, and the
instant is then held while the least-squares fit refines the rest (:func:`estimator.offline.diagnosis.fit.fit_model`).
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np

from estimator.offline.effects.catalogue import Effect
from estimator.offline.effects.types import Parameter

__all__ = ["candidate_instants", "profile_instant", "profile_discrete", "PROFILE_INSTANTS", "PROFILE_MARGIN",
           "PROFILE_FINEST", "PROFILE_KEEP"]

#: [count] candidate instants of the coarse grid over a fit block (its step at least PROFILE_FINEST x 4)
PROFILE_INSTANTS = 20
#: [s] a candidate instant leaves at least this much of the fit block on each side (both levels must show)
PROFILE_MARGIN = 2.0
#: [s] the grid step is halved around the best candidate down to this
PROFILE_FINEST = 0.25
#: [count] best coarse candidates (by the Gauss-Newton cost) evaluated at their step
PROFILE_KEEP = 3


def candidate_instants(time: np.ndarray, mask: slice) -> tuple[np.ndarray, float]:
    """The coarse grid of instants [s from ``time[0]``] within the fit block ``time[mask]`` (``time`` [s], shape
    (n,), increasing), PROFILE_MARGIN from its ends, and its step [s]; an empty grid when the block is shorter than
    twice the margin."""
    t = time[mask]
    lo, hi = float(t[0] - time[0]) + PROFILE_MARGIN, float(t[-1] - time[0]) - PROFILE_MARGIN
    if hi <= lo:
        return np.zeros(0), 0.0
    step = max((hi - lo) / PROFILE_INSTANTS, 4.0 * PROFILE_FINEST)
    return np.arange(lo, hi + 1e-9, step), step


def _cost(r: np.ndarray) -> float:
    return float(r @ r)


def profile_instant(residual: Callable[[np.ndarray], np.ndarray], set_instant: Callable[[float], None],
                    z0: np.ndarray, lo: np.ndarray, hi: np.ndarray, own: list[int], grid: np.ndarray,
                    step: float, h: float = 0.5) -> tuple[float, np.ndarray]:
    """The instant of least cost and the parameters of one Gauss-Newton step there (module docstring).

    Parameters
    ----------
    residual : z -> residual vector, shape (m,), of the model with the instant last set by ``set_instant``
    set_instant : sets the instant [s] the next residuals are computed with
    z0 : the start in the fit's scaled variables, shape (p,), with the step's size at zero (its neutral value)
    lo, hi : the bounds of z, shape (p,)
    own : indices in z of the parameters whose effect depends on the instant (the step's size)
    grid, step : the candidate instants [s] and the grid step [s] (:func:`candidate_instants`)
    h : finite-difference step in the scaled variables

    Returns
    -------
    (instant [s], z of the Gauss-Newton step at it, within the bounds).

    Raises
    ------
    ValueError
        An empty grid.
    """
    if grid.size == 0:
        raise ValueError("profile_instant needs at least one candidate instant")
    set_instant(float(grid[0]))
    r0 = residual(z0)
    p = z0.size
    rest = [j for j in range(p) if j not in own]

    def column(j: int) -> np.ndarray:
        d = np.zeros(p)
        d[j] = h if z0[j] + h <= hi[j] else -h
        return (residual(z0 + d) - r0) / d[j]

    J0 = np.stack([column(j) for j in rest], axis=1) if rest else np.zeros((r0.size, 0))

    def gauss_newton(c: float) -> tuple[float, np.ndarray]:
        set_instant(c)
        J = np.concatenate([J0, np.stack([column(j) for j in own], axis=1)], axis=1)
        delta = np.linalg.lstsq(J, -r0, rcond=None)[0]
        z = z0.copy()
        z[rest + own] += delta
        return _cost(r0 + J @ delta), np.clip(z, lo, hi)

    steps = {float(c): gauss_newton(float(c)) for c in grid}
    best_c, best_z, best = float(grid[0]), z0, _cost(r0)
    for c in sorted(steps, key=lambda k: steps[k][0])[:PROFILE_KEEP]:
        set_instant(c)
        if (cost := _cost(residual(steps[c][1]))) < best:
            best_c, best_z, best = c, steps[c][1], cost
    width = 0.5 * step
    while width >= PROFILE_FINEST:
        for c in (best_c - width, best_c + width):
            if grid[0] <= c <= grid[-1] + 0.5 * step:
                set_instant(c)
                if (cost := _cost(residual(best_z))) < best:
                    best_c, best = c, cost
        width *= 0.5
    set_instant(best_c)
    return best_c, best_z


def profile_discrete(p: Parameter, effects: list[Effect], params: list[Parameter], scale: np.ndarray, fixed: dict,
                     residual: Callable[[np.ndarray], np.ndarray], z_starts: list[np.ndarray], lo: np.ndarray,
                     hi: np.ndarray, time: np.ndarray, mask: slice) -> list[np.ndarray]:
    """The discrete parameter ``p`` (an instant [s]) of a fit profiled from its best start with the step's size at
    its neutral value, and held in ``fixed`` (the fit's held values, which ``residual`` reads).

    ``params``: the fit's continuous parameters, ``scale`` their scales (z = value / scale), ``z_starts`` the
    starts, ``lo`` and ``hi`` the bounds of z; ``time`` [s], shape (n,), the series' times and ``mask`` the fit
    block. Returns the starts with the profile's Gauss-Newton step first. Without room in the fit block for an
    instant (:func:`candidate_instants`) the instant is held at the block's middle and the starts are returned."""
    owner = next(e for e in effects if p in e.parameters)
    own = [j for j, q in enumerate(params) if q in owner.parameters]
    z0 = min(z_starts, key=lambda z: float(np.sum(residual(z) ** 2))).copy()
    z0[own] = np.clip(np.array([params[j].neutral for j in own]) / scale[own], lo[own], hi[own])
    grid, step = candidate_instants(time, mask)
    if grid.size == 0:
        t = time[mask]
        fixed[p.name] = 0.5 * float(t[0] + t[-1]) - float(time[0])
        return z_starts

    def set_instant(c: float) -> None:
        fixed[p.name] = c
    c, z = profile_instant(residual, set_instant, z0, lo, hi, own, grid, step)
    fixed[p.name] = c
    return [z] + z_starts
