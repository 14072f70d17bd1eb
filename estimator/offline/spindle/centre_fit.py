"""Calibration of the centre map (:mod:`estimator.online.spindle_centre`) on runs with jaw torque.

Every fit maps the calibration runs' spindle signals to their jaw torque; a prediction uses a run's
spindle signals only. The map is linear in its coefficients given the direction-state travel theta_z,
which is chosen from THETA_Z_GRID by the calibration's own fit cost.

Outside the spindle angles the calibration saw in each direction the shape along the stroke is *held* at its
value at the last angle seen (:func:`held_features`, :func:`predict_held`): the degree-4 polynomial is not
extrapolated (docs/results/mrd.md: on half of a 0.1 Hz run it reaches 4.8 FS beyond the data).

The load gain (how the jaw torque follows the band centre, about 1 / (r cosh K)) needs calibration
runs at two or more load levels. On runs of one load level the centre hardly changes, the gain is not
identifiable (:func:`scale_profile` measures the flat cost), and ``scale`` must be given: the
centre terms are then b_0 = scale, b_k = e_k = 0 (the shape along the stroke does not change with load).
"""
from __future__ import annotations

import numpy as np

from estimator.offline.spindle.shared import RunData
from estimator.online.spindle import spindle_rate
from estimator.online.spindle_centre import (
    MIN_RATE,
    CentreParams,
    centre_ready,
    direction_state,
    predict_centre_map,
    stroke_centre,
    stroke_starts,
)

__all__ = ["THETA_Z_GRID", "DEGREE", "band_edges", "fit_centre_map", "scale_profile", "run_centre", "scored_start",
           "within_run_gain", "shape_range", "held_features", "predict_held",
           "held_parts"]

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


Range = tuple[tuple[float, float], tuple[float, float]]


def shape_range(runs: list[RunData], starts: list[int], ref: float) -> Range:
    """((lo, hi) rising, (lo, hi) falling) of d = theta_p - ``ref`` [rad] over the samples from ``starts`` on
    with the spindle angle rising / falling: where the calibration saw the shape along the stroke.
    Raises ValueError when a direction has no sample."""
    out = []
    for up in (True, False):
        d = np.concatenate([(r.theta_p - ref)[k:][(spindle_rate(r.theta_p, r.dt)[k:] > 0) == up]
                            for r, k in zip(runs, starts, strict=False)])
        if d.size == 0:
            raise ValueError(f"shape_range: no sample with the spindle angle {'rising' if up else 'falling'}")
        out.append((float(d.min()), float(d.max())))
    return out[0], out[1]


def _powers(x: np.ndarray, deg: int) -> np.ndarray:
    """Columns x^0 .. x^deg, shape (n, deg + 1), by repeated multiplication (a power call per sample is slower)."""
    out = np.empty((x.size, deg + 1))
    out[:, 0] = 1.0
    for k in range(1, deg + 1):
        out[:, k] = out[:, k - 1] * x
    return out


def held_features(theta_p: np.ndarray, centre: np.ndarray, z: np.ndarray, theta_ref: float, deg: int,
                  rng: Range) -> np.ndarray:
    """The design matrix of :func:`estimator.online.spindle_centre.centre_features` (columns d^k, C d^k, z d^k,
    z C d^k) with the shape held outside ``rng`` (:func:`shape_range`): the rising branch (a + c, weight
    (1 + z) / 2) reads d clipped to the rising range, the falling branch (a - c, weight (1 - z) / 2) d clipped
    to the falling range. Inside both ranges it equals centre_features."""
    a, c = _held_branches(theta_p, z, theta_ref, deg, rng)
    return np.hstack([a, centre[:, None] * a, c, centre[:, None] * c])


def _held_branches(theta_p: np.ndarray, z: np.ndarray, theta_ref: float, deg: int,
                   rng: Range) -> tuple[np.ndarray, np.ndarray]:
    """The (a, c) column blocks of :func:`held_features`, each (n, deg + 1)."""
    d = np.asarray(theta_p, dtype=float) - theta_ref
    pu, pd = (_powers(np.clip(d, lo, hi), deg) for lo, hi in rng)
    wu, wd = (0.5 * (1.0 + z))[:, None], (0.5 * (1.0 - z))[:, None]
    return wu * pu + wd * pd, wu * pu - wd * pd


