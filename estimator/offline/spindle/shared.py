"""One parameter set of the spindle pair model for many runs: extension selection and leave-one-run-out.

The runs are given as :class:`RunData` (spindle torque and angle, the jaw truth, and the index
from which a run is scored: after its initialisation stroke). Procedure (the held-out discipline of
:mod:`estimator.offline.pair.diagnosis`):

1. :func:`select_extensions` - every run's first half (after its initialisation) fits, its second
   half validates. Starting from the base model (rho, Q, K_a, b), each extension of
   :data:`estimator.offline.spindle.fit.EXTENSIONS` not yet chosen is fitted (warm start from the chosen
   model, the new parameter at 0) and scored S = (validation rmse / base validation rmse)^2; the
   best is accepted when S / S_chosen + PENALTY (its extra parameters) < 1, and the rounds go on
   until nothing is accepted.
2. :func:`shared_fit` - the chosen model on all of every run (after initialisation).
3. :func:`leave_one_out` - for each run, the chosen model refitted on the others (warm start from
   the shared fit) predicts it from its spindle signals.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from estimator.offline.diagnosis.thresholds import PENALTY
from estimator.offline.spindle.fit import EXTENSION_STARTS, EXTENSIONS, fit_angle, fit_torque
from estimator.online.spindle import Batch, SpindleParams, make_batch, predict_angle, predict_torque, spindle_rate

__all__ = ["RunData", "batch_of", "kinematic_ratio", "load_sweep", "select_extensions", "shared_fit", "leave_one_out"]


@dataclass(frozen=True, eq=False)
class RunData:
    """One run: tau_p [N m], theta_p [rad], tau_d [N m], theta_d [rad] (shape (n,)), k0 the first
    scored sample (after the initialisation stroke), dt [s]."""

    name: str
    tau_p: np.ndarray
    theta_p: np.ndarray
    tau_d: np.ndarray
    theta_d: np.ndarray
    k0: int
    dt: float


def batch_of(runs: list[RunData], centre: float, theta_ref: float, step: int,
             part: str = "all") -> tuple[Batch, np.ndarray, np.ndarray, np.ndarray]:
    """(batch, jaw torque [N m], jaw angle [rad], weights) of the runs decimated by ``step``.

    ``part``: ``"all"`` weights every sample from k0 on, ``"first"`` / ``"second"`` the samples from
    k0 to the middle of the scored part / from there to the end (the model still runs from t = 0).
    """
    bt = make_batch([(r.tau_p, r.theta_p) for r in runs], centre, theta_ref, runs[0].dt, step)
    ws = []
    for r in runs:
        i = np.arange(len(r.tau_p))[::step]
        mid = (r.k0 + len(r.tau_p)) // 2
        m = {"all": i >= r.k0, "first": (i >= r.k0) & (i < mid), "second": i >= mid}[part]
        ws.append(m.astype(float))
    return (bt, np.concatenate([r.tau_d[::step] for r in runs]), np.concatenate([r.theta_d[::step] for r in runs]),
            np.concatenate(ws))


def _rmse(p: SpindleParams, bt: Batch, y: np.ndarray, w: np.ndarray) -> float:
    e = (predict_torque(p, bt) - y)[w > 0]
    return float(np.sqrt(np.mean(e ** 2)))


def kinematic_ratio(runs: list[RunData], middle: float = 0.6, min_rate: float = 0.05, stretch: bool = False) -> float:
    """n_k = d theta_d / d theta_p [-]: jaw angle per spindle angle in full motion (|rate| > ``min_rate``
    rad/s, the middle ``middle`` fraction of each run's spindle stroke, from k0 on), by least squares
    with an offset per run and direction (the cable stretch and jaw play shift the two directions).
    The pulley radii ratio r_p / r_d when the cable stretch does not change along the stroke.
    ``stretch``: a cable-stretch column (the spindle torque, one compliance for all runs) is fitted beside,
    so the ratio is the one at zero spindle torque difference (docs/results/mrd.md: it moves n_k by 1-4 %).
    Raises ValueError when no sample qualifies."""
    cols, ys, taus, nblk = [], [], [], 0
    for r in runs:
        om = spindle_rate(r.theta_p, r.dt)
        lo, hi = np.percentile(r.theta_p[r.k0:], [50 * (1 - middle), 50 * (1 + middle)])
        inside = (r.theta_p > lo) & (r.theta_p < hi) & (np.arange(r.theta_p.size) >= r.k0)
        for m in (inside & (om > min_rate), inside & (om < -min_rate)):
            if m.sum() > 10:
                cols.append((r.theta_p[m], nblk))
                ys.append(r.theta_d[m])
                taus.append(r.tau_p[m])
                nblk += 1
    if not cols:
        raise ValueError("no sample in full motion to read the kinematic ratio from")
    # an offset per block: the same slope as one least squares with an offset column per block, from the columns
    # with each block's mean taken out (Frisch-Waugh-Lovell), without the (n, blocks) matrix
    def centred(parts: list[np.ndarray]) -> np.ndarray:
        return np.concatenate([v - v.mean() for v in parts])
    A = np.column_stack([centred([c[0] for c in cols])] + ([centred(taus)] if stretch else []))
    coef, *_ = np.linalg.lstsq(A, centred(ys), rcond=None)
    return float(coef[0])


def _edge_bins(r: RunData, edges: np.ndarray, min_rate: float) -> np.ndarray:
    """Per spindle-angle bin: mean spindle torque and jaw torque in each direction (nan when empty)."""
    om = spindle_rate(r.theta_p, r.dt)
    after = np.arange(r.theta_p.size) >= r.k0
    out = np.full((edges.size - 1, 4), np.nan)
    for i, (a, b) in enumerate(zip(edges[:-1], edges[1:], strict=False)):
        m = after & (r.theta_p >= a) & (r.theta_p < b)
        for j, d in enumerate((m & (om < -min_rate), m & (om > min_rate))):
            if d.sum() > 5:
                out[i, j], out[i, 2 + j] = r.tau_p[d].mean(), r.tau_d[d].mean()
    return out


def load_sweep(groups: list[list[RunData]], middle: float = 0.6, bin_rad: float = 0.05,
               min_rate: float = 0.05) -> dict:
    """Model-free cross-load measurement of the spindle's friction band (no fit of the pair model).

    ``groups``: runs that differ only in load (e.g. one group per frequency), each with at least two
    runs. In spindle-angle bins of width ``bin_rad`` [rad] over the middle ``middle`` of the stroke,
    each edge of the spindle torque band (mean over one direction of motion, |rate| > ``min_rate``
    rad/s; the high edge is the falling angle's, as on the MRD rig, where a positive torque turns the
    shaft towards negative angles) is regressed on the jaw torque of the same direction across the
    group's runs. A capstan
    law with tension-independent friction F0 (docs/concepts/effects.md E8) on the load-carrying cable predicts
    edges tau_p = c(theta) +- F0 + r e^(+-K) tau_d, so the two slopes give r = sqrt(s_hi s_lo) (spindle
    torque per jaw torque without friction, = r_p / r_d times the sensors' gain ratio) and
    K = ln(s_hi / s_lo) / 2. Returns a JSON-ready dict: ``slope_high`` / ``slope_low`` / ``slope_centre``
    [-] (median over bins and groups), ``r``, ``K``, ``intercept_half_width_Nm`` (F0: half-width
    extrapolated to zero jaw torque), ``per_group`` lists. Raises ValueError when no group has two runs.
    """
    rows = []
    for g in groups:
        if len(g) < 2:
            continue
        th = np.concatenate([r.theta_p[r.k0:] for r in g])
        lo, hi = np.percentile(th, [50 * (1 - middle), 50 * (1 + middle)])
        b = [_edge_bins(r, np.arange(lo, hi, bin_rad), min_rate) for r in g]
        stack = np.stack(b)                     # (runs, bins, 4): tau_p high, low; tau_d high, low
        for i in range(stack.shape[1]):
            v = stack[:, i, :]
            if np.isnan(v).any():
                continue
            s_hi = np.polyfit(v[:, 2], v[:, 0], 1)[0]
            s_lo = np.polyfit(v[:, 3], v[:, 1], 1)[0]
            jaw = 0.5 * (v[:, 2] + v[:, 3])
            s_c, c0 = np.polyfit(jaw, 0.5 * (v[:, 0] + v[:, 1]), 1)
            s_w, w0 = np.polyfit(jaw, 0.5 * (v[:, 0] - v[:, 1]), 1)
            rows.append((s_hi, s_lo, s_c, w0, s_w, c0))
    if not rows:
        raise ValueError("load_sweep needs at least one group of two runs at different loads")
    a = np.median(np.asarray(rows), axis=0)
    return {"slope_high": float(a[0]), "slope_low": float(a[1]), "slope_centre": float(a[2]),
            "r": float(np.sqrt(a[0] * a[1])) if a[0] * a[1] > 0 else float("nan"),
            "K": float(0.5 * np.log(a[0] / a[1])) if a[0] > 0 and a[1] > 0 else float("nan"),
            "intercept_half_width_Nm": float(a[3]), "half_width_per_jaw_torque": float(a[4]),
            "centre_at_zero_jaw_torque_Nm": float(a[5]), "n_bins": len(rows)}


def select_extensions(runs: list[RunData], centre: float, theta_ref: float, step: int = 50,
                      candidates: tuple[str, ...] | None = None,
                      progress: Callable[[str], None] | None = None, fixed: tuple[str, ...] = (),
                      start: SpindleParams | None = None) -> dict:
    """Forward selection of torque extensions on a time split of every run (module docstring).

    ``fixed`` names base parameters held at their ``start`` values (e.g. rho from the kinematic
    ratio, :func:`kinematic_ratio`).

    Returns a JSON-ready dict: ``base`` {params, rmse_fit, rmse_val} [N m], ``rounds`` (per round:
    candidate -> {rmse_val [N m], S, price}), ``chosen`` (extension ids in order), ``params``
    (the chosen model's values).
    """
    tick = progress or (lambda label: None)
    cands = list(candidates if candidates is not None else EXTENSIONS)
    bf, yf, _, wf = batch_of(runs, centre, theta_ref, step, "first")
    bv, yv, _, wv = batch_of(runs, centre, theta_ref, step, "second")
    p0, _ = fit_torque(bf, yf, (), start=start, weights=wf, fixed=fixed, multistart=True)
    tick("base")
    base_val = _rmse(p0, bv, yv, wv)
    rounds: list[dict] = []
    out: dict = {"base": {"params": p0.as_dict(), "rmse_fit": _rmse(p0, bf, yf, wf), "rmse_val": base_val},
                 "rounds": rounds, "chosen": [], "fixed": list(fixed)}
    chosen: list[str] = []
    p_ch, s_ch = p0, 1.0
    while True:
        rnd = {}
        best: tuple[float, str, SpindleParams, float] | None = None
        for c in [c for c in cands if c not in chosen]:
            q, _ = fit_torque(bf, yf, tuple(chosen) + (c,), start=p_ch.with_values(**{c: EXTENSION_STARTS.get(c, 0.0)}),
                              weights=wf, max_nfev=80, fixed=fixed)
            v = _rmse(q, bv, yv, wv)
            S = (v / base_val) ** 2
            price = S / s_ch + PENALTY * 1
            rnd[c] = {"rmse_val": v, "S": S, "price": price}
            tick(f"+{c}")
            if best is None or price < best[0]:
                best = (price, c, q, S)
        rounds.append(rnd)
        if best is None or best[0] >= 1.0:
            break
        chosen.append(best[1])
        p_ch, s_ch = best[2], best[3]
    out["chosen"], out["params"] = chosen, p_ch.as_dict()
    out["rmse_val"] = _rmse(p_ch, bv, yv, wv)
    return out


def shared_fit(runs: list[RunData], free: tuple[str, ...], centre: float, theta_ref: float, step: int = 50,
               start: SpindleParams | None = None, max_nfev: int = 300, fixed: tuple[str, ...] = ()) -> SpindleParams:
    """The model BASE + ``free`` fitted to every run from its k0 on (torque, then angle); ``fixed``
    base parameters are held at their ``start`` values."""
    bt, yt, ya, w = batch_of(runs, centre, theta_ref, step)
    p, _ = fit_torque(bt, yt, free, start=start, weights=w, max_nfev=max_nfev, fixed=fixed)
    return fit_angle(p, bt, ya, weights=w)


def leave_one_out(runs: list[RunData], free: tuple[str, ...], centre: float, theta_ref: float, start: SpindleParams,
                  step: int = 50, progress: Callable[[str], None] | None = None, fixed: tuple[str, ...] = ()
                  ) -> list[tuple[SpindleParams, np.ndarray, np.ndarray]]:
    """For each run: (parameters refitted without it, predicted jaw torque [N m], angle [rad] at full rate);
    ``fixed`` base parameters keep their ``start`` values."""
    tick = progress or (lambda label: None)
    out = []
    for r in runs:
        others = [s for s in runs if s is not r]
        q = shared_fit(others, free, centre, theta_ref, step, start=start, max_nfev=60, fixed=fixed)
        b = make_batch([(r.tau_p, r.theta_p)], centre, theta_ref, r.dt)
        out.append((q, predict_torque(q, b), predict_angle(q, b)))
        tick(f"leave out {r.name}")
    return out
