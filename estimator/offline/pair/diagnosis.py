"""What the seed pair model gets wrong on a recording of an antagonistic pair, why, and the gain.

The pair counterpart of :func:`estimator.offline.diagnosis.selection.diagnose` for recordings with a motor command,
the two proximal tensions and the distal angle only (the KAIST flexible endoscope,
docs/results/kaist.md). The models and effects are in :mod:`estimator.offline.pair.models`. Held-out
discipline: model choice sees the training block only; the test block is touched once, for the
reported figure of the chosen model (and of the seed model it is compared with).

1. Every model is fitted on the whole training block (the first command cycle) with
   ``scipy.optimize.least_squares`` from a few starting points (relative tolerances FIT_TOL), and
   always runs from the first sample, so the test block (the later cycles) starts from the state the
   training left. The models are causal, so a fit runs them only up to its last fitted sample
   (:func:`estimator.offline.pair.models.head`; the same predictions there, bit for bit).
2. Choice by time-blocked cross-validation inside the training block: the block is cut into
   CV_BLOCKS (8) contiguous time blocks, the even ones form fold 1 and the odd ones fold 2; the
   model is refitted on each fold (warm start from step 1, at most CV_NFEV evaluations, the model
   still running from the first sample) and scored on the other; cv rmse = root of the mean of the
   two squared fold errors. (Halves, one reversal each, made the refits wander: an extrapolation
   to the other reversal rather than a check of the fit.)
   Score S = (cv rmse / cv rmse of the seed)^2.
3. Forward selection with a price per parameter: starting from the seed, the candidate with the
   lowest S / S_chosen + PENALTY (n_params - n_params_chosen) is accepted when that is below 1
   (PENALTY: the single-tendon diagnosis's price, :data:`estimator.offline.diagnosis.thresholds.PENALTY`); the first
   round offers the capstan structure (``capstan_joint``) and the seed with each effect, later
   rounds every effect that applies to the model chosen so far; at most ``max_effects`` are
   accepted, and the search stops once the chosen model's cv rmse is within STRUCTURE_RATIO
   times the tracker noise. A candidate whose *training* rmse ratio alone already prices it out
   ((rmse_train / rmse_train,chosen)^2 + PENALTY x extra parameters >= 1 + SCREEN_MARGIN) is not
   cross-validated (listed as ``screened_out``), which saves most of the refits.
3b. Tension plausibility (``tension_ratio``, default
   :data:`TENSION_PEAK_RATIO`): the proximal tensions are measured on the training block too, and a
   capstan-structure model predicts them. A candidate whose predicted peak proximal tension of either
   tendon over the training block is more than ``tension_ratio`` times, or less than 1 / ``tension_ratio``
   times, the measured peak is refused (listed with ``refused``, not cross-validated, never accepted):
   its angle fit has run along a valley of the parameters (G against lam) that the angle of one cycle
   does not close. When the capstan structure itself is refused in the first round, it is refitted with
   the measured proximal tensions in the residual (weight :data:`TENSION_FIT_WEIGHT`, the shared
   models' ``+T`` weight; id ``capstan/T``) and that fit, checked the same way, is the structure's
   candidate; effects added later to a ``/T`` model are fitted the same way. Models are still scored
   by the angle's cross-validation only. ``tension_ratio=None`` turns the check off.
4. ``unknown`` is appended when the chosen model's cv rmse is still above STRUCTURE_RATIO (3) times
   the tracker noise (robust level of the angle's second differences): structure left that no
   candidate explains. ``none`` when nothing is accepted and no structure is left.
"""
from __future__ import annotations

import math
import time as _time
from collections.abc import Callable

import numpy as np

from estimator.data import noise_level
from estimator.offline.pair.diagnosis_fit import (CAPSTAN_STARTS, CV_BLOCKS, SCREEN_MARGIN, TENSION_FIT_WEIGHT,
                                                  TENSION_PEAK_RATIO, FitResult, cross_validate, figure_bootstrap,
                                                  fit_model)
from estimator.offline.diagnosis.thresholds import PENALTY, STRUCTURE_RATIO
from estimator.offline.pair.fit import fit_pair
from estimator.offline.pair.models import CAUSE_OF_SEED, PAIR_EFFECTS, applicable

__all__ = ["diagnose_pair"]


