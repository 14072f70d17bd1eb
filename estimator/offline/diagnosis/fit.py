"""Fitting and scoring for the diagnosis (:mod:`estimator.offline.diagnosis.selection` selects;
docs/concepts/diagnosis.md).

* :func:`prepare`: block-average the recording to about ``target_rate`` (zero phase; the noise
  drops, the rate-independent maths does not change), a 3-sample mean on T_in, velocity dx_in/dt,
  noise levels, the model's node grid.
* :func:`split_at_rest`: training = the first ``train_fraction`` of the duration, moved to the
  quietest rest within 8 % of it so that whole cycles are held out; never random samples
  (neighbouring samples are almost equal and would leak).
* :func:`fit_model`: K and the extensions' parameters by ``scipy.optimize.least_squares`` on the
  training block, L/EA in closed form inside every evaluation (it enters x_out linearly).
* :func:`heldout_mse`, :func:`raw_rmse`: held-out errors on the averaged series and on the
  measured samples (the model always runs from the first sample, so the held-out block starts from
  the state the training block left, as online use would).
"""
from __future__ import annotations

import itertools
import math
import sys
from dataclasses import replace
from collections.abc import Callable

import numpy as np
from scipy.optimize import least_squares

from estimator.offline.diagnosis import thresholds as th
from estimator.offline.diagnosis.instant import profile_discrete
from estimator.offline.diagnosis.refinement import refine_best
from estimator.offline.effects.catalogue import Effect, predict
from estimator.offline.effects.types import K_MAX
from estimator.offline.effects.types import ROUTE
from estimator.offline.effects.types import ROUTE_FORMS
from estimator.offline.effects.types import Parameter
from estimator.offline.effects.types import Series
from estimator.offline.effects.predict import slide_window
from estimator.offline.effects.kernels import distal_slide
from estimator.sheath import SheathModel
from estimator.data import MeasuredData, noise_level
from estimator.errors import DataError

__all__ = [
    "Progress", "trimmed_ms", "paired_trimmed_ms", "prepare", "split_at_rest", "fit_model", "start_points",
    "rest_window", "rest_start", "heldout_mse", "raw_rmse", "quantum", "SIGNALS", "settings_keys", "predictions",
    "fit_residual", "SCALE",
]

_K = Parameter("K", "-", 0.0, K_MAX, 0.5, (), "friction exponent mu * total wrap angle")
#: [unit of each parameter] the fits' variables are the parameters over these (O(1) at a typical magnitude)
SCALE = {"K": 0.1, "c_v": 10.0, "T0": 1.0, "K_rate": 1e-3, "beta": 1.0, "T_c": 1.0, "r_s": 0.1, "a": 0.5,
          "x_p": 2e-5, "d_b": 2e-5, **{f"r_{k}": 0.1 for k in range(1, 12)},
          "b_T_in": 0.5, "b_T_out": 0.5, "g_T_in": 0.02, "g_T_out": 0.02, "tau_T_in": 0.01, "tau_T_out": 0.01,
          "d_T_in": 2e-3, "d_T_out": 2e-3, "b_x_in": 2e-5, "b_x_out": 2e-5, "tau_x_in": 0.01, "tau_x_out": 0.01,
          "dK": 0.1}
SIGNALS = ("T_out", "x_out")
#: every FIT_STRIDE-th sample of the averaged series enters the least-squares residual (the model
#: runs on all of them; the residual vector, and so the trust-region algebra, is that much shorter)
FIT_STRIDE = 3


def quantum(a: np.ndarray) -> float:
    """The quantisation step of a recorded channel [unit of a]: the 5th percentile of the non-zero
    sample-to-sample steps when the channel only takes multiples of one step (else 0)."""
    d = np.abs(np.diff(np.asarray(a, dtype=float)))
    d = d[d > 0]
    if d.size < 20:
        return 0.0
    q = float(np.percentile(d, 5))
    steps = d[: 2000] / q
    return q if np.all(np.abs(steps - np.round(steps)) < 0.05) else 0.0



