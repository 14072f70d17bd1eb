"""The steps and rules of the single-tendon diagnosis
(:func:`estimator.offline.diagnosis.selection.diagnose_recording`).

Each function is one step of the procedure or one rule: its docstring says what physical symptom it reads and why
that symptom points where it does. The numbers are in :mod:`estimator.offline.diagnosis.thresholds` (``th``);
docs/concepts/diagnosis.md explains the procedure as a whole.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from estimator.data import MeasuredData, noise_level
from estimator.offline.diagnosis import thresholds as th
from estimator.offline.diagnosis.fit import Progress, quantum, rest_start, rest_window, settings_keys, start_points
from estimator.offline.diagnosis.folds import FINER, Fit, Folds, structure, unresolved
from estimator.offline.diagnosis.readings import (
    channel_choice,
    look_alike,
    rest_offset,
    rest_tension,
    speed_or_lag,
    toe_or_play,
)
from estimator.offline.diagnosis.singles import Singles
from estimator.offline.effects.catalogue import CATALOGUE, EQUIVALENT, Effect
from estimator.offline.effects.types import ROUTE_FORMS, ROUTE_KEYS, UNKNOWN, Series, finer_route, uniform_route

__all__ = ["Context", "noise_floors", "candidate_effects", "refine_route", "refit_routes",
           "select", "shown_at_floor", "stick_slip_rule", "rest_rule", "report_channels", "verdict",
           "pretension_at_rest", "speed_or_delay", "speed_or_delay_alone"]


@dataclass
class Context:
    """What every step reads: the prepared series ``s`` and its ``folds``, the measured distal ``signals``, the noise
    ``floor`` per signal [N], [m], the base's route form (``route``: False held, True thirds, "fine", "twelfths"),
    the progress bar, and the floor bounds for the channels the recording was made with (``subset_floor``,
    ``excess_min``)."""

    s: Series
    folds: Folds
    signals: list[str]
    floor: dict[str, float]
    route: bool | str
    bar: Progress
    subset_floor: dict[str, float]
    excess_min: float


def worst(fit: Fit, floor: dict[str, float]) -> float:
    """The largest structure ratio of a model over the signals (validation rmse / floor) [-]."""
    return max(structure(fit, floor).values())


def noise_floors(s: Series, data: MeasuredData, base: Fit, signals: list[str]) -> dict[str, float]:
    """The rmse a perfect model reaches on each distal signal [N], [m], estimated from the recording itself.

    Sensor noise and quantisation of the signal, the proximal load cell's noise carried through the model, and the
    model's own resolution (MODEL_RESOLUTION of the signal's range). The carry: d(signal)/d(T_in) is T_in e^-+K on
    the two branches (the memory latches the noise extremes of T_in); their rms sqrt(cosh 2K) carries sigma_in into
    T_out and, times L/EA, into the elongation.
    """
    sensor = {n: noise_level(getattr(s, n)) for n in signals}
    quanta = {n: quantum(getattr(data, n)) for n in signals}
    sigma_in = s.sigma_T_in
    carry = math.sqrt(math.cosh(2.0 * min(base.values[0]["K"], 3.0)))
    gain_in = {"T_out": carry, "x_out": base.compliance[0] * carry}
    span = {"T_out": float(np.ptp(s.T_out)) if s.T_out is not None else 0.0,
            "x_out": float(np.ptp(s.x_in - s.x_out)) if s.x_out is not None else 0.0}
    return {n: math.sqrt(v ** 2 + quanta[n] ** 2 / 12.0 + (sigma_in * gain_in[n]) ** 2
                         + (th.MODEL_RESOLUTION * span[n]) ** 2) for n, v in sensor.items()}


def candidate_effects(effects: list[Effect], signals: list[str]) -> list[Effect]:
    """The extensions to try: those the recording can show (their required signals measured), one of each group of
    equivalent effects (:data:`estimator.offline.effects.catalogue.EQUIVALENT`: they give the same outputs)."""
    cands: list[Effect] = []
    for e in effects:
        if all(r in signals for r in e.requires) and not any(q.id in EQUIVALENT.get(e.id, ()) for q in cands):
            cands.append(e)
    return cands


def route_alone(ctx: Context, base: Fit, form: str, alone: dict[str, Fit]) -> Fit:
    """The base refitted on the finer route ``form`` from its own route read at the finer knots (kept in
    ``alone``), scored against the base."""
    alone[form] = Fit([], ctx.folds, [{**finer_route(v, ROUTE_FORMS[form]), "K": v["K"]} for v in base.values[:1]],
                      route=form, base=base, floor=ctx.floor)
    return alone[form]


def refine_route(ctx: Context, base: Fit, alone: dict[str, Fit]) -> Fit:
    """Route refinement: where along the sheath the friction sits, finer when the coarse route leaves structure.

    Symptom: the base on thirds leaves a structure ratio above WEAK_STRUCTURE. A wrap concentrated in short arcs
    spreads over a whole third and misplaces the elongation at reversals; the sixths are tried, and the twelfths
    when the structure left is still above STRUCTURE_RATIO. A finer route becomes the base when it removes most of
    the structure on the validation blocks (S < ROUTE_SCORE); ``ctx.route`` is set to it.
    """
    if not (ctx.route and worst(base, ctx.floor) > th.WEAK_STRUCTURE):
        return base
    for form, above in (("fine", th.WEAK_STRUCTURE), ("twelfths", th.STRUCTURE_RATIO)):
        if worst(base, ctx.floor) > above:
            f = route_alone(ctx, base, form, alone)
            if f.S < th.ROUTE_SCORE:
                f.S, base, ctx.route = 1.0, f, form
                alone.clear()
    return base


def _refit_route_free(ctx: Context, eid: str, singles: dict[str, Fit], base: Fit) -> None:
    """Refit one candidate with the route shares free, from its fitted values, from the uniform route (the base's
    route, bent by what it lacks, can sit in a corner) and from the uniform route with a parameter read at the
    initial rest (Parameter.rest); kept when it scores better."""
    fitted = singles[eid].values[0]
    uniform = uniform_route(ctx.route)
    at_rest = rest_window(ctx.s)
    read = {p.name: max(r, 0.1) if p.rest == "replace" else r for p in CATALOGUE[eid].parameters
            if p.rest and math.isfinite(r := rest_start(p.name, ctx.s, at_rest))}
    starts = [fitted, {**fitted, **uniform}] + ([{**fitted, **uniform, **read}] if read else [])
    f = Fit([CATALOGUE[eid]], ctx.folds, starts, route=ctx.route, base=base, floor=ctx.floor,
            need=1.0 - th.PENALTY * singles[eid].n_params)
    if f.S < singles[eid].S:
        singles[eid] = f


def _none_explains(ctx: Context, singles: dict[str, Fit], base: Fit) -> bool:
    """The base leaves structure and every candidate fitted so far leaves structure too."""
    return (worst(base, ctx.floor) > th.STRUCTURE_RATIO
            and all(worst(singles[eid], ctx.floor) > th.STRUCTURE_RATIO for eid in singles))


def _on_finer_routes(ctx: Context, singles: dict[str, Fit], base: Fit, alone: dict[str, Fit]) -> None:
    """The best few on each finer route, from their own fitted route read at the finer knots, scored against the same
    finer route without an effect (so that a route refinement alone is not named). Kept only when it does what the
    step is for: the structure under the threshold."""
    for form in FINER[ctx.route]:
        by_route = min((alone[form] if form in alone else route_alone(ctx, base, form, alone)).S, 1.0)
        for eid in sorted(singles, key=lambda k: singles[k].S)[:th.POLISH]:
            v0 = singles[eid].values[0]
            f = Fit([CATALOGUE[eid]], ctx.folds, [{**v0, **finer_route(v0, ROUTE_FORMS[form])}], route=form,
                    base=base, floor=ctx.floor, need=(1.0 - th.PENALTY * singles[eid].n_params) * by_route)
            f.S /= by_route
            if f.S < singles[eid].S and worst(f, ctx.floor) <= th.STRUCTURE_RATIO:
                singles[eid] = f


def refit_routes(ctx: Context, singles: Singles, base: Fit, alone: dict[str, Fit]) -> None:
    """Route refits: an effect the base lacks distorts the base's fitted route, and its fit on that route may gain
    nothing. Symptom and remedy, in turn:

    * the best POLISH candidates are refitted with the route free; every candidate when none is acceptable yet and
      the base leaves structure (a position lag or offset skews the route so far that its own fit gains nothing);
    * when none of them brings the structure under STRUCTURE_RATIO, every other candidate too (a pretension can
      bend the route so that it scores above 1 on it);
    * when still none does, the best few on the finer routes (an effect whose model needs the wrap where it is:
      the drift of a load cell on a route of one arc).

    The candidates screened at the base (:mod:`estimator.offline.diagnosis.singles`) are fitted first where every
    candidate is refitted (the first two cases): their single fit on the base's route can gain nothing either.
    """
    if not ctx.route:
        return
    none_acceptable = (min((f.S + th.PENALTY * f.n_params for f in singles.values()), default=1.0) >= 1.0
                       and worst(base, ctx.floor) > th.STRUCTURE_RATIO)
    if none_acceptable:
        singles.complete()
    polish = sorted(singles, key=lambda k: singles[k].S)[:th.POLISH]
    if none_acceptable:
        polish += [eid for eid in singles if eid not in polish]
    for j, eid in enumerate(polish):
        _refit_route_free(ctx, eid, singles, base)
        if j < th.POLISH:
            ctx.bar(f"{eid}, route")
    if _none_explains(ctx, singles, base):
        singles.complete()
        for eid in [eid for eid in singles if eid not in polish]:
            _refit_route_free(ctx, eid, singles, base)
    if _none_explains(ctx, singles, base):
        _on_finer_routes(ctx, singles, base, alone)


def shown_at_floor(ctx: Context, base: Fit, eid: str, f: Fit) -> bool:
    """At the floor (base structure <= STRUCTURE_RATIO), whether an extension explains enough to be named.

    Near the floor a structure ratio says how far the base is from its noise, S only which share of it an extension
    explains; together they say how much it explains. Named when S is below the bar (STRONG_SCORE, MID_SCORE when
    the base's structure is above WEAK_STRUCTURE, or the effect's own bound FLOOR_SCORE: what it never reaches on a
    clean recording; the bounds of recordings made without a channel when one is missing) or when it removes at
    least EXCESS_MIN squared floors of the base's validation mean square, B (1 - S).
    """
    ratios = structure(base, ctx.floor)
    strong = th.MID_SCORE if max(ratios.values()) > th.WEAK_STRUCTURE else th.STRONG_SCORE
    bound = max(strong, th.FLOOR_SCORE.get(eid, 0.0))
    base_squares = sum(v * v for v in ratios.values())
    return f.S < min(bound, ctx.subset_floor.get(eid, bound)) or base_squares * (1.0 - f.S) >= ctx.excess_min


def _second_round(ctx: Context, chosen: Fit, pool: dict[str, Fit], base: Fit) -> dict[str, Fit]:
    """The best SECOND_ROUND candidates fitted together with the model so far (its route and values held)."""
    trial = {}
    for eid in sorted(pool, key=lambda k: pool[k].S)[:th.SECOND_ROUND]:
        fx = chosen.effects + [CATALOGUE[eid]]
        kept = {k: v for k, v in pool[eid].values[0].items() if k in settings_keys([CATALOGUE[eid]])}
        v0 = {**chosen.values[0], **kept}
        trial[eid] = Fit(fx, ctx.folds, start_points(fx, v0, ctx.s, v0),
                         fixed=[{**{k: v[k] for k in ROUTE_KEYS if k in v}, **kept} for v in chosen.values],
                         base=base, floor=ctx.floor,
                         need=chosen.S * (1.0 - th.PENALTY * len(CATALOGUE[eid].parameters)))
        ctx.bar(f"{'+'.join(chosen.ids)}+{eid}")
    return trial


def _prices(ctx: Context, trial: dict[str, Fit], chosen: Fit, at_floor: bool) -> dict[str, float]:
    """S relative to the model so far plus PENALTY per extra parameter; infinite for an effect fitted at a magnitude
    the recording cannot resolve (:func:`estimator.offline.diagnosis.folds.unresolved`)."""
    price = {eid: f.S / chosen.S + th.PENALTY * (f.n_params - chosen.n_params) for eid, f in trial.items()}
    return {eid: math.inf if any(unresolved(trial[eid].effects, v, ctx.floor,
                                            dominant=not at_floor and trial[eid].S < th.DOMINANT_SCORE)
                                 for v in trial[eid].values) else p
            for eid, p in price.items()}


def select(ctx: Context, base: Fit, singles: Singles, max_effects: int, data: MeasuredData) -> Fit:
    """Forward selection on the validation blocks, with a price per parameter relative to the model so far.

    An extension is acceptable when its price is below 1; among those, the lowest log S + log(RANK_FACTOR) per extra
    parameter wins, and two look-alike pairs are decided by what tells them apart (:func:`look_alike`,
    :func:`toe_or_play`). At the floor only those that explain enough compete (:func:`shown_at_floor`); a second
    effect is tried only while the model so far leaves structure. Returns the chosen model (``base`` for none).
    """
    chosen, pool = base, dict(singles)
    at_floor = worst(base, ctx.floor) <= th.STRUCTURE_RATIO
    while len(chosen.effects) < max_effects and pool:
        if chosen is not base and (at_floor or worst(chosen, ctx.floor) <= th.STRUCTURE_RATIO):
            break                       # nothing left above the noise for another effect to explain
        trial = pool if chosen is base else _second_round(ctx, chosen, pool, base)
        price = _prices(ctx, trial, chosen, at_floor)
        rank = {eid: math.log(max(f.S / chosen.S, 1e-12)) + math.log(th.RANK_FACTOR) * (f.n_params - chosen.n_params)
                for eid, f in trial.items() if price[eid] < 1.0}
        order = rank or price
        if at_floor and chosen is base:
            order = {eid: v for eid, v in order.items() if shown_at_floor(ctx, base, eid, trial[eid])} or order
        best = look_alike(min(order, key=lambda k: order[k]), price, data)
        best = toe_or_play(best, {eid: (f.S, f.values[0]) for eid, f in trial.items()}, price)
        best = pretension_at_rest(best, price, data)
        best = speed_or_delay(best, price, _training(ctx, data))
        if price[best] >= 1.0 or (at_floor and not shown_at_floor(ctx, base, best, trial[best])):
            break
        chosen = trial[best]
        pool.pop(best)
    return speed_or_delay_alone(chosen, base, singles, _training(ctx, data)) if chosen is base else chosen


def _training(ctx: Context, data: MeasuredData) -> MeasuredData:
    """The raw samples of the training block (up to the last sample of the prepared training block)."""
    return data.slice(0, int(np.searchsorted(data.time, ctx.folds.train.time[-1], side="right")))


_ENCODER_OFFSETS = ("sensor_offset:x_in", "sensor_offset:x_out")
_SPEED_OR_LAG = ("velocity_friction", "sensor_lag:T_out")


def pretension_at_rest(best: str, price: dict[str, float], data: MeasuredData) -> str:
    """Pretension or an encoder offset: what each does at rest.

    Symptom: an encoder offset is the best fit, but both load cells read a tension at the initial rest
    (:func:`estimator.offline.diagnosis.readings.rest_tension`) and neither encoder reads off its zero there
    (:func:`estimator.offline.diagnosis.readings.rest_offset`). A pretension is tension the tendon carries at rest,
    read by both load cells, and it moves no encoder; an encoder offset shifts its position by the same amount at
    every tension, the rest included, and loads nothing. Under operator-like motion the two bend the elongation alike
    (a pretension changes the tension at which the distal end starts to move, which an offset of x imitates on a
    spring load), and the fit may prefer the offset: the rest decides. Named when the pretension is acceptable
    (price < 1)."""
    if best not in _ENCODER_OFFSETS or price.get("pretension", math.inf) >= 1.0:
        return best
    rest = rest_tension(data)
    if rest is None or not rest["pretension"] or rest_offset(data) is not None:
        return best
    return "pretension"


def speed_or_delay(best: str, price: dict[str, float], data: MeasuredData) -> str:
    """Velocity friction or a lag of the distal load cell: what each does with speed and at reversals.

    Symptom: one of the two is the best fit and the other is acceptable (price < 1). Both widen the loop with the
    speed of a move; velocity friction by K c_v |v| in ln(T_in / T_out), whatever the tension's rate, vanishing at
    rest; a lag by tau |d ln T_out / dt|, every change read tau late whatever the speed, so that at a reversal the
    distal tension turns tau after the proximal one. The reading
    (:func:`estimator.offline.diagnosis.readings.speed_or_lag`, on the training block) separates the two terms over
    the slip samples: a delay of at least HAND_LAG_MIN names the lag, a smaller one velocity friction; the reading
    decides only where its delay or its speed term stands HAND_T_MIN standard errors from zero."""
    if best not in _SPEED_OR_LAG or not all(price.get(e, math.inf) < 1.0 for e in _SPEED_OR_LAG):
        return best
    reading = speed_or_lag(data)
    if reading is None or max(reading["delay_t"], reading["speed_t"]) < th.HAND_T_MIN:
        return best
    return "sensor_lag:T_out" if reading["delay"] >= th.HAND_LAG_MIN else "velocity_friction"


def speed_or_delay_alone(chosen: Fit, base: Fit, singles: Singles, data: MeasuredData) -> Fit:
    """Velocity friction or a distal load-cell lag at the floor, where the models named nothing: two signs together.

    Symptom: the speed-or-lag reading (:func:`estimator.offline.diagnosis.readings.speed_or_lag`, training block)
    shows a friction rising with sliding speed (c_v = speed / K of at least HAND_SPEED_MIN, a delay under
    HAND_LAG_MIN) or a delay of at least HAND_LAG_MIN with no such rise, that term at least HAND_T_MIN standard errors
    from zero, and that effect's extension fits the validation blocks better than the base (S < HAND_WEAK_SCORE).
    Velocity friction acts only while the tendon slides, so on a load that stops the distal end or under motion that
    mostly holds it shows on a few seconds of slip: there the reading measures it over every slip sample, while the
    fit's score, over every sample of the blocks, is diluted by the holds where both models agree. A clean recording
    shows neither term. Returns the named single or ``chosen``."""
    if chosen is not base or not all(singles.has(e) for e in _SPEED_OR_LAG):
        return chosen
    reading = speed_or_lag(data)
    if reading is None:
        return chosen
    if reading["delay"] >= th.HAND_LAG_MIN and reading["delay_t"] >= th.HAND_T_MIN:
        eid = "sensor_lag:T_out"
    elif reading["speed"] >= th.HAND_SPEED_MIN * max(reading["K"], 0.05) and reading["speed_t"] >= th.HAND_T_MIN:
        eid = "velocity_friction"
    else:
        return chosen
    f = singles.need(eid)
    return f if f is not None and f.S < th.HAND_WEAK_SCORE else chosen


def stick_slip_rule(ctx: Context, chosen: Fit, singles: dict[str, Fit], chatter: float | None
                    ) -> tuple[Fit, bool, bool, list[str]]:
    """Stick-slip: static friction above kinetic with a falling branch makes the tendon stick and slip, and the
    proximal load cell reads a saw-tooth in steady moves that no quasi-static extension reproduces.

    Symptom: the proximal tension rougher in steady moves than in holds (``chatter``, the ratio of
    :func:`estimator.offline.diagnosis.readings.stick_slip_ratio` on the training block; about 1 for sensor noise).
    Stiction is named (1) when the models named nothing and the ratio is at least STICK_SLIP_RATIO, (2) when they
    named nothing, the ratio is at least STICK_SLIP_WEAK and the stiction extension explains a tenth of what the
    base leaves (S < STICK_SLIP_WEAK_SCORE): two signs, each too weak alone, or (3) when the ratio is at least
    STICK_SLIP_RATIO and the models named effects that leave structure (a sensor lag or gain has no stick-slip:
    they are overruled). Returns (model, named, weak, overruled ids).
    """
    if chatter is None or "stiction" not in singles:
        return chosen, False, False, []
    weak = th.STICK_SLIP_WEAK <= chatter < th.STICK_SLIP_RATIO and singles["stiction"].S < th.STICK_SLIP_WEAK_SCORE
    overruled = (list(chosen.ids) if chatter >= th.STICK_SLIP_RATIO and chosen.effects
                 and "stiction" not in chosen.ids and worst(chosen, ctx.floor) > th.STRUCTURE_RATIO else [])
    named = (not chosen.effects and (chatter >= th.STICK_SLIP_RATIO or weak)) or bool(overruled)
    return (singles["stiction"] if named else chosen), named, bool(named and weak), overruled


def rest_rule(chosen: Fit, singles: dict[str, Fit], off_zero: str | None) -> tuple[Fit, bool]:
    """An encoder off its zero: positions are zeroed at the initial rest and no physical effect moves a reading at
    rest, so a position channel reading away from zero there (``off_zero``, the offset id of
    :func:`estimator.offline.diagnosis.readings.rest_offset`) is that encoder's offset. Named when the models name
    nothing (the base can absorb a small offset into its route and K). Returns (model, named)."""
    if off_zero is None or chosen.effects:
        return chosen, False
    fit = next((singles[q] for q in (off_zero, *EQUIVALENT.get(off_zero, ())) if q in singles), None)
    return (chosen, False) if fit is None else (fit, True)


def report_channels(chosen: Fit, data: MeasuredData) -> tuple[list[str], list[str], dict]:
    """Equivalent effects (the same outputs) are reported on the channel the data point to
    (:func:`estimator.offline.diagnosis.readings.channel_choice`): an x_in offset b is an x_out offset -b, a T_in gain
    g a T_out gain 1/(1 + g) - 1. Returns (ids as reported, the equivalents not reported, the renaming of ids and
    parameters with their conversions)."""
    rename: dict = {}
    equivalent: list[str] = []
    for e in chosen.effects:
        if e.id in EQUIVALENT:
            pick = channel_choice(data, e.id)
            equivalent += [q for q in (e.id, *EQUIVALENT[e.id]) if q != pick]
            if pick != e.id:
                other = CATALOGUE[pick]
                conv = (lambda v: -v) if "offset" in e.id else (lambda v: 1.0 / (1.0 + v) - 1.0)
                rename[e.id] = (pick,)
                rename[e.parameters[0].name] = (other.parameters[0].name, conv)
    return [rename.get(i, (i,))[0] for i in chosen.ids], equivalent, rename


def verdict(ids: list[str], left: dict[str, float], chosen: Fit, by_reading: bool) -> list[str]:
    """The causes in order: the accepted ids, then "unknown" when structure above STRUCTURE_RATIO is left. When more
    than twice the threshold is left the catalogue did not find the cause (what the accepted ones explain is a side
    issue): "unknown" first - unless they removed nearly all of the base's excess (S < DOMINANT_SCORE) or a
    model-free reading (stick-slip, the rest) named them."""
    excess = max(left.values())
    first = (excess > 2.0 * th.STRUCTURE_RATIO and not (chosen.effects and chosen.S < th.DOMINANT_SCORE)
             and not by_reading)
    return [UNKNOWN] + ids if first else ids + ([UNKNOWN] if excess > th.STRUCTURE_RATIO else [])

