"""What the seed pair model gets wrong on a recording of an antagonistic pair, why, and the gain.

The pair counterpart of :func:`estimator.offline.diagnosis.diagnose` for recordings with a motor command,
the two proximal tensions and the distal angle only (the KAIST flexible endoscope,
docs/findings.md). The models and effects are in :mod:`estimator.offline.pair_models`. Held-out
discipline: model choice sees the training block only; the test block is touched once, for the
reported figure of the chosen model (and of the seed model it is compared with).

1. Every model is fitted on the whole training block (the first command cycle) with
   ``scipy.optimize.least_squares`` from a few starting points (relative tolerances FIT_TOL), and
   always runs from the first sample, so the test block (the later cycles) starts from the state the
   training left. The models are causal, so a fit runs them only up to its last fitted sample
   (:func:`estimator.offline.pair_models.head`; the same predictions there, bit for bit).
2. Choice by time-blocked cross-validation inside the training block: the block is cut into
   CV_BLOCKS (8) contiguous time blocks, the even ones form fold 1 and the odd ones fold 2; the
   model is refitted on each fold (warm start from step 1, at most CV_NFEV evaluations, the model
   still running from the first sample) and scored on the other; cv rmse = root of the mean of the
   two squared fold errors. (Halves, one reversal each, made the refits wander: an extrapolation
   to the other reversal rather than a check of the fit.)
   Score S = (cv rmse / cv rmse of the seed)^2.
3. Forward selection with a price per parameter: starting from the seed, the candidate with the
   lowest S / S_chosen + PENALTY (n_params - n_params_chosen) is accepted when that is below 1
   (PENALTY: the single-tendon diagnosis's price, :data:`estimator.offline.diagnosis.PENALTY`); the first
   round offers the capstan structure (``capstan_joint``) and the seed with each effect, later
   rounds every effect that applies to the model chosen so far; at most ``max_effects`` are
   accepted, and the search stops once the chosen model's cv rmse is within STRUCTURE_RATIO
   times the tracker noise. A candidate whose *training* rmse ratio alone already prices it out
   ((rmse_train / rmse_train,chosen)^2 + PENALTY x extra parameters >= 1 + SCREEN_MARGIN) is not
   cross-validated (listed as ``screened_out``), which saves most of the refits.
3b. Tension plausibility (session 8, docs/findings.md, Finding 3; ``tension_ratio``, default
   :data:`TENSION_PEAK_RATIO`): the proximal tensions are measured on the training block too, and a
   capstan-structure model predicts them. A candidate whose predicted peak proximal tension of either
   tendon over the training block is more than ``tension_ratio`` times, or less than 1 / ``tension_ratio``
   times, the measured peak is refused (listed with ``refused``, not cross-validated, never accepted):
   its angle fit has run along a valley of the parameters (G against lam) that the angle of one cycle
   does not close. When the capstan structure itself is refused in the first round, it is refitted with
   the measured proximal tensions in the residual (weight :data:`TENSION_FIT_WEIGHT`, the shared
   models' ``+T`` weight; id ``capstan/T``) and that fit, checked the same way, is the structure's
   candidate; effects added later to a ``/T`` model are fitted the same way. Models are still scored
   by the angle's cross-validation only. ``tension_ratio=None`` gives the procedure before session 8.
4. ``unknown`` is appended when the chosen model's cv rmse is still above STRUCTURE_RATIO (3) times
   the tracker noise (robust level of the angle's second differences): structure left that no
   candidate explains. ``none`` when nothing is accepted and no structure is left.
"""
from __future__ import annotations

import math
import time as _time
from typing import Callable

import numpy as np
from scipy.optimize import least_squares

from estimator.offline.diagnosis import PENALTY, STRUCTURE_RATIO
from estimator.offline.diagnosis_fit import noise_level
from estimator.offline.pair import fit_pair
from estimator.offline.pair_models import (CAUSE_OF_SEED, PAIR_EFFECTS, applicable, head, model_id, model_params,
                                           predict_model)