def prepare(data: MeasuredData, *, n_nodes: int = 32, target_rate: float = 200.0,
            wrap_shape: np.ndarray | None = None) -> Series:
    """Block-average a recording to about ``target_rate`` [Hz] and set up the model's node grid.

    Parameters
    ----------
    data : MeasuredData with time [s], x_in [m], T_in [N] and x_out [m] and/or T_out [N]
    n_nodes : elements of the tension profile (32 keeps the elongation error below 0.1 um)
    wrap_shape : normalised route shape, see :class:`estimator.sheath.SheathModel` (None: uniform)

    Raises
    ------
    DataError
        No distal column, or a non-finite sample in a column. ValueError: fewer than 400 samples after
        averaging.
    """
    data.require_distal()
    for name in ("time", "x_in", "T_in", "x_out", "T_out"):
        col = getattr(data, name)
        bad = np.flatnonzero(~np.isfinite(np.asarray(col, dtype=float))) if col is not None else np.empty(0, int)
        if bad.size:
            raise DataError(f"{data.source}: column {name} has {bad.size} non-finite samples (first at sample "
                            f"{int(bad[0])}); cut the recording before them or repair the column")
    t = np.asarray(data.time, dtype=float)
    fs = (t.size - 1) / max(t[-1] - t[0], 1e-12)
    m = max(1, int(fs // target_rate))
    nb = t.size // m
    if nb < 400:
        raise ValueError(f"{data.source}: {t.size} samples at {fs:.0f} Hz are too few to diagnose (need >= 400 "
                         f"after averaging to {target_rate:.0f} Hz, i.e. a few cycles)")

    def dec(a):
        return None if a is None else np.asarray(a, dtype=float)[: nb * m].reshape(nb, m).mean(axis=1)

    time, x_in, T_in = dec(t), dec(data.x_in), dec(data.T_in)
    sigma_in = noise_level(T_in) / math.sqrt(3.0)          # after the mean below
    # a further 3-sample zero-phase mean on T_in: the play operator latches noise extremes (times
    # e^K on release), and this halves that bias while keeping reversal corners
    T_in = np.convolve(np.pad(T_in, 1, mode="edge"), np.ones(3) / 3.0, mode="valid")
    velocity = np.gradient(x_in, time)
    shape, weight = SheathModel(K=1.0, compliance=1.0, wrap_shape=wrap_shape).nodes(int(n_nodes))
    T_min = max(10.0 * sigma_in, 0.01 * float(np.ptp(T_in)))
    x_out = dec(data.x_out)
    travel, slide = 0.0, None
    if x_out is not None and data.x_out is not None and th.SLIDE_SEEN:
        travel = max(th.SLIDE_QUANTA * quantum(data.x_out), th.SLIDE_SIGMAS * noise_level(x_out),
                     th.SLIDE_SHARE * float(np.ptp(x_in)))
        slide = distal_slide(x_out, travel, slide_window(time))
    return Series(time, x_in, T_in, velocity, dec(data.T_out), x_out, shape, weight, T_min, sigma_in, travel, slide)


def split_at_rest(s: Series, train_fraction: float) -> int:
    """Index of the first held-out sample: near ``train_fraction`` of the duration, at a rest.

    Within +-8 % of the duration around the nominal split the sample with the lowest
    (0.5 s mean speed / its median + T_in / range of T_in) is taken, so the split falls in a hold at
    low tension between cycles when there is one. Raises ValueError for a fraction outside
    [0.3, 0.9] or blocks of fewer than 20 samples.
    """
    if not 0.3 <= train_fraction <= 0.9:
        raise ValueError(f"train_fraction must be in [0.3, 0.9], got {train_fraction!r}")
    t = s.time
    dur = t[-1] - t[0]
    lo = np.searchsorted(t, t[0] + (train_fraction - 0.08) * dur)
    hi = np.searchsorted(t, t[0] + (train_fraction + 0.08) * dur)
    win = max(1, min(int(round(0.5 / max(np.median(np.diff(t)), 1e-9))), len(s) // 4))
    v = np.convolve(np.abs(s.velocity), np.ones(win) / win, mode="same")
    score = v / max(float(np.median(v)), 1e-12) + (s.T_in - s.T_in.min()) / max(float(np.ptp(s.T_in)), 1e-12)
    k = int(lo + np.argmin(score[lo:hi])) if hi > lo else int(np.searchsorted(t, t[0] + train_fraction * dur))
    if k < 20 or len(s) - k < 20:
        raise ValueError(f"a {train_fraction:.0%} split leaves a block with fewer than 20 samples")
    return k


def _params(effects: list[Effect], route: bool | str = False) -> list[Parameter]:
    shares = list(ROUTE_FORMS[route]) if isinstance(route, str) else list(ROUTE) if route else []
    return [_K] + shares + [p for e in effects for p in e.parameters if not p.discrete]


def _residual_scales(s: Series) -> dict[str, float]:
    out = {}
    for name in SIGNALS:
        y = getattr(s, name)
        if y is not None:
            out[name] = max(float(np.ptp(y)), 1e-12)
    return out


def fit_model(effects: list[Effect], train: Series, starts: list[dict[str, float]], *,
              max_starts: int = 2, route: bool | str = False, fixed: dict[str, float] | None = None,
              mask: slice | None = None, tol: float = th.FIT_TOL) -> tuple[dict[str, float], float, float]:
    """Least-squares fit of K and the parameters of ``effects`` on a training series.

    Every start (dict of parameter values, missing ones neutral) is scored, the best
    ``max_starts`` are refined by ``scipy.optimize.least_squares`` (trust-region reflective, within
    the parameters' bounds, in variables scaled to O(1)). L/EA is solved in closed form inside
    every residual evaluation. ``route``: fit the route shares r_1, r_2 too (estimator.offline.effects.types.ROUTE),
    or with "fine" the sixths r_1 ... r_5 (estimator.offline.effects.types.ROUTE_FINE), with "twelfths" r_1 ... r_11
    (estimator.offline.effects.types.ROUTE_TWELFTHS);
    ``fixed``: values held (e.g. the base model's route); ``mask``: the samples of ``train`` whose
    residuals count (default all; the model always runs from the first sample). A refinement that takes
    no step at all (K on the edge of a step in the residual) is tried again with K held, then with all
    free from there, and that is kept when it costs less with the effects' parameters inside their bounds.
    A discrete parameter (``Parameter.discrete``: the instant of a step) not in ``fixed`` is fitted first by a
    profile over candidate instants in the fit block from the best start
    (:func:`estimator.offline.diagnosis.instant.profile_discrete`) and then held. ``tol``: the refinements'
    relative ftol and xtol (``thresholds.FIT_TOL``; the model choice passes ``thresholds.CHOICE_TOL``).
    Returns (values, compliance [m/N], cost).
    """
    m, norm, ys, stop = _fit_block(train, mask)
    params = _params(effects, route)
    # an effect's form (Effect.variants: held, not fitted) travels with the first start
    fixed = {**{k: starts[0][k] for k in settings_keys(effects) if starts and k in starts[0]}, **(fixed or {})}
    scale = np.array([SCALE[p.name] for p in params])
    lo = np.array([p.lower for p in params]) / scale
    hi = np.array([p.upper for p in params]) / scale

    def values(z):
        return {**fixed, **{p.name: float(v) for p, v in zip(params, z * scale, strict=False)}}

    # every point evaluated, by its bytes and the held discrete values: (residual, L/EA). The starts are ranked and
    # then refined from, and the solution's L/EA is that of its last evaluation: none is run twice
    seen: dict[bytes, tuple[np.ndarray, float]] = {}
    discrete = [p for e in effects for p in e.parameters if p.discrete and p.name not in fixed]

    def key_of(z) -> bytes:
        return np.asarray(z, dtype=float).tobytes() + repr([fixed.get(p.name) for p in discrete]).encode()

    def residual(z):
        key = key_of(z)
        if key not in seen:
            pr = predict(effects, values(z), train, fit_mask=m, stop=stop)
            seen[key] = (_residual_of(pr, m, norm, ys), pr.compliance)
        return seen[key][0].copy()

    def refine(fun, z, lower, upper):
        return least_squares(fun, z, bounds=(lower, upper), diff_step=1e-2, x_scale=1.0, ftol=tol, xtol=tol,
                             max_nfev=40 * len(z))

    z_starts = [np.clip(np.array([st.get(p.name, p.neutral) for p in params]) / scale, lo, hi) for st in starts]
    if discrete:
        z_starts = profile_discrete(discrete[0], effects, params, scale, fixed, residual, z_starts, lo, hi,
                                    train.time, m)
    ranked = sorted(z_starts, key=lambda z: float(np.sum(residual(z) ** 2)))
    own = slice(len(_params([], route)), None)             # the effects' parameters
    best = refine_best(ranked[:max_starts], residual, refine, lo, hi, own)
    vals = values(best.x)
    key = key_of(best.x)
    c = seen[key][1] if key in seen else predict(effects, vals, train, fit_mask=m, stop=stop).compliance
    return vals, c, float(best.cost)


def _fit_block(train: Series, mask: slice | None) -> tuple[slice, dict[str, float], dict[str, np.ndarray], int | None]:
    """The samples whose residuals count, each signal's scale (its range), its measured samples there (every
    FIT_STRIDE-th) and the sample the model may stop at (the forward fold's residuals end where its fit block does:
    the model runs no further than they need; None: the whole series)."""
    m = slice(None) if mask is None else mask
    norm = _residual_scales(train)
    ys = {k: getattr(train, k)[m][::FIT_STRIDE] for k in norm}
    stop = m.stop if isinstance(m, slice) and m.stop is not None and 0 < m.stop < len(train) else None
    return m, norm, ys, stop


def _residual_of(pr, m: slice, norm: dict[str, float], ys: dict[str, np.ndarray]) -> np.ndarray:
    return np.concatenate([(getattr(pr, k)[m][::FIT_STRIDE] - ys[k]) / v for k, v in norm.items()])


def fit_residual(effects: list[Effect], values: dict[str, float], train: Series, mask: slice | None) -> np.ndarray:
    """The residual vector :func:`fit_model` minimises, at ``values``: each distal signal's model minus measured
    samples over ``mask`` (every FIT_STRIDE-th sample), divided by the signal's range; shape (n,), n the kept samples
    times the signals. The same numbers as inside the fit."""
    m, norm, ys, stop = _fit_block(train, mask)
    return _residual_of(predict(effects, values, train, fit_mask=m, stop=stop), m, norm, ys)


def settings_keys(effects: list[Effect]) -> set[str]:
    """Names of the held settings of ``effects`` (the keys of their ``variants``)."""
    return {k for e in effects for v in e.variants for k in v}


def start_points(effects: list[Effect], base: dict[str, float], s: Series, fixed: dict[str, float]) -> list[dict]:
    """Starting points: the fitted values so far, and the product of each new parameter's starts
    (the effects' held settings, e.g. the pre-sliding form, taken from ``fixed``)."""
    held = {k: fixed[k] for k in settings_keys(effects) if k in fixed}
    first = rest_window(s)
    grids = []
    for e in effects:
        for p in e.parameters:
            if p.name in fixed:
                grids.append([(p.name, fixed[p.name])])
            elif p.rest == "replace":      # from the rest reading only (Parameter.rest)
                grids.append([(p.name, max(rest_start(p.name, s, first), 0.1))])
            elif p.rest == "extend":       # ... or also, when it lies beyond the starts
                rest = rest_start(p.name, s, first)
                grids.append([(p.name, v) for v in (*p.starts, *((rest,) if abs(rest) > max(p.starts) else ()))])
            else:
                grids.append([(p.name, v) for v in (p.starts or (p.neutral,))])
    # a base model driven to K = 0 by what it lacks (a large pretension) sits where the
    # noise band of the memory rule leaves K without a gradient: the extension also starts from a typical K
    ks = [base["K"]] + ([th.K_RESTART] if base["K"] < 0.1 * th.K_RESTART else [])
    return [{"K": k, **held, **dict(combo)} for k in ks for combo in itertools.product(*grids)]


def rest_window(s: Series) -> slice:
    """The first samples of a prepared series, taken as the initial rest before the first move (the first
    half percent, at least 3; the start values of Parameter.rest)."""
    return slice(0, max(3, len(s) // 200))


def rest_start(name: str, s: Series, first: slice) -> float:
    """The value parameter ``name`` takes if the samples ``first`` (the initial rest) read it alone: T_in
    there for a tension (the pretension T0, the T_in offset b_T_in) [N]; x_out - x_in for the x_out offset
    and x_in - x_out for the x_in offset (no elongation at rest without a pretension) [m]; nan without x_out."""
    if name in ("b_x_out", "b_x_in"):
        if s.x_out is None:
            return float("nan")
        d = float(np.median(s.x_out[first] - s.x_in[first]))
        return d if name == "b_x_out" else -d
    return float(np.median(s.T_in[first]))


def heldout_mse(pr, s: Series, k: int) -> dict[str, float]:
    return {name: float(np.mean((getattr(pr, name)[k:] - getattr(s, name)[k:]) ** 2))
            for name in SIGNALS if getattr(s, name) is not None}


def raw_rmse(pr, s: Series, data: MeasuredData, t_split: float) -> dict[str, float | None]:
    """Held-out rmse on the measured samples (predictions interpolated to the raw time base)."""
    m = data.time >= t_split
    out: dict[str, float | None] = {}
    for name, unit in (("T_out", "N"), ("x_out", "m")):
        y = getattr(data, name)
        out[f"rmse_{name}_{unit}"] = None if y is None else float(
            np.sqrt(np.mean((np.interp(data.time[m], s.time, getattr(pr, name)) - y[m]) ** 2)))
    return out


class Progress:
    """A one-line stderr bar (``enabled`` True), a callback(done, total, label), or nothing.

    The bar redraws itself with carriage returns, which only a terminal shows as one line: when stderr is not a
    terminal (a log file, a pipe) it writes nothing."""

    def __init__(self, total: int, enabled: bool | Callable):
        self.total, self.done = total, 0
        self.enabled = enabled if callable(enabled) else bool(enabled) and _is_terminal(sys.stderr)

    def __call__(self, label: str) -> None:
        self.done = min(self.done + 1, self.total)
        if callable(self.enabled):
            self.enabled(self.done, self.total, label)
        elif self.enabled:
            n = 30 * self.done // self.total
            sys.stderr.write(f"\rdiagnose [{'#' * n}{'.' * (30 - n)}] {self.done}/{self.total} {label:<28}")
            if self.done >= self.total:
                sys.stderr.write("\n")
            sys.stderr.flush()

    def finish(self) -> None:
        while self.done < self.total:       # the steps that were not needed
            self("done")


def _is_terminal(stream) -> bool:
    """Whether ``stream`` is a terminal (False for a stream without ``isatty``)."""
    isatty = getattr(stream, "isatty", None)
    return bool(isatty()) if callable(isatty) else False


def trimmed_ms(r: np.ndarray, trim: float) -> float:
    """Mean square of a residual without its largest ``trim`` share: the short transients of fast moves
    (load and motor dynamics outside any quasi-static model) do not decide the model choice."""
    r2 = np.sort(r * r)
    return float(np.mean(r2[: max(1, int(round(r2.size * (1.0 - trim))))]))


def paired_trimmed_ms(r: np.ndarray, r_ref: np.ndarray, trim: float) -> tuple[float, float]:
    """Mean squares of two models' residuals on the same samples: without the largest ``trim`` share of
    min(|r|, |r_ref|), i.e. the transients that neither model explains. Returns (ms of r, ms of r_ref).

    Trimming each model by its own largest residuals (:func:`trimmed_ms`) would drop exactly what one of
    them explains when that lives in a few short events: a lagging T_out load cell on a constant-force load
    differs from the base model only at the few steps where the load leaves or lands on its stop."""
    k = max(1, int(round(r.size * (1.0 - trim))))
    keep = np.argsort(np.minimum(np.abs(r), np.abs(r_ref)), kind="stable")[:k]
    return float(np.mean(r[keep] ** 2)), float(np.mean(r_ref[keep] ** 2))


def predictions(result: dict, data: MeasuredData) -> dict[str, np.ndarray | None]:
    """Re-run the base and the extended model of a :func:`estimator.offline.diagnosis.selection.diagnose` result on the
    measured samples (re-exported by estimator.offline.diagnosis.selection).

    Returns
    -------
    dict of ndarray, shape (n_samples,) (None for a signal not recorded): ``T_out_base``,
    ``T_out_ext`` [N], ``x_out_base``, ``x_out_ext`` [m] (interpolated from the averaged series to
    ``data.time``), ``velocity`` [m/s] and ``phase`` (int8 codes of :class:`estimator.phase.Phase`,
    from the base model).
    """
    from estimator.online.distal import estimate_batch      # local: phase classification only
    from estimator.sheath import SheathModel

    st = result["settings"]
    shape = None if st.get("wrap_shape") is None else np.asarray(st["wrap_shape"], dtype=float)
    if st.get("distal_end_held"):        # x_out was not used (diagnose): no x_out prediction either
        data = replace(data, x_out=None)
    s = prepare(data, n_nodes=st["n_nodes"], target_rate=st["target_rate_hz"], wrap_shape=shape)
    out: dict[str, np.ndarray | None] = {}
    for tag, model in (("base", result["base_model"]), ("ext", result["model"])):
        pr = predict(model["effects"], model["values"], s, compliance=model["compliance"])
        for name in SIGNALS:
            out[f"{name}_{tag}"] = None if getattr(data, name) is None else np.interp(data.time, s.time,
                                                                                     getattr(pr, name))
    out["velocity"] = np.interp(data.time, s.time, s.velocity)
    base = result["base_model"]
    out["phase"] = estimate_batch(np.interp(data.time, s.time, s.T_in), data.x_in,
                                  SheathModel(K=base["values"]["K"], compliance=max(base["compliance"], 1e-12),
                                              wrap_shape=shape), time=data.time, n_nodes=st["n_nodes"]).phase
    return out
