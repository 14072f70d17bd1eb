"""Calibration of the centre map (:mod:`estimator.online.spindle_centre`) on runs with jaw torque.

Every fit maps the calibration runs' spindle signals to their jaw torque; a prediction uses a run's
spindle signals only. The map is linear in its coefficients given the direction-state travel theta_z,
which is chosen from THETA_Z_GRID by the calibration's own fit cost.

The load gain (how the jaw torque follows the band centre, about 1 / (r cosh K)) needs calibration
runs at two or more load levels. On runs of one load level the centre hardly changes, the gain is not
identifiable (:func:`scale_profile` measures the flat cost), and ``scale`` must be given: the
centre terms are then b_0 = scale, b_k = e_k = 0 (the shape along the stroke does not change with load).
"""
from __future__ import annotations

import numpy as np

from estimator.offline.spindle_shared import RunData
from estimator.online.spindle import spindle_rate
from estimator.online.spindle_centre import (
    MIN_RATE,
    CentreParams,
    centre_features,
    centre_ready,
    direction_state,
    stroke_centre,
)

__all__ = ["THETA_Z_GRID", "DEGREE", "band_edges", "fit_centre_map", "scale_profile", "run_centre", "scored_start"]

#: Candidate direction-state travels [rad].
THETA_Z_GRID = (0.003, 0.006, 0.01, 0.02, 0.04, 0.08)
#: Polynomial degree in the spindle angle of (SC2).
DEGREE = 4


def _edge_masks(r: RunData, window: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    om = spindle_rate(r.theta_p, r.dt)
    after = np.arange(r.theta_p.size) >= r.k0
    m = after & (r.theta_p >= window[0]) & (r.theta_p <= window[1])
    hi, lo = m & (om < -MIN_RATE), m & (om > MIN_RATE)
    if hi.sum() < 5 or lo.sum() < 5:
        raise ValueError(f"run {r.name}: no full motion in both directions inside {window}")
    return hi, lo


def band_edges(r: RunData, window: tuple[float, float]) -> tuple[float, float]:
    """(high edge, low edge) [N m]: mean spindle torque in full motion inside ``window`` [rad], falling and
    rising angle, from k0 on. Raises ValueError when a direction has no sample."""
    hi, lo = _edge_masks(r, window)
    return float(r.tau_p[hi].mean()), float(r.tau_p[lo].mean())


def _edge_slopes(runs: list[RunData], window: tuple[float, float], ref: float) -> tuple[float, float]:
    """Slope of each band edge along the stroke [N m/rad]: spindle torque on angle with an offset per run."""
    out = []
    for j in (0, 1):
        num = den = 0.0
        for r in runs:                          # within-run regression: an offset per run
            m = _edge_masks(r, window)[j]
            d, y = r.theta_p[m] - ref, r.tau_p[m]
            d, y = d - d.mean(), y - y.mean()
            num, den = num + float(d @ y), den + float(d @ d)
        out.append(num / den if den > 0 else 0.0)
    return out[0], out[1]


def scored_start(r: RunData, window: tuple[float, float]) -> int:
    """First sample the centre map is fitted and scored on: max(k0, :func:`centre_ready`) - after the pair
    model's initialisation stroke and once the centre reading has both band edges. Spindle angle only."""
    return max(r.k0, centre_ready(r.theta_p, r.dt, window))


def run_centre(r: RunData, window: tuple[float, float]) -> float:
    """Band centre [N m] of a whole run (mean of its two edges, :func:`band_edges`)."""
    return float(np.mean(band_edges(r, window)))


def _setup(runs: list[RunData]) -> tuple[tuple[float, float], tuple[float, float], float, float,
                                        tuple[float, float]]:
    th = np.concatenate([r.theta_p[r.k0:] for r in runs])
    lo, hi = np.percentile(th, [20.0, 80.0])
    window = (float(lo), float(hi))
    e = np.array([band_edges(r, window) for r in runs])
    C, W = e.mean(axis=1), 0.5 * (e[:, 0] - e[:, 1])
    if np.ptp(C) > 1e-3 and len(runs) > 1:
        w1, w0 = np.polyfit(C, W, 1)
    else:
        w1, w0 = 0.0, float(W.mean())
    ref = float(th.mean())
    return window, (float(w0), float(w1)), float(C.mean()), ref, _edge_slopes(runs, window, ref)


def _design(runs: list[RunData], centres: list[np.ndarray], starts: list[int], ref: float, theta_z: float, step: int):
    Xs, ys = [], []
    for r, c, k_start in zip(runs, centres, starts):
        z = direction_state(r.theta_p, r.dt, theta_z)
        k = slice(k_start, None, step)
        Xs.append(centre_features(r.theta_p[k], c[k], z[k], ref, DEGREE))
        ys.append(r.tau_d[k])
    return np.vstack(Xs), np.concatenate(ys)


def _solve(X: np.ndarray, y: np.ndarray, scale: float | None) -> np.ndarray:
    n = DEGREE + 1
    if scale is None:
        coef, *_ = np.linalg.lstsq(X, y, rcond=None)
        return coef
    keep = np.r_[0:n, 2 * n:3 * n]              # a_k and c_k free; b_0 = scale; b_k (k >= 1), e_k = 0
    sub, *_ = np.linalg.lstsq(X[:, keep], y - scale * X[:, n], rcond=None)
    coef = np.zeros(4 * n)
    coef[keep], coef[n] = sub, scale
    return coef


def fit_centre_map(runs: list[RunData], scale: float | None = None, step: int = 10,
                   theta_z: float | None = None) -> tuple[CentreParams, float]:
    """Fit (SC2) to the jaw torque of ``runs`` (from each run's k0, decimated by ``step``); ``scale``
    [-] fixes the load gain b_0 (needed when the runs share one load level); ``theta_z`` [rad] fixes the
    direction-state travel (else the best of THETA_Z_GRID on the runs' fit cost). Returns the
    parameters and the rms fit residual [N m]. Raises ValueError for no runs."""
    if not runs:
        raise ValueError("fit_centre_map needs at least one run")
    window, half, c0, ref, slope = _setup(runs)
    centres = [stroke_centre(r.tau_p, r.theta_p, r.dt, window, half, c0, slope, ref) for r in runs]
    starts = [scored_start(r, window) for r in runs]          # where the centre reading has both edges
    best: tuple[float, float, np.ndarray] | None = None
    for tz in (THETA_Z_GRID if theta_z is None else (theta_z,)):
        X, y = _design(runs, centres, starts, ref, tz, step)
        coef = _solve(X, y, scale)
        rms = float(np.sqrt(np.mean((X @ coef - y) ** 2)))
        if best is None or rms < best[0]:
            best = (rms, tz, coef)
    assert best is not None
    notes = {"load_gain": "fixed" if scale is not None else "fitted", "degree": DEGREE}
    return CentreParams(best[2].reshape(4, DEGREE + 1), ref, best[1], window, half, c0, slope, notes), best[0]


def scale_profile(runs: list[RunData], scales: np.ndarray, step: int = 10) -> list[tuple[float, CentreParams, float]]:
    """The fit with the load gain held at each of ``scales``: (scale, parameters, rms fit residual [N m]).
    On runs of one load level the residual is flat in the scale: the gain is not identifiable there."""
    out = []
    for s in scales:
        p, rms = fit_centre_map(runs, scale=float(s), step=step)
        out.append((float(s), p, rms))
    return out
