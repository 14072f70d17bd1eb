"""What the base model gets wrong on a recording, which physical effect explains it, and the gain.

:func:`diagnose_recording` is the procedure, step by step (docs/concepts/diagnosis.md explains each):

1. split the recording in time at a rest into a training block and a test block, and the training block into two
   time-blocked folds (fit on the first 65 %, validate on the rest; fit on the last 65 %, validate on the first
   35 %; the model always runs from the first sample);
2. the noise floor of each distal signal, from the recording itself;
3. the base model (profile memory with K, L/EA and the route shares) fitted on each fold, on a finer route when
   the coarse one leaves structure;
4. every extension of the catalogue (:mod:`estimator.offline.effects.catalogue`) the recording can show, fitted alone
   (one a linearised screen at the base prices out when a step needs it: :mod:`estimator.offline.diagnosis.singles`);
5. its score S against the base on the validation blocks (the worse fold counts),

       S = sum_signals (rms_ext / floor)^2 / sum_signals (rms_base / floor)^2;

6. selection by a price per parameter, with the rules at the floor, pairs of the strongest candidates where one
   leaves structure (:mod:`estimator.offline.diagnosis.pairs`), and the model-free readings (stick-slip, the
   encoder reading at the initial rest);
7. the chosen and the base model refitted on the whole training block;
8. the test block, used once, for the reported errors and the gain.

The rules are in :mod:`estimator.offline.diagnosis.rules`, the numbers in
:mod:`estimator.offline.diagnosis.thresholds`, the fitted models in :mod:`estimator.offline.diagnosis.folds`, the
result in :mod:`estimator.offline.diagnosis.result`.
"""
from __future__ import annotations

import math
import time as _time
from dataclasses import replace
from collections.abc import Callable

import numpy as np

from estimator.data import MeasuredData, noise_level
from estimator.offline.diagnosis import thresholds as th
from estimator.offline.diagnosis.fit import SIGNALS, Progress, fit_model, prepare, raw_rmse, split_at_rest
from estimator.offline.diagnosis.folds import (FORM_NAME, UNITS, Fit, Folds, gain, parameters_table, route_of,
                                               structure)
from estimator.offline.diagnosis.pairs import (
    consider_pairs,
    offset_beside_physical,
    second_at_floor,
    speed_beside_offset,
)
from estimator.offline.diagnosis.readings import (distal_at_end, distal_end_held, rest_offset, rest_reading,
                                                  sample_block, stick_slip_ratio)
from estimator.offline.diagnosis.result import Candidate, Diagnosis, Model, RestOffset, StickSlip
from estimator.offline.diagnosis.rules import (Context, candidate_effects, noise_floors, refine_route,
                                               refit_routes, rest_rule, report_channels, select, stick_slip_rule,
                                               verdict, worst)
from estimator.offline.diagnosis.singles import Singles
from estimator.offline.effects.catalogue import CATALOGUE, EQUIVALENT, NOISE_BAND, Effect, effect, predict
from estimator.offline.effects.types import NONE, UNKNOWN, Series

__all__ = ["diagnose", "diagnose_recording"]

#: the base model's starts of K [-]
BASE_STARTS = (0.2, 0.6, 1.2)

#: [samples] the most samples of the averaged series that the model choice (steps 2-6) runs on: a longer recording
#: is averaged further for it, to target_rate x SELECTION_SAMPLES / its samples but not below SELECTION_RATE_MIN;
#: the chosen and the base model are then refitted and tested at ``target_rate`` (steps 7-8). A run-time bound (the
#: choice's cost grows with the samples, what it reads does not), not tuned: every pinned and benchmark recording of
#: up to two minutes at 200 Hz is below it.
SELECTION_SAMPLES = 24000
#: [Hz] the lowest averaging rate of the model choice: blocks of at most 10 ms, the shortest sensor delay the
#: catalogue names (a delay within one block shows as a blur, and velocity friction's rise with speed then reads as
#: a delay of the distal load cell)
SELECTION_RATE_MIN = 100.0