def diagnose_pair(rec, train: slice, test: slice, *, max_effects: int = 2,
                  progress: Callable[[str], None] | None = None,
                  n_bootstrap: int = 0,
                  tension_ratio: float | None = TENSION_PEAK_RATIO) -> tuple[dict, dict[str, FitResult]]:
    """Diagnose one pair recording: the seed model's error, the effects that explain it, the gain.

    Parameters
    ----------
    rec : recording with time [s], command [rad], T_a, T_b [N], angle [rad], arrays of shape (n,)
    train, test : sample slices (KAIST: command cycle 1 and the later cycles, :func:`recorded.kaist.split`);
        the choice uses ``train`` only (module docstring), ``test`` gives the reported figures
    max_effects : most effects accepted (the capstan structure counts as one), >= 1
    progress : called with a label after every fitted model
    n_bootstrap : draws of the chosen model's test-figure uncertainty (:func:`figure_bootstrap`; 0: none);
        computed after the choice, which it does not affect
    tension_ratio : factor > 1 of the tension plausibility check (module docstring, step 3b; default
        :data:`TENSION_PEAK_RATIO`), or None: no check and no ``/T`` refit

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
    n_train = _check_pair(rec, train, max_effects, tension_ratio)
    search = _Search(rec, train, test, tension_ratio, progress or (lambda label: None))
    sp = fit_pair(rec.command, rec.T_a, rec.T_b, rec.angle, train.stop).params
    seed = fit_model("seed", (), rec, train, test, [sp])
    search.cv[seed.id] = cross_validate(seed, rec, train)
    search.tick("seed")
    search.fits[seed.id] = seed
    chosen, accepted = seed, []
    noise = noise_level(np.asarray(rec.angle, dtype=float))
    for rnd in range(1, max_effects + 1):
        if search.cv[chosen.id] <= STRUCTURE_RATIO * noise:
            break                       # nothing left above the noise for another effect to explain
        trial = search.trials(chosen, rnd)
        price = search.prices(trial, chosen, seed, rnd)
        if not price:
            break
        best = min(price, key=lambda e: price[e])
        if price[best] >= 1.0:
            break
        chosen = trial[best][1]
        accepted.append(best)
        search.candidates[chosen.id]["accepted"] = True
    ratio = search.cv[chosen.id] / max(noise, 1e-12)
    causes = accepted + (["unknown"] if ratio > STRUCTURE_RATIO else [])
    # the chosen model's test-figure uncertainty: after the choice, which it does not affect
    boot = {"rmse_test_bootstrap": figure_bootstrap(chosen, rec, train, test, n_bootstrap)} if n_bootstrap else {}
    cv = search.cv
    summary = {"seed": {**seed.summary(), "rmse_cv_deg": math.degrees(cv[seed.id])},
               "extended": {**chosen.summary(), "rmse_cv_deg": math.degrees(cv[chosen.id]), **boot},
               "cause": causes[0] if causes else "none",
               "causes": causes, "gain": 1.0 - chosen.rmse_test / seed.rmse_test, "candidates": search.candidates,
               "noise_deg": math.degrees(noise), "structure_ratio": ratio, "n_train": n_train,
               "n_test": len(range(*test.indices(len(rec.angle)))), "penalty_per_parameter": PENALTY,
               **_pair_notes(train, test, n_bootstrap, accepted, tension_ratio),
               "elapsed_s": _time.perf_counter() - t0}
    return summary, search.fits


def _check_pair(rec, train: slice, max_effects: int, tension_ratio: float | None) -> int:
    """The arguments of :func:`diagnose_pair` checked (its Raises); returns the training block's length."""
    if max_effects < 1:
        raise ValueError(f"max_effects must be >= 1, got {max_effects!r}")
    if tension_ratio is not None and not (math.isfinite(tension_ratio) and tension_ratio > 1.0):
        raise ValueError(f"tension_ratio must be None or a finite number > 1, got {tension_ratio!r}")
    n_train = len(range(*train.indices(len(rec.angle))))
    if n_train < 16:
        raise ValueError(f"the training block has {n_train} samples, need at least 16")
    return n_train


