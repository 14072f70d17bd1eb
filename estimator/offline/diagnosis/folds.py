"""The fitted models of the diagnosis: the time-blocked folds, one model fitted on them, and its scores.

:class:`Folds` holds the training block and its two folds (forward and backward in time); :class:`Fit` fits one
model (the base, or the base with extensions) on each fold's fit block and scores it on the validation block
against the base (:func:`score`, the worse fold counts); :func:`structure` says how far a model's validation error
is above the noise floor. The procedure that uses them is :func:`estimator.offline.diagnosis.selection.diagnose`.
"""
from __future__ import annotations

import math

import numpy as np

from estimator.offline.diagnosis import thresholds as th
from estimator.offline.diagnosis.fit import SIGNALS, fit_model, paired_trimmed_ms, settings_keys, trimmed_ms
from estimator.offline.diagnosis.instant import PROFILE_MARGIN
from estimator.offline.diagnosis.readings import holds_release
from estimator.offline.effects.catalogue import Effect, below_resolution, predict
from estimator.offline.effects.types import ROUTE_FORMS, ROUTE_KEYS, ROUTE_TWELFTHS

__all__ = ["Folds", "Fit", "judging_folds", "sole_fold", "step_fold", "score", "structure", "unresolved",
           "tension_offsets",
           "route_of", "gain", "parameters_table", "FINER", "FORM_NAME", "UNITS"]

#: the unit of each distal signal in the JSON keys
UNITS = {"T_out": "N", "x_out": "m"}


def tension_offsets(values: dict) -> dict[str, float]:
    """The tension offsets [N] of a fitted model (see OFFSET_FLOORS) by effect id."""
    return {"friction_offset": values.get("a", 0.0) * (1.0 - math.exp(-values.get("K", 0.0))),
            "sensor_offset:T_in": abs(values.get("b_T_in", 0.0)),
            "sensor_offset:T_out": abs(values.get("b_T_out", 0.0))}


def unresolved(effects: list[Effect], values: dict, floor: dict[str, float], dominant: bool = False) -> bool:
    """An effect fitted at a magnitude the recording cannot resolve: at its smallest showable value
    (:func:`estimator.offline.effects.catalogue.below_resolution`), or a tension offset (friction offset at the tip,
    load-cell offset) [N] below OFFSET_FLOORS x the T_out floor [N] (when T_out is recorded) - unless ``dominant``:
    the base leaves structure above STRUCTURE_RATIO and the effect removes nearly all of it (S < DOMINANT_SCORE), so
    its size is read from a pattern over many samples, not from one sample's noise."""
    if below_resolution(effects, values):
        return True
    if "T_out" in floor and not dominant:
        size = tension_offsets(values)
        return any(e.id in size and size[e.id] < th.OFFSET_FLOORS * floor["T_out"] for e in effects)
    return False


class Folds:
    """The training block [0, kt) of a prepared series and its two time-blocked folds: forward (fit
    on [0, kv), validate on [kv, kt)) and backward (fit on [kb, kt), validate on [0, kb)). The model
    always runs from the first sample; a fold only chooses which residuals count."""

    def __init__(self, s, kb: int, kv: int, kt: int):
        self.s, self.train, self.kt = s, s.slice(kt), kt
        self.fit = (slice(0, kv), slice(kb, kt))
        self.val = (slice(kv, kt), slice(0, kb))
        self.judged: tuple[int, ...] = judging_folds(s, self.fit)


def judging_folds(s, fit: tuple[slice, slice]) -> tuple[int, ...]:
    """The folds whose validation judges (structure and scores): both, unless one fit block holds a release of the
    proximal tension (:func:`estimator.offline.diagnosis.readings.holds_release`) and the other does not.

    Where the friction sits along the sheath shows only while a slip front crosses the sheath after a reversal: a
    fold fitted on one monotonic pull cannot know the route's shape, and its validation block then shows the base's
    extrapolation, not a missing effect."""
    held = [holds_release(s.T_in[f]) for f in fit]
    return (held.index(True),) if sum(held) == 1 else (0, 1)