def diagnose(data: MeasuredData, *, train_fraction: float = 0.6, progress: bool | Callable = False,
             effects: tuple[str, ...] | None = None, max_effects: int = 2, n_nodes: int = 32,
             target_rate: float = 200.0, wrap_shape: np.ndarray | None = None,
             recorded: tuple[str, ...] | None = None) -> dict:
    """Diagnose one recording: base model error, the effect that explains it, the held-out gain.

    Parameters
    ----------
    data : MeasuredData
        time [s], x_in [m], T_in [N] and at least one of T_out [N], x_out [m]; positions zeroed at a
        rest of the unloaded tendon (or at the preloaded rest: that is the pretension effect). An x_out
        that never moves (:func:`estimator.offline.diagnosis.readings.distal_end_held`: the distal end held by a
        stop or a load never lifted) is set aside when T_out is recorded: ``settings.distal_end_held``; one
        that barely moves (NEAR_HELD_SHARE of x_in's travel: pressed on a stop) is set aside when the diagnosis
        with it leaves "unknown" and the one without it does not (``distal_end_held.pressed`` True). One that
        sits at an end of its range for most of the proximal travel (a joint held on its stop) cannot show a lag of
        its own: ``settings.distal_at_end`` (:func:`estimator.offline.diagnosis.readings.distal_at_end`) gives the share
        and the effects it hides; the answer is not changed.
    train_fraction : float in [0.3, 0.9]
        Nominal share of the duration used for training (fit + validation); the split moves to a
        rest within 8 %. The test block after it is used once, for the reported errors and gain.
    progress : bool or callable(done, total, label)
        A stderr progress bar (drawn on a terminal only: nothing when stderr is a file or a pipe), or a callback
        per fitted model.
    effects : tuple of ids, optional
        Candidate extensions (default: the whole catalogue).
    max_effects : int
        Most extensions accepted together, >= 1.
    n_nodes, target_rate, wrap_shape
        Profile elements, averaging rate [Hz] (of the models refitted and tested; the model choice of a recording
        longer than SELECTION_SAMPLES at it runs at a lower rate, not below SELECTION_RATE_MIN) and route shape, see
        :func:`estimator.offline.diagnosis.fit.prepare`;
        with ``wrap_shape`` given the route is held, without it the route shares are fitted.
    recorded : tuple of "T_out", "x_out", optional
        The distal channels the recording was made with (default: those of ``data``; a channel set aside before
        the call may be named). With one of them only, the floor bounds of clean recordings made that way apply too
        (FLOOR_SCORE_WITHOUT, EXCESS_MIN_WITHOUT); a channel set aside by the diagnosis itself (a held distal end)
        does not count as missing.

    Returns
    -------
    dict, JSON-ready:
        ``cause`` one id (an effect, "none" or "unknown"); ``causes`` accepted ids in order (plus
        "unknown" when structure is left); ``equivalent`` ids that explain the data identically;
        ``base``, ``extended`` {rmse_T_out_N, rmse_x_out_m} on the test block (measured samples,
        None for a signal not recorded); ``gain`` 1 - extended/base on ``primary_signal``;
        ``parameters`` name -> {value, unit, effect} of the chosen model refitted on the training
        block; ``candidates`` id -> {validation rmse, score, penalised_score, accepted, parameters}
        (fit block only); ``split`` {fit, validation, test: {index [start, stop) of the measured
        samples, time_s [first, last], n_samples}, time_s, n_train, n_heldout, train_fraction};
        ``noise``, ``structure`` (validation rmse / floor: base, extended), ``stick_slip`` {ratio
        (:func:`estimator.offline.diagnosis.readings.stick_slip_ratio` on the training block, None when unreadable),
        named (stiction named by it: the models named nothing and ratio >= STICK_SLIP_RATIO, or ratio >=
        STICK_SLIP_WEAK with stiction's score below STICK_SLIP_WEAK_SCORE, or the models named effects that leave
        structure above STRUCTURE_RATIO and ratio >= STICK_SLIP_RATIO), weak (named by the second rule), overruled
        (the ids the models named that the third rule set aside), samples},
        ``rest_offset`` {reads (the offset id whose encoder reads away from zero at the initial rest,
        :func:`estimator.offline.diagnosis.readings.rest_offset`, or None), named (named by that reading: the models
        named nothing), x_in_m, x_out_m (|median| at the initial rest [m])}, ``model`` and
        ``base_model`` (refitted on the training block; enough to re-run both, see
        :func:`study.report.write_report`), ``settings`` (the arguments, the thresholds, ``selection_rate_hz`` the
        averaging rate of steps 2-6: ``target_rate`` or, beyond SELECTION_SAMPLES, lower; ``pair_rule`` the step of
        two causes at once whose model the answer names, e.g. ``"offset_beside_physical"``, or None), ``elapsed_s``.

    Raises
    ------
    DataError
        No distal signal. ValueError: too short a recording, a bad fraction, an unknown effect id or ``recorded``
        naming a channel that is not distal or leaving out one the data have.
    """
    return diagnose_recording(data, train_fraction=train_fraction, progress=progress, effects=effects,
                              max_effects=max_effects, n_nodes=n_nodes, target_rate=target_rate,
                              wrap_shape=wrap_shape, recorded=recorded).to_json()