class _Search:
    """The forward selection's fits (``fits``), cross-validated errors (``cv`` [rad]) and candidate entries."""

    def __init__(self, rec, train: slice, test: slice, tension_ratio: float | None, tick: Callable[[str], None]):
        self.rec, self.train, self.test, self.ratio, self.tick = rec, train, test, tension_ratio, tick
        self.fits: dict[str, FitResult] = {}
        self.cv: dict[str, float] = {}
        self.candidates: dict[str, dict] = {}
        self.refusal = (None if tension_ratio is None else f"predicted peak proximal tension outside "
                        f"1/{tension_ratio:g}-{tension_ratio:g} x the measured one on the training block")

    def fit(self, structure: str, effects: tuple[str, ...], starts: list[dict], **kw) -> FitResult:
        fx = fit_model(structure, effects, self.rec, self.train, self.test, starts, **kw)
        self.tick(fx.id)
        return fx

    def entry(self, fx: FitResult, eid: str, rnd: int) -> dict:
        """A candidate's JSON entry before cross-validation (rmse_cv_deg, score and price None)."""
        return {"effect": eid, "round": rnd, "rmse_cv_deg": None, "rmse_train_deg": math.degrees(fx.rmse_train),
                "score": None, "price": None, "accepted": False, "params": {k: float(v) for k, v in fx.values.items()},
                "tension_peak_ratio": fx.tension_peak_ratio(self.rec, self.train)}

    def implausible(self, ratio: list[float] | None) -> bool:
        """Whether the tension check (step 3b) refuses a candidate with these peak ratios."""
        return (self.ratio is not None and ratio is not None
                and any(not (1.0 / self.ratio <= x <= self.ratio) for x in ratio))

    def trials(self, chosen: FitResult, rnd: int) -> dict[str, tuple[str, FitResult]]:
        """The round's candidates: the capstan structure (refitted with the measured tensions when the check
        refuses it) while the seed is chosen, and the chosen model with each effect that applies."""
        trial: dict[str, tuple[str, FitResult]] = {}
        if chosen.structure == "seed":
            carried = {p.name: chosen.values[p.name] for e in chosen.effects for p in PAIR_EFFECTS[e].parameters}
            starts = [{**s, **carried} for s in CAPSTAN_STARTS]
            fx = self.fit("capstan", chosen.effects, starts)
            e = self.entry(fx, CAUSE_OF_SEED, rnd)
            if self.implausible(e["tension_peak_ratio"]):    # step 3b: refitted with the measured tensions
                self.fits[fx.id] = fx
                self.candidates[fx.id] = {**e, "refused": self.refusal}
                fx = self.fit("capstan", chosen.effects, starts, tension_weight=TENSION_FIT_WEIGHT)
            trial[CAUSE_OF_SEED] = ("capstan", fx)
        for eid in applicable(chosen.structure, chosen.effects):
            trial[eid] = (chosen.structure, self.fit(chosen.structure, chosen.effects + (eid,),
                                                     [dict(chosen.values)], tension_weight=chosen.tension_weight))
        return trial

    def prices(self, trial: dict[str, tuple[str, FitResult]], chosen: FitResult, seed: FitResult,
               rnd: int) -> dict[str, float]:
        """Each plausible candidate's price S / S_chosen + PENALTY x extra parameters, cross-validated unless its
        training error alone prices it out."""
        price: dict[str, float] = {}
        cv = self.cv
        for eid, (_, fx) in trial.items():
            self.fits[fx.id] = fx
            e = self.entry(fx, eid, rnd)
            if self.implausible(e["tension_peak_ratio"]):
                self.candidates[fx.id] = {**e, "refused": self.refusal}
                continue
            extra = PENALTY * (fx.n_params - chosen.n_params)
            if (fx.rmse_train / chosen.rmse_train) ** 2 + extra >= 1.0 + SCREEN_MARGIN:
                # priced out on its training error alone (a cv error is not below it): no cv refits
                self.candidates[fx.id] = {**e, "screened_out": "training error alone prices it out"}
                continue
            cv[fx.id] = cross_validate(fx, self.rec, self.train)
            S = (cv[fx.id] / cv[seed.id]) ** 2
            price[eid] = S / (cv[chosen.id] / cv[seed.id]) ** 2 + extra
            self.candidates[fx.id] = {**e, "rmse_cv_deg": math.degrees(cv[fx.id]), "score": S, "price": price[eid]}
        return price


def _pair_notes(train: slice, test: slice, n_bootstrap: int, accepted: list[str],
                tension_ratio: float | None) -> dict:
    """The summary's ``samples``, ``literature`` and ``tension_check`` entries (what was used for what)."""
    return {"samples": {"fit": [train.start or 0, train.stop],
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
                "inputs": "training block only: command, measured angle and measured proximal tensions"}}