def sole_fold(effects: list[Effect], folds: Folds, base: Fit | None, floor: dict[str, float]) -> int | None:
    """The one fold whose score counts for a model of ``effects`` (0 forward, 1 backward), or None: the worse of both.

    * Only one fold judges the recording (:func:`judging_folds`): that one.
    * An effect that acts through the starting state only (``Effect.initial_state``: a pretension whose profile the
      first full slide erases) cannot show on the forward fold's validation block, which lies after the start;
      where the base already fits that block to its floor, the backward fold (validated on the start) decides.
    * Mirrored, an effect that is zero at the start and grows with time (``Effect.from_start``: a load cell drifting
      from its zero) shows least on the backward fold's validation block, the start, while that fold's fit block
      absorbs part of it into the base: where the base is at its floor (both folds together and the backward one),
      the forward fold decides. Not above the floor: there a drift fitted forward also bends to a gain whose error
      grows with the protocol's tension.
    """
    def at_floor(fold: int | None) -> bool:
        return (bool(floor) and base is not None
                and max(structure(base, floor, fold=fold).values()) < th.STRUCTURE_RATIO)
    one_kind = base is not None and bool(effects)
    if base is not None and len(folds.judged) == 1:
        return folds.judged[0]
    if one_kind and all(e.initial_state for e in effects) and at_floor(0):
        return 1
    if one_kind and all(e.from_start for e in effects) and at_floor(None) and at_floor(1):
        return 0
    return None


def step_fold(folds: Folds, instants: list[float], fold_S: list[float] | None = None) -> int | None:
    """The one fold that judges a model with a step at an instant (``Parameter.discrete``; fitted per fold, [s] from
    the first sample), or None: both.

    A step shows only to a fold whose fit block holds both sides of it: one the forward fold's fit block ends before
    (the backward fold's instant after it) shows on the backward fold alone, one before the backward fold's fit block
    on the forward fold alone; the other fold saw one level only and its validation block shows the base's
    extrapolation, not the step. When both hold (one fold fitted the step, the other a step of nothing where the
    first cannot look), the fold whose step explains more of its validation block (the lower of ``fold_S``, the
    folds' scores) judges."""
    if len(instants) < 2:
        return None
    t = folds.train.time
    fwd_end = float(t[folds.fit[0].stop - 1] - t[0])
    back_start = float(t[folds.fit[1].start] - t[0])
    late, early = instants[1] > fwd_end - PROFILE_MARGIN, instants[0] < back_start + PROFILE_MARGIN
    if late and early and fold_S is not None and len(fold_S) == 2:
        return int(np.argmin(fold_S))
    if late:
        return 1
    if early:
        return 0
    return None


class Fit:
    """One model (a list of extensions) fitted on each fold's fit block, with its validation errors.

    The forward fold is refined from the ``refined`` least costly of ``starts``
    (:func:`estimator.offline.diagnosis.fit.fit_model` ranks them by their cost), the backward fold from the forward
    fold's values, both to the model choice's tolerance (``thresholds.CHOICE_TOL``)."""

    def __init__(self, effects: list[Effect], folds: Folds, starts: list[dict], *, route: bool | str = False,
                 fixed: dict | list[dict] | None = None, base: Fit | None = None,
                 floor: dict[str, float] | None = None, need: float = math.inf, refined: int = 2):
        self.effects = effects
        self.values: list[dict[str, float]] = []
        self.compliance: list[float] = []
        self.mse: list[dict[str, float]] = []
        self.residuals: list[dict[str, np.ndarray]] = []     # validation residuals per fold and signal
        # per fold: (this model's, the base's) mean squares on the samples kept for both (paired trim)
        self.pairs: list[tuple[dict[str, float], dict[str, float]]] = []
        floor = floor or {}
        tr = folds.train
        self.judged = folds.judged
        self.sole_fold = sole_fold(effects, folds, base, floor)
        instant = next((p.name for e in effects for p in e.parameters if p.discrete), None)
        for j, (fm, vm) in enumerate(zip(folds.fit, folds.val, strict=False)):
            if (j == 1 and base is not None and self.sole_fold is None and instant is None
                    and score(*self.pairs[0], floor) >= need):
                break           # cannot be accepted (the worse fold counts): the second fold is not needed
            vals, c, _ = fit_model(effects, tr, starts if j == 0 else [self.values[0]], route=route,
                                   fixed=fixed[j] if isinstance(fixed, list) else fixed, mask=fm,
                                   max_starts=refined if j == 0 else 1, tol=th.CHOICE_TOL)
            pred = predict(effects, vals, tr, compliance=c)
            self.values.append(vals)
            self.compliance.append(c)
            res = {n: getattr(pred, n)[vm] - getattr(tr, n)[vm] for n in SIGNALS if getattr(tr, n) is not None}
            self.residuals.append(res)
            self.mse.append({n: trimmed_ms(r, th.TRIM) for n, r in res.items()})
            if base is not None:
                pair = {n: paired_trimmed_ms(r, base.residuals[j][n], th.TRIM) for n, r in res.items()}
                self.pairs.append(({n: v[0] for n, v in pair.items()}, {n: v[1] for n, v in pair.items()}))
        # the worse fold counts: an extension must help forward and backward in time; each fold compares the
        # two models on the same samples (the transients neither explains left out: paired_trimmed_ms)
        self.fold_S = [score(m, bm, floor) for m, bm in self.pairs]     # forward, backward (when computed)
        if instant is not None and self.sole_fold is None and base is not None:
            self.sole_fold = step_fold(folds, [v[instant] for v in self.values], self.fold_S)
            if self.sole_fold is not None:      # the other fold saw one level only: it judges no structure either
                self.judged = (self.sole_fold,)
        scored = self.fold_S if self.sole_fold is None else self.fold_S[self.sole_fold:self.sole_fold + 1]
        self.S = 1.0 if base is None else max(scored)
        self.complete = len(self.mse) == len(folds.fit)

    @property
    def n_params(self) -> int:
        return sum(len(e.parameters) for e in self.effects)

    @property
    def ids(self) -> list[str]:
        return [e.id for e in self.effects]

    def val_mse(self) -> dict[str, float]:
        """Mean over the judged folds (``Folds.judged``; those computed) of the validation mean square error per
        signal."""
        use = [self.mse[j] for j in self.judged if j < len(self.mse)] or self.mse
        return {n: float(np.mean([m[n] for m in use])) for n in use[0]}