def diagnose_recording(data: MeasuredData, *, train_fraction: float = 0.6, progress: bool | Callable = False,
                       effects: tuple[str, ...] | None = None, max_effects: int = 2, n_nodes: int = 32,
                       target_rate: float = 200.0, wrap_shape: np.ndarray | None = None,
                       recorded: tuple[str, ...] | None = None) -> Diagnosis:
    """The diagnosis procedure of :func:`diagnose` step by step, returning the typed :class:`Diagnosis` (same
    arguments, the same errors; ``.to_json()`` is what :func:`diagnose` returns)."""
    t_start = _time.perf_counter()
    catalogue, channels, missing = _check_inputs(data, effects, max_effects, recorded)
    # 1. split: a distal end that never moved set aside, the training and test blocks, the two folds
    used, held, at_end, blocks, full = _split(data, train_fraction, n_nodes, target_rate, wrap_shape)
    signals = [n for n in SIGNALS if getattr(used, n) is not None]
    cands = candidate_effects(catalogue, signals)
    bar = _progress_bar(len(cands), wrap_shape is None, max_effects, progress)
    # 2-3. the base model on each fold, the noise floors it is judged against, its route refined
    base = Fit([], blocks.folds, [{"K": K0} for K0 in BASE_STARTS], route=wrap_shape is None)
    bar("base model")
    ctx = Context(blocks.s, blocks.folds, signals, noise_floors(blocks.s, used, base, signals), wrap_shape is None,
                  bar, th.FLOOR_SCORE_WITHOUT.get(missing, {}), th.EXCESS_MIN_WITHOUT.get(missing, th.EXCESS_MIN))
    alone: dict[str, Fit] = {}          # the finer routes fitted without an effect
    base = refine_route(ctx, base, alone)
    # the model-free readings: stick-slip on the training block, the encoders at the initial rest
    i_t = blocks.n_train(used)
    chatter = stick_slip_ratio(used.time[:i_t], used.x_in[:i_t], used.T_in[:i_t])
    off_zero = rest_offset(used)
    keep = ({"stiction"} if chatter is not None and chatter >= th.STICK_SLIP_WEAK else set()) \
        | ({off_zero, *EQUIVALENT.get(off_zero, ())} if off_zero else set())
    # 4-5. every candidate alone (those screened at the base on demand), scored against the base; route refits where
    # what the base lacks bent its route
    singles = Singles.screen(ctx, base, cands, keep)
    refit_routes(ctx, singles, base, alone)
    # 6. selection (on every candidate where the model chosen leaves structure), the steps of two causes, the readings
    chosen = select(ctx, base, singles, max_effects, used)
    if singles.screened and min(worst(chosen, ctx.floor), worst(base, ctx.floor)) > th.STRUCTURE_RATIO:
        singles.complete()
        chosen = select(ctx, base, singles, max_effects, used)
    pair_rule = None
    if max_effects >= 2:
        chosen, pair_rule = _two_causes(ctx, base, singles, chosen, used.slice(0, i_t))
    paired = chosen
    chosen, by_chatter, weak, overruled = stick_slip_rule(ctx, chosen, singles, chatter)
    chosen, by_rest = rest_rule(chosen, singles, off_zero)
    pair_rule = pair_rule if chosen is paired else None
    # 7-8. the base and the chosen model refitted on the training block, the test block used once
    final_base, final = _refit(ctx, base, chosen, full.slice(int(np.searchsorted(full.time, blocks.t_split))))
    ids, equivalent, rename = report_channels(chosen, used)
    left = structure(chosen, ctx.floor)
    causes = verdict(ids, left, chosen, by_chatter or by_rest)
    result = _result(ctx, full, used, blocks, base, chosen, singles, final_base, final, causes, equivalent, rename)
    result.stick_slip = StickSlip(chatter, by_chatter, weak, overruled, blocks.train_block(used))
    result.rest_offset = RestOffset(off_zero, by_rest, rest_reading(used, "x_in"),
                                    None if used.x_out is None else rest_reading(used, "x_out"))
    result.settings.update(_settings(ctx, train_fraction, n_nodes, target_rate, channels, final[0], held, at_end,
                                     wrap_shape))
    result.settings["pair_rule"] = pair_rule
    result.elapsed_s = _time.perf_counter() - t_start
    if held is None and used.T_out is not None and UNKNOWN in causes:
        return _without_pressed_distal_end(result, used, t_start, dict(
            train_fraction=train_fraction, effects=effects, max_effects=max_effects, n_nodes=n_nodes,
            target_rate=target_rate, wrap_shape=wrap_shape, recorded=recorded))
    return result