def held_parts(p: CentreParams, theta_p: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """The spindle-angle-only blocks (a, c) of :func:`predict_held` for one run (theta_p [rad], spacing dt [s]),
    each (n, deg + 1): computed once, they serve every spindle torque of the run (shifted loads)."""
    z = direction_state(theta_p, dt, p.theta_z)
    (ul, uh), (dl, dh) = p.notes["shape_range"]
    return _held_branches(theta_p, z, p.theta_ref, np.asarray(p.coef).shape[1] - 1, ((ul, uh), (dl, dh)))


def predict_held(p: CentreParams, tau_p: np.ndarray, theta_p: np.ndarray, dt: float,
                 parts: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """Jaw torque [N m], shape (n,), of one run from its spindle torque [N m] and angle [rad]: the centre map
    with its shape held outside the calibration's angle range (``p.notes["shape_range"]``, set by
    :func:`fit_centre_map`); parameters without it give :func:`predict_centre_map`'s polynomial. ``parts``:
    :func:`held_parts` of this run's theta_p, when already computed."""
    if "shape_range" not in p.notes:
        return predict_centre_map(p, tau_p, theta_p, dt)
    c = stroke_centre(tau_p, theta_p, dt, p.window, p.half_width, p.centre0, p.edge_slope, p.theta_ref)
    k = np.asarray(p.coef, dtype=float)       # rows: a, C a, c, C c of held_features, summed without the matrix
    a, cc = held_parts(p, theta_p, dt) if parts is None else parts
    return a @ k[0] + c * (a @ k[1]) + cc @ k[2] + c * (cc @ k[3])


def _design(runs: list[RunData], centres: list[np.ndarray], starts: list[int], ref: float, theta_z: float, step: int,
            rng: Range):
    Xs, ys = [], []
    for r, c, k_start in zip(runs, centres, starts, strict=False):
        z = direction_state(r.theta_p, r.dt, theta_z)
        k = slice(k_start, None, step)
        Xs.append(held_features(r.theta_p[k], c[k], z[k], ref, DEGREE, rng))
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
    direction-state travel (else the best of THETA_Z_GRID on the runs' fit cost). The fitted samples' angle
    range per direction is kept in ``notes["shape_range"]`` (rising, falling) [rad]: :func:`predict_held` holds
    the shape outside it. Returns the parameters and the rms fit residual [N m]. Raises ValueError for no runs."""
    if not runs:
        raise ValueError("fit_centre_map needs at least one run")
    window, half, c0, ref, slope = _setup(runs)
    centres = [stroke_centre(r.tau_p, r.theta_p, r.dt, window, half, c0, slope, ref) for r in runs]
    starts = [scored_start(r, window) for r in runs]          # where the centre reading has both edges
    rng = shape_range(runs, starts, ref)
    best: tuple[float, float, np.ndarray] | None = None
    for tz in (THETA_Z_GRID if theta_z is None else (theta_z,)):
        X, y = _design(runs, centres, starts, ref, tz, step, rng)
        coef = _solve(X, y, scale)
        rms = float(np.sqrt(np.mean((X @ coef - y) ** 2)))
        if best is None or rms < best[0]:
            best = (rms, tz, coef)
    assert best is not None
    notes = {"load_gain": "fixed" if scale is not None else "fitted", "degree": DEGREE,
             "shape_range": [list(rng[0]), list(rng[1])]}
    return CentreParams(best[2].reshape(4, DEGREE + 1), ref, best[1], window, half, c0, slope, notes), best[0]


def scale_profile(runs: list[RunData], scales: np.ndarray, step: int = 10) -> list[tuple[float, CentreParams, float]]:
    """The fit with the load gain held at each of ``scales``: (scale, parameters, rms fit residual [N m]).
    On runs of one load level the residual is flat in the scale: the gain is not identifiable there."""
    out = []
    for s in scales:
        p, rms = fit_centre_map(runs, scale=float(s), step=step)
        out.append((float(s), p, rms))
    return out


def _periods(theta_p: np.ndarray, dt: float) -> np.ndarray:
    """Period index of every sample: the number of spindle reversals before it, halved."""
    flips = np.zeros(theta_p.size, dtype=int)
    flips[stroke_starts(spindle_rate(theta_p, dt))] = 1
    return np.cumsum(flips) // 2


def _shape(d: np.ndarray, up: np.ndarray, deg: int) -> np.ndarray:
    return np.column_stack([(up == j) * d ** k for j in (False, True) for k in range(deg + 1)])


def within_run_gain(r: RunData | list[RunData], deg: int = DEGREE, step: int = 10, middle: float = 0.6) -> dict:
    """Can one run's own signals fix the load gain? The capstan pair puts the band edges at
    c(theta, direction) + r e^(+-K) tau_d, so along a run the spindle torque follows its own jaw torque
    with slope r e^(-+K) on each direction's edge, s = their mean ~ r cosh K = 1 / gain, *after* the shape along the
    stroke (spring, wrap friction: a polynomial of degree ``deg`` in the spindle angle per direction, the centre map's)
    is taken out. Only the part of the jaw torque that is not a function of (angle, direction) carries s.

    Samples: full motion (|rate| > MIN_RATE) in the middle ``middle`` of the run's spindle stroke, from k0,
    every ``step``-th. Reads the run's spindle torque and angle and its jaw torque (a calibration run's
    target). Returns a JSON-ready dict: ``slope`` s [-], ``gain`` 1 / s, ``edge_slopes_falling_rising``,
    ``jackknife_se`` of s (a period left out at a time; None below three periods), ``profile_ci95`` of s (profile
    likelihood, residual variance at n_eff = n / the residual's integrated autocorrelation time), ``jaw_free_rms_Nm``
    (jaw torque not explained by the shape), ``jaw_rms_Nm`` (its whole variation), ``resid_rms_Nm``, ``n``, ``n_eff``,
    ``periods``.
    Raises ValueError when fewer than 2 (deg + 2) samples qualify."""
    runs = [r] if isinstance(r, RunData) else list(r)
    cols: list[list[np.ndarray]] = [[], [], [], [], []]
    for i, q in enumerate(runs):
        om = spindle_rate(q.theta_p, q.dt)
        lo, hi = np.percentile(q.theta_p[q.k0:], [50 * (1 - middle), 50 * (1 + middle)])
        k = np.arange(q.theta_p.size)
        idx = np.flatnonzero((k >= q.k0) & (q.theta_p > lo) & (q.theta_p < hi) & (np.abs(om) > MIN_RATE))[::step]
        for c, v in zip(cols, (q.theta_p[idx], om[idx] > 0, q.tau_p[idx], q.tau_d[idx],
                               _periods(q.theta_p, q.dt)[idx] + 10_000 * i), strict=False):
            c.append(v)
    th, up, tp, td, per = (np.concatenate(c) for c in cols)
    if th.size < 2 * (deg + 2):
        raise ValueError(f"run {','.join(q.name for q in runs)}: {th.size} samples in full motion, too few for the "
                         "within-run gain")
    d = th - float(np.mean(th))

    def fit(m: np.ndarray) -> tuple[float, np.ndarray, np.ndarray, list[float], list[float]]:
        free, res, ffs, slopes = np.zeros(int(m.sum())), np.zeros(int(m.sum())), [], []
        for j in (False, True):                     # each direction its own edge slope r e^(-+K)
            q = up[m] == j
            N = _shape(d[m][q], up[m][q], deg)
            f = td[m][q] - N @ np.linalg.lstsq(N, td[m][q], rcond=None)[0]
            rest = tp[m][q] - N @ np.linalg.lstsq(N, tp[m][q], rcond=None)[0]
            sj = float(f @ rest / (f @ f)) if f @ f > 0 else float("nan")
            free[q], res[q] = f, rest - sj * f
            ffs.append(float(f @ f))
            slopes.append(sj)
        return 0.5 * (slopes[0] + slopes[1]), free, res, ffs, slopes

    s, free, res, ffs, edge = fit(np.ones(th.size, dtype=bool))
    ps = np.unique(per)
    se = None                                       # the jackknife needs three periods or more
    if ps.size > 2:
        jk = np.array([fit(per != p)[0] for p in ps])
        se = float(np.sqrt((jk.size - 1) / jk.size * np.sum((jk - jk.mean()) ** 2)))
    e = res - res.mean()
    ac = np.correlate(e, e, "full")[e.size - 1:] / (e @ e)
    cut = int(np.argmax(ac < 0)) if np.any(ac < 0) else ac.size
    n_eff = float(th.size / max(1.0, 2.0 * ac[:cut].sum() - 1.0))
    rss = float(res @ res)
    inv = 0.25 * sum(1.0 / f if f > 0 else np.inf for f in ffs)       # variance factor of (s_1 + s_2) / 2
    half = float(np.sqrt(rss * np.expm1(3.84 / n_eff) * inv))
    return {"slope": s, "gain": 1.0 / s if s else float("nan"), "jackknife_se": se,
            "profile_ci95": [s - half, s + half], "edge_slopes_falling_rising": edge,
            "jaw_free_rms_Nm": float(np.sqrt(np.mean(free ** 2))),
            "jaw_rms_Nm": float(np.std(td)), "resid_rms_Nm": float(np.sqrt(rss / th.size)), "n": int(th.size),
            "n_eff": n_eff, "periods": int(ps.size), "degree": deg}
