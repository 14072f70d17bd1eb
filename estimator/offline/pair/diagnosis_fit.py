"""The fits of the pair diagnosis (:mod:`estimator.offline.pair.diagnosis`): one model fitted on the training block
(:func:`fit_model`, :class:`FitResult`), its time-blocked cross-validation (:func:`folds`, :func:`cross_validate`)
and the test figure's bootstrap (:func:`figure_bootstrap`). Re-exported by :mod:`estimator.offline.pair.diagnosis`.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.optimize import least_squares

from estimator.offline.pair.models import head, model_id, model_params, predict_model

__all__ = ["CAPSTAN_STARTS", "MAX_NFEV", "CV_NFEV", "FIT_TOL", "SCREEN_MARGIN", "CV_BLOCKS", "TENSION_PEAK_RATIO",
           "TENSION_FIT_WEIGHT", "FitResult", "fit_model", "folds", "cross_validate", "figure_bootstrap", "spread_deg"]

#: Starting points of the capstan structure (G [-], lam [rad/N], K_a, K_b [-], k [N/rad]).
CAPSTAN_STARTS = ({"G": 1.4, "lam": 0.4, "K_a": 0.8, "K_b": 0.4, "k": 4.0},
                  {"G": 2.0, "lam": 0.3, "K_a": 0.3, "K_b": 0.3, "k": 2.0},
                  {"G": 2.0, "lam": 0.3, "K_a": 1.2, "K_b": 0.8, "k": 10.0},
                  {"G": 1.3, "lam": 0.5, "K_a": 0.5, "K_b": 0.1, "k": 1.5})
_BAD = 10.0     # residual [rad] returned for a parameter set the kernels refuse
#: Most residual evaluations of one least-squares start (bounds the run time on data far from every
#: model; the KAIST fits converge in 30-190).
MAX_NFEV = 200
#: Relative tolerances (ftol, xtol) of every least-squares fit: the fits stop once the training cost
#: changes by less than 1e-6 of itself (angle changes far below the tracker noise), not at scipy's 1e-8.
FIT_TOL = 1e-6
#: Most residual evaluations of a cross-validation refit (warm-started from the full training fit).
CV_NFEV = 40
#: A candidate whose training-error ratio alone gives a price >= 1 + SCREEN_MARGIN is not cross-validated.
SCREEN_MARGIN = 0.1
#: Contiguous time blocks of the training block, alternately given to the two cross-validation folds.
CV_BLOCKS = 8
#: Tension plausibility of a capstan-structure candidate (module docstring, step 3b): its predicted peak
#: proximal tension of each tendon over the training block must lie within this factor of the measured
#: peak. Set on command cycle 1 only: the angle-only capstan fits predict the peaks at
#: 0.74-1.40x the measured ones at N = 0-180 (the model family's known tension-shape error) and at 1.64 and
#: 1.85x at N = 240, where the fit runs along the G-lam valley (docs/results/kaist.md).
TENSION_PEAK_RATIO = 1.5
#: Weight [rad/N] of the measured proximal tensions in the residual of a ``/T`` refit (step 3b), also the
#: shared ``+T`` models' weight (:data:`estimator.offline.pair.shared.TENSION_WEIGHT` is this value; 1 N
#: costs as much as 0.57 deg).
TENSION_FIT_WEIGHT = 0.01


class FitResult:
    """A fitted model over one recording: structure, effects, values (name -> SI value), the angle
    [rad] and (capstan) proximal tensions [N] over the whole recording, train and test rmse [rad], and
    (capstan) the rmse of the predicted proximal tensions [N] on the test (``rmse_T_in``) and training
    (``rmse_T_train``) samples (None for the seed structure)."""

    def __init__(self, structure: str, effects: tuple[str, ...], values: dict[str, float], rec,
                 train: slice | np.ndarray, test: slice | np.ndarray, tension_weight: float = 0.0):
        self.structure, self.effects, self.values = structure, tuple(effects), dict(values)
        self.tension_weight = float(tension_weight)
        self.angle, self.T_in = predict_model(structure, self.effects, self.values, rec)
        err = self.angle - np.asarray(rec.angle, dtype=float)
        self.rmse_train = float(np.sqrt(np.mean(err[train] ** 2)))
        self.rmse_test = float(np.sqrt(np.mean(err[test] ** 2)))
        self.max_test = float(np.max(np.abs(err[test])))
        T = np.column_stack([rec.T_a, rec.T_b])
        self.rmse_T_in = None if self.T_in is None else float(np.sqrt(np.mean((self.T_in[test] - T[test]) ** 2)))
        self.rmse_T_train = None if self.T_in is None else float(np.sqrt(np.mean((self.T_in[train] - T[train]) ** 2)))

    @property
    def id(self) -> str:
        """Model id (:func:`estimator.offline.pair.models.model_id`), ``/T`` appended when the fit had the
        measured proximal tensions in its residual."""
        return model_id(self.structure, self.effects) + ("/T" if self.tension_weight > 0.0 else "")

    def tension_peak_ratio(self, rec, train: slice | np.ndarray) -> list[float] | None:
        """Predicted / measured peak proximal tension of tendons a and b over the ``train`` samples (None
        for the seed structure, which takes the tensions as input). Raises ValueError when a measured peak
        is not positive."""
        if self.T_in is None:
            return None
        meas = np.max(np.column_stack([rec.T_a, rec.T_b])[train], axis=0)
        if not np.all(meas > 0.0):
            raise ValueError(f"measured proximal tension peaks must be > 0 N, got {meas.tolist()}")
        return [float(x) for x in np.max(self.T_in[train], axis=0) / meas]

    @property
    def n_params(self) -> int:
        return len(model_params(self.structure, self.effects))

    def summary(self) -> dict:
        """JSON-ready: model, fit_inputs (which measured signals the fit used), params {name: {value, unit}},
        rmse_train_deg, rmse_test_deg,
        max_abs_test_deg, rmse_T_in_N (predicted vs measured proximal tensions on the test block;
        None for the seed structure, which takes them as input)."""
        units = {p.name: p.unit for p in model_params(self.structure, self.effects)}
        return {"model": self.id, "fit_inputs": "command, measured angle" + (
                    f" and measured proximal tensions (weight {self.tension_weight:g} rad/N)" if self.tension_weight > 0
                    else " (proximal tensions: first sample only)" if self.structure == "capstan"
                    else " and measured proximal tensions (model input)"),
                "params": {k: {"value": float(v), "unit": units[k]} for k, v in self.values.items()},
                "rmse_train_deg": math.degrees(self.rmse_train), "rmse_test_deg": math.degrees(self.rmse_test),
                "max_abs_test_deg": math.degrees(self.max_test), "rmse_T_in_N": self.rmse_T_in}


def fit_model(structure: str, effects: tuple[str, ...], rec, train: slice | np.ndarray,
              test: slice | np.ndarray,
              starts: list[dict[str, float]], max_nfev: int = MAX_NFEV, tension_weight: float = 0.0) -> FitResult:
    """Fit one model on the ``train`` samples by ``least_squares`` from each start; keep the lowest
    training cost.

    Parameters
    ----------
    structure, effects : the model (:mod:`estimator.offline.pair.models`)
    rec : recording (time, command, T_a, T_b, angle; arrays of shape (n,))
    train, test : slices of the samples (the model runs from sample 0 in both cases)
    starts : starting values by name; a missing name takes each of its parameter's ``starts``
    max_nfev : most residual evaluations per start
    tension_weight : w [rad/N] >= 0; > 0 adds the measured proximal tensions to the residual of the
        capstan structure, w (T_in,model - T_in,measured) beside the angle error (the "+T" fits of
        :mod:`estimator.offline.pair.shared`; docs/results/kaist.md). 0 (default): angle only.
        The diagnosis itself fits on the angle only.

    Returns
    -------
    FitResult

    Raises
    ------
    ValueError
        ``tension_weight`` negative or not finite.
    """
    if not (math.isfinite(tension_weight) and tension_weight >= 0.0):
        raise ValueError(f"tension_weight must be finite and >= 0, got {tension_weight!r}")
    params = model_params(structure, effects)
    names = [p.name for p in params]
    lo = np.array([p.lo for p in params])
    hi = np.array([p.hi for p in params])
    y = np.asarray(rec.angle, dtype=float)[train]

    part = head(rec, train)                       # the model is causal: run it up to the fitted samples only
    w = tension_weight if structure == "capstan" else 0.0
    T_meas = np.column_stack([rec.T_a, rec.T_b])[train] if w > 0.0 else None

    def residual(x: np.ndarray) -> np.ndarray:
        try:
            th, T = predict_model(structure, effects, dict(zip(names, map(float, x), strict=False)), part)
        except ValueError:
            return np.full(y.size * (3 if w > 0.0 else 1), _BAD)
        if T_meas is not None and T is not None:
            return np.concatenate([th[train] - y, (w * (T[train] - T_meas)).ravel()])
        return th[train] - y

    x0s = []
    for s in starts:
        missing = [p for p in params if p.name not in s]
        for extra in (zip(*[p.starts for p in missing], strict=False) if missing else [()]):
            v = {**s, **{p.name: x for p, x in zip(missing, extra, strict=False)}}
            x0s.append(np.clip([v[n] for n in names], lo, hi))
    best = None
    for x0 in x0s:
        sol = least_squares(residual, x0, bounds=(lo, hi), x_scale=[p.scale for p in params], diff_step=1e-3,
                            max_nfev=max_nfev, ftol=FIT_TOL, xtol=FIT_TOL)
        if best is None or sol.cost < best.cost:
            best = sol
    assert best is not None                       # at least one start
    return FitResult(structure, effects, dict(zip(names, map(float, best.x), strict=False)), rec, train, test, w)


def folds(train: slice, n: int, blocks: int = CV_BLOCKS) -> list[tuple[np.ndarray, np.ndarray]]:
    """The two folds of the time-blocked cross-validation inside ``train`` (of a recording of ``n``
    samples): the block is cut into ``blocks`` contiguous time blocks, fold 1 holds the even ones and
    fold 2 the odd ones; returns [(fit on fold 1, score on fold 2), (fit on fold 2, score on fold 1)]
    as sample index arrays."""
    a, b, _ = train.indices(n)
    edges = np.linspace(a, b, blocks + 1).round().astype(int)
    parts = [np.arange(edges[i], edges[i + 1]) for i in range(blocks)]
    even, odd = np.concatenate(parts[0::2]), np.concatenate(parts[1::2])
    return [(even, odd), (odd, even)]


def cross_validate(fx: FitResult, rec, train: slice, max_nfev: int = CV_NFEV,
                   tension_weight: float | None = None) -> float:
    """Time-blocked cross-validation rmse [rad] of a fitted model inside the training block
    (:func:`folds`; each fold refitted from ``fx.values``, the model running from the first sample,
    with the tension weight of :func:`fit_model`, by default the one ``fx`` was fitted with; the score is
    the angle's alone)."""
    if tension_weight is None:
        tension_weight = fx.tension_weight
    y = np.asarray(rec.angle, dtype=float)
    sq = []
    for fit_on, score_on in folds(train, len(y)):
        f = fit_model(fx.structure, fx.effects, rec, fit_on, score_on, [dict(fx.values)], max_nfev=max_nfev,
                      tension_weight=tension_weight)
        sq.append(np.mean((f.angle[score_on] - y[score_on]) ** 2))
    return float(np.sqrt(np.mean(sq)))


def figure_bootstrap(fx: FitResult, rec, train: slice, test: slice, n_draws: int = 20, seed: int = 0) -> dict:
    """Uncertainty of a fitted model's test figure: its training block cut into :data:`CV_BLOCKS`
    contiguous time blocks (one command cycle: no cycles to draw), the blocks drawn with replacement,
    the model refitted on each draw (warm start ``fx.values``, :data:`CV_NFEV` evaluations) and its
    test-block RMSE recorded. Returns {std_deg, ci95_deg [2.5, 97.5 %], n_draws, method}.

    Raises
    ------
    ValueError
        ``n_draws`` < 5.
    """
    if n_draws < 5:
        raise ValueError(f"n_draws must be >= 5, got {n_draws}")
    a, b, _ = train.indices(len(rec.angle))
    edges = np.linspace(a, b, CV_BLOCKS + 1).round().astype(int)
    rng = np.random.default_rng(seed)
    xs = []
    for _ in range(n_draws):
        pick = rng.integers(0, CV_BLOCKS, CV_BLOCKS)
        idx = np.concatenate([np.arange(edges[k], edges[k + 1]) for k in pick])
        f = fit_model(fx.structure, fx.effects, rec, idx, test, [dict(fx.values)], max_nfev=CV_NFEV,
                      tension_weight=fx.tension_weight)
        xs.append(math.degrees(f.rmse_test))
    return spread_deg(xs, f"the training block's {CV_BLOCKS} time blocks drawn with replacement, refitted; the "
                          "test block scored")


def spread_deg(xs: list[float], method: str) -> dict:
    """Summary of a bootstrap's figures ``xs`` [deg] (at least 2): {std_deg (ddof 1), ci95_deg [2.5, 97.5 %
    percentiles], n_draws, method}."""
    return {"std_deg": float(np.std(xs, ddof=1)), "ci95_deg": [float(np.percentile(xs, 2.5)),
                                                               float(np.percentile(xs, 97.5))],
            "n_draws": len(xs), "method": method}