def _two_causes(ctx: Context, base: Fit, singles: Singles, chosen: Fit, train: MeasuredData
                ) -> tuple[Fit, str | None]:
    """The steps of two causes at once in turn (:mod:`estimator.offline.diagnosis.pairs`) on the model the forward
    selection chose; ``train``: the training block's samples. Returns the model kept and the name of the last step
    that changed it (None: none did)."""
    rule = None
    steps = (("consider_pairs", consider_pairs), ("offset_beside_physical", offset_beside_physical),
             ("second_at_floor", second_at_floor))
    for name, step in steps:
        kept = step(ctx, base, singles, chosen)
        if kept is not chosen:
            chosen, rule = kept, name
    kept = speed_beside_offset(ctx, base, singles, chosen, train)
    return (chosen, rule) if kept is chosen else (kept, "speed_beside_offset")


def _check_inputs(data: MeasuredData, effects: tuple[str, ...] | None, max_effects: int,
                  recorded: tuple[str, ...] | None) -> tuple[list[Effect], tuple[str, ...], str]:
    """The candidate effects, the distal channels the recording was made with, and the one it lacks ("" none)."""
    names = tuple(CATALOGUE) if effects is None else tuple(effects)
    try:
        catalogue = [effect(n) for n in names]
    except KeyError as err:
        raise ValueError(f"unknown effect: {err.args[0]}") from None
    if max_effects < 1:
        raise ValueError(f"max_effects must be >= 1, got {max_effects!r}")
    present = tuple(n for n in SIGNALS if getattr(data, n) is not None)
    if recorded is None:
        recorded = present
    elif not set(recorded) <= set(SIGNALS) or not set(present) <= set(recorded):
        raise ValueError(f"recorded must be distal channels {SIGNALS!r} including those of the data {present!r}, "
                         f"got {recorded!r}")
    return catalogue, recorded, next((n for n in SIGNALS if n not in recorded), "")


class _Blocks:
    """The prepared series ``s``, the index of its first test sample ``kt``, the folds, and the block edges in time
    [s]: ``t_split`` (training | test), ``t_val`` (forward fit | validation), ``t_back`` (backward validation | fit),
    each half a sample before the first sample of the later block."""

    def __init__(self, s, train_fraction: float):
        self.s = s
        kt = split_at_rest(s, train_fraction)
        kv = split_at_rest(s.slice(kt), 1.0 - th.VALIDATION_FRACTION)
        kb = split_at_rest(s.slice(kt), th.VALIDATION_FRACTION)
        self.folds = Folds(s, kb, kv, kt)
        half = 0.5 * (s.time[1] - s.time[0])
        self.t_split, self.t_val, self.t_back = (float(s.time[k] - half) for k in (kt, kv, kb))

    def n_train(self, data: MeasuredData) -> int:
        """The measured samples of the training block: [0, n_train)."""
        return int(np.searchsorted(data.time, self.t_split))

    def train_block(self, data: MeasuredData) -> dict:
        return sample_block(data, -math.inf, self.t_split)

    def to_json(self, data: MeasuredData, judged: tuple[int, ...]) -> dict:
        """The ``split`` object of the result."""
        n, i_t, t_split = len(data), self.n_train(data), self.t_split
        return {"folds": [{"fit": sample_block(data, -math.inf, self.t_val),
                           "validation": sample_block(data, self.t_val, t_split)},
                          {"fit": sample_block(data, self.t_back, t_split),
                           "validation": sample_block(data, -math.inf, self.t_back)}],
                "train": self.train_block(data), "test": sample_block(data, t_split, math.inf), "time_s": t_split,
                "n_train": i_t, "n_heldout": n - i_t, "heldout_s": float(data.time[-1] - data.time[min(i_t, n - 1)]),
                "train_fraction": float((t_split - data.time[0]) / max(data.duration, 1e-12)),
                "judged_folds": (["forward", "backward"] if len(judged) == 2 else
                                 [("forward", "backward")[judged[0]]
                                  + " alone (the other fold's fit block holds no release: it cannot know the route)"]),
                "selection": "model choice by two time-blocked folds inside the training block (fit on one "
                             "part, validate on the other, forward and backward in time; the worse fold "
                             "counts); the chosen and the base model refitted on the whole training block; "
                             "the test block used once, for the reported errors and gain"}