#: the route forms finer than each (the ``route`` argument of the fits: True is the thirds)
FINER: dict = {True: ("fine", "twelfths"), "fine": ("twelfths",), "twelfths": ()}
#: their names in the JSON (``settings.route_form``, ``settings.model_route_form``)
FORM_NAME: dict = {False: "held", True: "thirds", "fine": "sixths", "twelfths": "twelfths"}


def route_of(values: dict, route: bool | str) -> bool | str:
    """The route form a model's values were fitted on (False when the route is held): by its shares' count."""
    n = sum(k in values for k in ROUTE_KEYS)
    if not route:
        return False
    return "twelfths" if n == len(ROUTE_TWELFTHS) else "fine" if n == len(ROUTE_FORMS["fine"]) else True


def score(mse: dict, base: dict, floor: dict[str, float]) -> float:
    """Validation score relative to the base: sum over signals of (rmse / floor)^2, extension over base.

    Each signal counts by how far above its noise floor it is, so a signal the extension does not
    touch (T_out for tendon stiffening) does not dilute what it explains in the other."""
    num = den = 0.0
    for key, f in floor.items():
        if key in mse and base.get(key) and f > 0:
            num += mse[key] / f ** 2
            den += base[key] / f ** 2
    return num / den if den > 0 else 1.0


def structure(fit: Fit, noise: dict[str, float], fold: int | None = None) -> dict[str, float]:
    """Validation rmse / noise floor per signal on the averaged series [-] (mean over the folds, or of fold
    ``fold`` alone)."""
    mse = fit.val_mse() if fold is None else fit.mse[fold]
    return {n: math.sqrt(v) / max(noise[n], 1e-300) for n, v in mse.items()}


def gain(ext: dict, base: dict, signal: str) -> float | None:
    """1 - rmse_ext / rmse_base [-] on ``signal`` of two ``raw_rmse`` dicts; None when either is missing or the
    base's is 0."""
    b, e = base.get(f"rmse_{signal}_{UNITS[signal]}"), ext.get(f"rmse_{signal}_{UNITS[signal]}")
    return None if b is None or e is None or b <= 0 else 1.0 - e / b


def parameters_table(effects: list[Effect], values: dict, compliance: float, rename: dict) -> dict:
    """name -> {value, unit, effect} of a fitted model: K, L/EA [m/N], the route shares, every effect's parameters
    (renamed and converted by ``rename``: id -> (id,), parameter -> (name, conversion)) and its held settings."""
    out = {"K": {"value": values["K"], "unit": "-", "effect": "base"},
           "compliance": {"value": compliance, "unit": "m/N", "effect": "base"}}
    for name in ROUTE_KEYS:
        if name in values:
            out[name] = {"value": values[name], "unit": "-", "effect": "base"}
    for e in effects:
        for p in e.parameters:
            name, conv = rename.get(p.name, (p.name, float))
            out[name] = {"value": conv(values[p.name]), "unit": p.unit, "effect": rename.get(e.id, (e.id,))[0]}
        for k in settings_keys([e]):        # the form the fit kept (held, not fitted)
            if k in values:
                out[k] = {"value": values[k], "unit": "-", "effect": e.id}
    return out