__all__ = ["CAPSTAN_STARTS", "MAX_NFEV", "CV_NFEV", "FIT_TOL", "TENSION_PEAK_RATIO", "TENSION_FIT_WEIGHT", "fit_model", "folds", "cross_validate", "diagnose_pair",
           "figure_bootstrap", "spread_deg", "FitResult"]

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
#: peak. Set in session 8 on command cycle 1 only: the angle-only capstan fits predict the peaks at
#: 0.74-1.40x the measured ones at N = 0-180 (the model family's known tension-shape error) and at 1.64 and
#: 1.85x at N = 240, where the fit runs along the G-lam valley (docs/findings.md, Finding 3).
TENSION_PEAK_RATIO = 1.5
#: Weight [rad/N] of the measured proximal tensions in the residual of a ``/T`` refit (step 3b), also the
#: shared ``+T`` models' weight (:data:`estimator.offline.pair_shared.TENSION_WEIGHT` is this value; 1 N
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
        """Model id (:func:`estimator.offline.pair_models.model_id`), ``/T`` appended when the fit had the
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
    structure, effects : the model (:mod:`estimator.offline.pair_models`)
    rec : recording (time, command, T_a, T_b, angle; arrays of shape (n,))
    train, test : slices of the samples (the model runs from sample 0 in both cases)
    starts : starting values by name; a missing name takes each of its parameter's ``starts``
    max_nfev : most residual evaluations per start
    tension_weight : w [rad/N] >= 0; > 0 adds the measured proximal tensions to the residual of the
        capstan structure, w (T_in,model - T_in,measured) beside the angle error (the "+T" fits of
        :mod:`estimator.offline.pair_shared`; docs/findings.md, Finding 3). 0 (default): angle only.
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
            th, T = predict_model(structure, effects, dict(zip(names, map(float, x))), part)
        except ValueError:
            return np.full(y.size * (3 if w > 0.0 else 1), _BAD)
        if T_meas is not None and T is not None:
            return np.concatenate([th[train] - y, (w * (T[train] - T_meas)).ravel()])
        return th[train] - y

    x0s = []
    for s in starts:
        missing = [p for p in params if p.name not in s]
        for extra in (zip(*[p.starts for p in missing]) if missing else [()]):
            v = {**s, **{p.name: x for p, x in zip(missing, extra)}}
            x0s.append(np.clip([v[n] for n in names], lo, hi))
    best = None
    for x0 in x0s:
        sol = least_squares(residual, x0, bounds=(lo, hi), x_scale=[p.scale for p in params], diff_step=1e-3,
                            max_nfev=max_nfev, ftol=FIT_TOL, xtol=FIT_TOL)
        if best is None or sol.cost < best.cost:
            best = sol
    assert best is not None                       # at least one start
    return FitResult(structure, effects, dict(zip(names, map(float, best.x))), rec, train, test, w)


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


def diagnose_pair(rec, train: slice, test: slice, *, max_effects: int = 2,
                  progress: Callable[[str], None] | None = None,
                  n_bootstrap: int = 0,
                  tension_ratio: float | None = TENSION_PEAK_RATIO) -> tuple[dict, dict[str, FitResult]]:
    """Diagnose one pair recording: the seed model's error, the effects that explain it, the gain.

    Parameters
    ----------
    rec : recording with time [s], command [rad], T_a, T_b [N], angle [rad], arrays of shape (n,)
    train, test : sample slices (KAIST: command cycle 1 and the later cycles, :func:`study.kaist.split`);
        the choice uses ``train`` only (module docstring), ``test`` gives the reported figures
    max_effects : most effects accepted (the capstan structure counts as one), >= 1
    progress : called with a label after every fitted model
    n_bootstrap : draws of the chosen model's test-figure uncertainty (:func:`figure_bootstrap`; 0: none);
        computed after the choice, which it does not affect
    tension_ratio : factor > 1 of the tension plausibility check (module docstring, step 3b; default
        :data:`TENSION_PEAK_RATIO`), or None: no check and no ``/T`` refit (the procedure before session 8)

    Returns
    -------
    summary : dict, JSON-ready
        ``seed`` and ``extended`` (:meth:`FitResult.summary` plus ``rmse_cv_deg``; ``extended`` also
        ``rmse_test_bootstrap`` when ``n_bootstrap``), ``cause`` (first
        accepted effect, "none" or "unknown"), ``causes`` (accepted in order, plus "unknown" when
        structure is left), ``gain`` (1 - extended / seed test rmse), ``candidates`` (model id ->
        rmse_cv_deg, rmse_train_deg, score S, price, accepted, round, params, tension_peak_ratio and, when
        the check refused it, ``refused``; no test figure), ``tension_check`` (the rule and its factor),
        ``samples`` (which samples were used for what), ``noise_deg``, ``structure_ratio``,
        ``n_train``, ``n_test``, ``elapsed_s``.
    fits : dict of model id -> FitResult (predictions for figures; not JSON)

    Raises
    ------
    ValueError
        ``max_effects`` < 1, a training block shorter than 16 samples, ``tension_ratio`` not None and not
        a finite number > 1, or (with the check) a measured peak proximal tension that is not positive.
    """
    t0 = _time.perf_counter()
    if max_effects < 1:
        raise ValueError(f"max_effects must be >= 1, got {max_effects!r}")
    if tension_ratio is not None and not (math.isfinite(tension_ratio) and tension_ratio > 1.0):
        raise ValueError(f"tension_ratio must be None or a finite number > 1, got {tension_ratio!r}")
    n = len(rec.angle)
    n_train = len(range(*train.indices(n)))
    if n_train < 16:
        raise ValueError(f"the training block has {n_train} samples, need at least 16")
    tick = progress or (lambda label: None)
    sp = fit_pair(rec.command, rec.T_a, rec.T_b, rec.angle, train.stop).params
    seed = fit_model("seed", (), rec, train, test, [sp])
    cv = {seed.id: cross_validate(seed, rec, train)}
    tick("seed")
    fits: dict[str, FitResult] = {seed.id: seed}
    candidates: dict[str, dict] = {}
    chosen, accepted = seed, []
    noise = noise_level(np.asarray(rec.angle, dtype=float))

    def entry(fx: FitResult, eid: str, rnd: int) -> dict:
        """A candidate's JSON entry before cross-validation (rmse_cv_deg, score and price None)."""
        return {"effect": eid, "round": rnd, "rmse_cv_deg": None, "rmse_train_deg": math.degrees(fx.rmse_train),
                "score": None, "price": None, "accepted": False, "params": {k: float(v) for k, v in fx.values.items()},
                "tension_peak_ratio": fx.tension_peak_ratio(rec, train)}

    def implausible(ratio: list[float] | None) -> bool:
        """Whether the tension check (step 3b) refuses a candidate with these peak ratios."""
        return (tension_ratio is not None and ratio is not None
                and any(not (1.0 / tension_ratio <= x <= tension_ratio) for x in ratio))

    refusal = (None if tension_ratio is None else f"predicted peak proximal tension outside 1/{tension_ratio:g}-"
               f"{tension_ratio:g} x the measured one on the training block")

    for rnd in range(1, max_effects + 1):
        if cv[chosen.id] <= STRUCTURE_RATIO * noise:
            break                       # nothing left above the noise for another effect to explain
        trial: dict[str, tuple[str, FitResult]] = {}
        if chosen.structure == "seed":
            carried = {p.name: chosen.values[p.name] for e in chosen.effects for p in PAIR_EFFECTS[e].parameters}
            starts = [{**s, **carried} for s in CAPSTAN_STARTS]
            fx = fit_model("capstan", chosen.effects, rec, train, test, starts)
            tick(fx.id)
            e = entry(fx, CAUSE_OF_SEED, rnd)
            if implausible(e["tension_peak_ratio"]):    # step 3b: the structure refitted with the measured tensions
                fits[fx.id] = fx
                candidates[fx.id] = {**e, "refused": refusal}
                fx = fit_model("capstan", chosen.effects, rec, train, test, starts, tension_weight=TENSION_FIT_WEIGHT)
                tick(fx.id)
            trial[CAUSE_OF_SEED] = ("capstan", fx)
        for eid in applicable(chosen.structure, chosen.effects):
            fx = fit_model(chosen.structure, chosen.effects + (eid,), rec, train, test, [dict(chosen.values)],
                           tension_weight=chosen.tension_weight)
            trial[eid] = (chosen.structure, fx)
            tick(fx.id)
        price: dict[str, float] = {}
        for eid, (_, fx) in trial.items():
            fits[fx.id] = fx
            e = entry(fx, eid, rnd)
            if implausible(e["tension_peak_ratio"]):
                candidates[fx.id] = {**e, "refused": refusal}
                continue
            extra = PENALTY * (fx.n_params - chosen.n_params)
            if (fx.rmse_train / chosen.rmse_train) ** 2 + extra >= 1.0 + SCREEN_MARGIN:
                # priced out on its training error alone (a cv error is not below it): no cv refits
                candidates[fx.id] = {**e, "screened_out": "training error alone prices it out"}
                continue
            cv[fx.id] = cross_validate(fx, rec, train)
            S = (cv[fx.id] / cv[seed.id]) ** 2
            price[eid] = S / (cv[chosen.id] / cv[seed.id]) ** 2 + extra
            candidates[fx.id] = {**e, "rmse_cv_deg": math.degrees(cv[fx.id]), "score": S, "price": price[eid]}
        if not price:
            break
        best = min(price, key=lambda e: price[e])
        if price[best] >= 1.0:
            break
        chosen = trial[best][1]
        accepted.append(best)
        candidates[chosen.id]["accepted"] = True
    ratio = cv[chosen.id] / max(noise, 1e-12)
    causes = accepted + (["unknown"] if ratio > STRUCTURE_RATIO else [])
    # the chosen model's test-figure uncertainty: after the choice, which it does not affect
    boot = {"rmse_test_bootstrap": figure_bootstrap(chosen, rec, train, test, n_bootstrap)} if n_bootstrap else {}
    summary = {"seed": {**seed.summary(), "rmse_cv_deg": math.degrees(cv[seed.id])},
               "extended": {**chosen.summary(), "rmse_cv_deg": math.degrees(cv[chosen.id]), **boot},
               "cause": causes[0] if causes else "none",
               "causes": causes, "gain": 1.0 - chosen.rmse_test / seed.rmse_test, "candidates": candidates,
               "noise_deg": math.degrees(noise), "structure_ratio": ratio, "n_train": n_train,
               "n_test": len(range(*test.indices(n))), "penalty_per_parameter": PENALTY,
               "samples": {"fit": [train.start or 0, train.stop],
                           "choice": f"time-blocked cross-validation inside the fit block: {CV_BLOCKS} contiguous "
                                     "blocks, the even ones fitted and the odd ones scored, and the reverse",
                           "test": [test.start, test.stop],
                           "test_use": "once, for the chosen model's reported figure (and the seed's)"
                                       + ("; after the choice, for that figure's bootstrap refits" if n_bootstrap
                                          else "")},
               "literature": {e: PAIR_EFFECTS[e].literature for e in accepted},
               "tension_check": None if tension_ratio is None else {
                   "ratio": tension_ratio, "fit_weight_rad_per_N": TENSION_FIT_WEIGHT,
                   "rule": "a capstan-structure candidate whose predicted peak proximal tension of either tendon on "
                           "the training block is outside 1/ratio-ratio x the measured peak is refused; a refused "
                           "capstan structure is refitted with the measured tensions in the residual (id '/T')",
                   "inputs": "training block only: command, measured angle and measured proximal tensions"},
               "elapsed_s": _time.perf_counter() - t0}
    return summary, fits