def _split(data: MeasuredData, train_fraction: float, n_nodes: int, target_rate: float,
           wrap_shape: np.ndarray | None) -> tuple[MeasuredData, dict | None, dict | None, _Blocks, Series]:
    """Step 1. A distal end that never moved (held by a stop, or a load never lifted) says nothing of the tendon:
    x_out is set aside when T_out is recorded. Then what share of the proximal travel x_out spends at an end of its
    range (what such a recording cannot show), the prepared series and its blocks. Returns (the data used, the held
    reading or None, the at-end reading or None, the blocks of the model choice, the series at ``target_rate``: the
    blocks' own unless it holds more than SELECTION_SAMPLES, when the choice runs on a further averaged one)."""
    held = distal_end_held(data) if data.T_out is not None else None
    if held is not None:
        data = replace(data, x_out=None)
    at_end = distal_at_end(data)
    full = prepare(data, n_nodes=n_nodes, target_rate=target_rate, wrap_shape=wrap_shape)
    rate = max(target_rate * SELECTION_SAMPLES / len(full), min(SELECTION_RATE_MIN, target_rate))
    s = full if len(full) <= SELECTION_SAMPLES or rate >= target_rate else prepare(
        data, n_nodes=n_nodes, target_rate=rate, wrap_shape=wrap_shape)
    return data, held, at_end, _Blocks(s, train_fraction), full


def _progress_bar(n_cands: int, route: bool, max_effects: int, progress: bool | Callable) -> Progress:
    """The bar over the fits: base, each candidate, the polished ones, the second round, the two refits."""
    n_second = min(th.SECOND_ROUND, max(n_cands - 1, 0)) * (max_effects - 1)
    return Progress(1 + n_cands + (th.POLISH if route else 0) + n_second + 2, progress)


def _refit(ctx: Context, base: Fit, chosen: Fit, train: Series) -> tuple[tuple[dict, float], tuple[dict, float]]:
    """Step 7: the base and the chosen model refitted on the whole training block ``train`` (at the full rate, from
    the model choice's values): ((values, L/EA) of each)."""
    vals, c, _ = fit_model([], train, [base.values[0]], route=ctx.route)
    final_base = (vals, c)
    ctx.bar("base model, training block")
    if chosen.effects:
        vals, c, _ = fit_model(chosen.effects, train, [chosen.values[0]], route=route_of(chosen.values[0], ctx.route))
    ctx.bar("chosen model, training block")
    ctx.bar.finish()
    return final_base, (vals, c)


def _candidate(f: Fit, accepted: bool) -> Candidate:
    """One candidate's entry of the result (its fold fits, not the test block)."""
    vm = f.val_mse()
    eid = f.ids[0]
    return Candidate({f"rmse_{n}_{UNITS[n]}": (math.sqrt(vm[n]) if n in vm else None) for n in SIGNALS}, f.S,
                     f.S + th.PENALTY * f.n_params, accepted, list(EQUIVALENT.get(eid, ())),
                     parameters_table(f.effects, f.values[0], f.compliance[0], {}),
                     [{p.name: float(v[p.name]) for e in f.effects for p in e.parameters if p.name in v}
                      for v in f.values],
                     [float(v) for v in f.fold_S],
                     ("both folds (the worse counts)" if f.sole_fold is None else
                      ("the forward fold", "the backward fold")[f.sole_fold]
                      + " alone (the other fold's base at its floor)"))


def _result(ctx: Context, s: Series, data: MeasuredData, blocks: _Blocks, base: Fit, chosen: Fit,
            singles: Singles, final_base: tuple[dict, float], final: tuple[dict, float], causes: list[str],
            equivalent: list[str], rename: dict) -> Diagnosis:
    """Step 8 and the result: both refitted models run once over the series ``s`` at the full rate, judged on the test
    block (measured samples), the gain on the chosen model's primary signal; the readings and settings are filled in
    by the caller."""
    t_split = blocks.t_split
    base_raw = raw_rmse(predict([], final_base[0], s, compliance=final_base[1]), s, data, t_split)
    ext_raw = raw_rmse(predict(chosen.effects, final[0], s, compliance=final[1]), s, data, t_split) \
        if chosen.effects else dict(base_raw)
    want = chosen.effects[0].primary if chosen.effects else "T_out"
    prim = want if want in ctx.signals else ctx.signals[0]
    sensor_raw = {n: noise_level(np.asarray(getattr(data, n), dtype=float)) for n in ctx.signals}
    return Diagnosis(
        cause=causes[0] if causes else NONE, causes=causes, equivalent=equivalent, base=base_raw, extended=ext_raw,
        gain=(gain(ext_raw, base_raw, prim) or 0.0) if chosen.effects else 0.0, primary_signal=prim,
        parameters=parameters_table(chosen.effects, final[0], final[1], rename),
        candidates={eid: _candidate(singles[eid], eid in chosen.ids) for eid in singles.effects if eid in singles},
        screened={eid: dict(v) for eid, v in singles.screened.items()},
        split=blocks.to_json(data, blocks.folds.judged),
        noise={**{f"{k}_{UNITS[k]}": v for k, v in sensor_raw.items()}, "T_in_N": s.sigma_T_in,
               **{f"floor_{k}_{UNITS[k]}": v for k, v in ctx.floor.items()}},
        structure={"base": structure(base, ctx.floor), "extended": structure(chosen, ctx.floor)},
        stick_slip=StickSlip(None, False, False, [], {}), rest_offset=RestOffset(None, False, 0.0, None),
        model=Model(chosen.ids, {**final[0]}, final[1]), base_model=Model([], final_base[0], final_base[1]),
        settings={}, elapsed_s=0.0)


def _settings(ctx: Context, train_fraction: float, n_nodes: int, target_rate: float, recorded: tuple[str, ...],
              model_values: dict, held: dict | None, at_end: dict | None, wrap_shape: np.ndarray | None) -> dict:
    """The ``settings`` object of the result: the arguments, every threshold applied, the route forms, the readings
    of the distal end, the averaging rate of the model choice (``ctx.s``)."""
    return {"train_fraction": train_fraction, "validation_fraction": th.VALIDATION_FRACTION,
            "n_nodes": n_nodes, "target_rate_hz": target_rate,
            "penalty_per_parameter": th.PENALTY, "structure_ratio": th.STRUCTURE_RATIO,
            "strong_score": th.STRONG_SCORE, "weak_structure": th.WEAK_STRUCTURE, "mid_score": th.MID_SCORE,
            "excess_min": th.EXCESS_MIN, "floor_score": dict(th.FLOOR_SCORE),
            "recorded": list(recorded), "floor_score_without": dict(ctx.subset_floor),
            "excess_min_applied": ctx.excess_min, "stick_slip_ratio": th.STICK_SLIP_RATIO,
            "stick_slip_weak": th.STICK_SLIP_WEAK, "stick_slip_weak_score": th.STICK_SLIP_WEAK_SCORE,
            "dominant_score": th.DOMINANT_SCORE, "offset_floors": th.OFFSET_FLOORS,
            "noise_band_sigmas": NOISE_BAND, "rank_factor": th.RANK_FACTOR, "screen_share": th.SCREEN_SHARE,
            "model_resolution": th.MODEL_RESOLUTION, "trim": th.TRIM, "route_score": th.ROUTE_SCORE,
            "route_form": FORM_NAME[ctx.route], "model_route_form": FORM_NAME[route_of(model_values, ctx.route)],
            "distal_end_held": held, "distal_at_end": at_end, "distal_slide_travel_m": ctx.s.slide_travel,
            "selection_rate_hz": float((len(ctx.s) - 1) / max(ctx.s.time[-1] - ctx.s.time[0], 1e-12)),
            "wrap_shape": None if wrap_shape is None else [float(v) for v in wrap_shape]}


def _without_pressed_distal_end(result: Diagnosis, data: MeasuredData, t_start: float, kwargs: dict) -> Diagnosis:
    """A distal end pressed on a stop: an x_out that barely moves (below NEAR_HELD_SHARE of x_in's travel) moves by
    the stop's deflection and the tendon's pre-sliding, which the base model reads as elongation. When the
    diagnosis with it leaves structure no effect explains ("unknown") and the one without it does not, x_out is set
    aside (``settings.distal_end_held.pressed``)."""
    pressed = distal_end_held(data, th.NEAR_HELD_SHARE)
    if pressed is None:
        return result
    alt = diagnose_recording(replace(data, x_out=None), progress=False, **kwargs)
    if UNKNOWN in alt.causes:
        return result
    alt.settings["distal_end_held"] = {**pressed, "pressed": True}
    alt.elapsed_s = _time.perf_counter() - t_start
    return alt
