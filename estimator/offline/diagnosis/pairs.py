"""Two causes at once: pairs of the strongest single candidates, where the model chosen so far leaves structure.

A step of :func:`estimator.offline.diagnosis.selection.diagnose_recording` after the forward selection
(:func:`estimator.offline.diagnosis.rules.select`): :func:`consider_pairs`, :func:`offset_beside_physical`,
:func:`second_at_floor` and :func:`speed_beside_offset` (their docstrings give the rules; the numbers are PENALTY,
RANK_FACTOR, DOMINANT_SCORE, STRUCTURE_RATIO and SCREEN_SHARE of :mod:`estimator.offline.diagnosis.thresholds`, and the
run-time bound :data:`PAIR_POOL`).
"""
from __future__ import annotations

import copy
import dataclasses
import math

import numpy as np

from estimator.data import MeasuredData
from estimator.offline.diagnosis import thresholds as th
from estimator.offline.diagnosis.fit import settings_keys, start_points
from estimator.offline.diagnosis.folds import Fit, unresolved
from estimator.offline.diagnosis.readings import speed_or_lag
from estimator.offline.diagnosis.rules import Context, shown_at_floor, worst
from estimator.offline.diagnosis.screen import Linearised
from estimator.offline.diagnosis.singles import Singles, forms
from estimator.offline.effects.catalogue import CATALOGUE, Effect
from estimator.offline.effects.types import ROUTE_KEYS, uniform_route

__all__ = ["consider_pairs", "second_at_floor", "speed_beside_offset", "offset_beside_physical", "PAIR_POOL",
           "PAIR_REFINED"]

#: [count] the strongest single candidates (lowest S), and the strongest physical ones, whose pairs are fitted when
#: the model so far leaves structure: a run-time bound (at most 15 pair fits), not tuned
PAIR_POOL = 3
#: [count] starts refined on the forward fold of a pair fit. The pair starts from both single fits' values (or the
#: first model's), already near the minimum: refining the second least costly start as well takes a third of a long
#: recording's diagnosis and names the same causes on the development sets (docs/results/diagnosis.md)
PAIR_REFINED = 1


def _rank(f: Fit) -> float:
    """log S + log(RANK_FACTOR) per parameter: the forward selection's rank of a model against the base."""
    return math.log(max(f.S, 1e-12)) + math.log(th.RANK_FACTOR) * f.n_params


def _pair_fit(ctx: Context, base: Fit, singles: dict[str, Fit], a: str, b: str) -> Fit:
    """Two candidates fitted together on each fold: from both single fits' values (the first one's route held)."""
    fx = [CATALOGUE[a], CATALOGUE[b]]
    v0 = {**singles[b].values[0], **singles[a].values[0]}
    kept = {k: v for k, v in v0.items() if k in settings_keys(fx)}
    n = sum(len(e.parameters) for e in fx)
    per_fold = singles[a].values + singles[a].values[-1:] * (len(ctx.folds.fit) - len(singles[a].values))
    return Fit(fx, ctx.folds, start_points(fx, v0, ctx.s, v0),
               fixed=[{**{k: v[k] for k in ROUTE_KEYS if k in v}, **kept} for v in per_fold],
               base=base, floor=ctx.floor, need=1.0 - th.PENALTY * n, refined=PAIR_REFINED)


def _pool(singles: dict[str, Fit], out: list[str]) -> list[str]:
    """The PAIR_POOL strongest single candidates (S < 1) and the PAIR_POOL strongest physical ones, without ``out``."""
    ranked = sorted((eid for eid in singles if singles[eid].S < 1.0 and eid not in out), key=lambda k: singles[k].S)
    physical = [eid for eid in ranked if not CATALOGUE[eid].channel]
    return ranked[:PAIR_POOL] + [eid for eid in physical[:PAIR_POOL] if eid not in ranked[:PAIR_POOL]]


def consider_pairs(ctx: Context, base: Fit, singles: dict[str, Fit], chosen: Fit) -> Fit:
    """Two causes at once: where the model chosen so far leaves structure (above STRUCTURE_RATIO on a signal, the base
    above it too), the pairs of the PAIR_POOL strongest single candidates and the PAIR_POOL strongest physical ones
    (not sensor effects), and the strongest single beside every other physical candidate, at least one of each pair
    physical, are fitted together and scored against the base on the same validation blocks.

    Two effects at once bend each other's single fits: each alone explains part of the residual, and the one the
    forward selection takes first may not be one of them, so that no second effect fits beside it; a sensor offset
    beside a physical effect explains most of the residual alone and hides the physical one among the sensor
    effects that explain the same offset a little worse. A pair is acceptable with the same price as any model,
    S + PENALTY x (its parameters) < 1, and only when each of its two effects earns its own parameters against the
    other alone (S_pair / S_single + PENALTY x (the other's parameters)
    < 1; neither fitted at a magnitude the recording cannot resolve); among the acceptable ones and the model so far,
    the lowest log S + log(RANK_FACTOR) x (parameters) is kept. Returns the model kept (``chosen`` when no pair does
    better)."""
    if (worst(chosen, ctx.floor) <= th.STRUCTURE_RATIO or worst(base, ctx.floor) <= th.STRUCTURE_RATIO
            or len(singles) < 2):
        return chosen
    pool = _pool(singles, [])
    pairs = [(a, b) for i, a in enumerate(pool) for b in pool[i + 1:]]
    if pool:        # the strongest single beside every physical candidate (its own single fit bent by the first)
        pairs += [(pool[0], b) for b in singles if not CATALOGUE[b].channel and b not in pool]
    best, best_rank = chosen, _rank(chosen) if chosen.effects else 0.0
    for a, b in pairs:
        if {a, b} == set(chosen.ids) or (CATALOGUE[a].channel and CATALOGUE[b].channel):
            continue        # the model so far, or two sensor effects: a pair names a physical cause
        f = _pair_fit(ctx, base, singles, a, b)
        if _acceptable(ctx, f, singles, (a, b)) and _rank(f) < best_rank:
            best, best_rank = f, _rank(f)
    return best


def second_at_floor(ctx: Context, base: Fit, singles: Singles, chosen: Fit) -> Fit:
    """A second cause under the first: where the base leaves structure and one effect brings it to the floor
    (STRUCTURE_RATIO or less), a second effect is named when, beside the first, it passes the bars at the floor with
    the first effect's model as the base.

    A sensor offset or a pretension explains most of what the base leaves; a velocity friction or a drift of K beside
    it leaves the first model near its floor, where the forward selection tries no second effect. At the floor the
    rules name an effect on a clean recording (:func:`estimator.offline.diagnosis.rules.shown_at_floor`: S below the
    effect's own bar, or B (1 - S) of at least EXCESS_MIN squared floors); with the first effect explained the
    residual is such a recording's, so the same bars apply to the pair's S relative to the first model. The partners
    are every physical candidate and, beside a physical first effect, the PAIR_POOL strongest singles: a second
    effect's single fit is bent by the first, so its S alone does not say what it adds beside it (a drift of K
    beside a pretension ranks below the encoder offsets and the play that mimic the pretension). A partner must pay
    its parameters (S_rel + PENALTY x its parameters < 1) and be resolved; among those
    the lowest log S_rel + log(RANK_FACTOR) x (its parameters) is kept. A partner whose linearised share of the first
    model's residual is below SCREEN_SHARE x its price is not fitted (:mod:`estimator.offline.diagnosis.screen`); a
    partner fitted alone is tried in its single fit's form, one screened at the base
    (:mod:`estimator.offline.diagnosis.singles`), which has no form of its own, in each form whose share passes.
    Returns ``chosen`` or the pair."""
    if (len(chosen.effects) != 1 or worst(base, ctx.floor) <= th.STRUCTURE_RATIO
            or worst(chosen, ctx.floor) > th.STRUCTURE_RATIO):
        return chosen
    first = chosen.effects[0]
    best, best_rank = chosen, 0.0
    partners = [eid for eid in (*singles, *singles.screened) if not CATALOGUE[eid].channel and eid != first.id]
    if not first.channel:
        partners += [eid for eid in _pool(singles, chosen.ids)[:PAIR_POOL] if eid not in partners]
    screen = Linearised(chosen.effects, chosen.values[0], ctx.folds.train, ctx.folds.fit[0])
    for eid in partners:
        e = CATALOGUE[eid]
        if eid in singles.screened:     # no form of its own: each form whose share passes
            held = [form for form in forms(ctx, e) if not screen.skips(e, form)]
        else:
            kept = {k: v for k, v in singles[eid].values[0].items() if k in settings_keys([e])}
            held = [] if screen.skips(e, kept) else [kept]      # below its price: not fitted
        for kept in held:
            f, rank = _beside_first(ctx, base, chosen, e, kept)
            if rank < best_rank:
                best, best_rank = f, rank
    return best


def _beside_first(ctx: Context, base: Fit, chosen: Fit, e: Effect, kept: dict) -> tuple[Fit, float]:
    """``e`` fitted beside the single effect of ``chosen`` in its form ``kept``, judged as :func:`second_at_floor`
    asks: (the pair, its rank log S_rel + log(RANK_FACTOR) x (its parameters), inf when it is not named)."""
    fx = [chosen.effects[0], e]
    v0 = {**chosen.values[0], **kept}
    n = len(e.parameters)
    f = Fit(fx, ctx.folds, start_points(fx, v0, ctx.s, v0),
            fixed=[{**{k: v[k] for k in ROUTE_KEYS if k in v}, **kept} for v in chosen.values],
            base=base, floor=ctx.floor, need=chosen.S * (1.0 - th.PENALTY * n), refined=PAIR_REFINED)
    if not f.complete and f.sole_fold is None:
        return f, math.inf
    rel = copy.copy(f)
    rel.S = f.S / max(chosen.S, 1e-12)
    rank = math.log(max(rel.S, 1e-12)) + math.log(th.RANK_FACTOR) * n
    named = (rel.S + th.PENALTY * n < 1.0 and shown_at_floor(ctx, chosen, e.id, rel)
             and not any(unresolved(f.effects, v, ctx.floor) for v in f.values))
    return f, rank if named else math.inf


_TENSION_OFFSETS = ("sensor_offset:T_in", "sensor_offset:T_out")


def speed_beside_offset(ctx: Context, base: Fit, singles: Singles, chosen: Fit, data: MeasuredData) -> Fit:
    """Velocity friction beside a load-cell offset: the speed term read once the offset is taken off its channel.

    Symptom: the chosen model holds an offset of T_in or T_out and no velocity friction, and the speed-or-lag reading
    (:func:`estimator.offline.diagnosis.readings.speed_or_lag`) of ``data`` (the training block's raw samples) with
    the fitted offset taken off its channel shows a friction rising with sliding speed: c_v = speed / K of at least
    HAND_SPEED_MIN, at least HAND_T_MIN standard errors from zero, a delay under HAND_LAG_MIN. An offset explains most
    of what the base leaves and bends every other single fit; the second effect fitted beside it is then whichever
    widens the loop best (stiction, a distal lag) or none. The offset alone adds no speed term (it shifts ln T_in -
    ln T_out by an amount that depends on the tension, not on the speed); velocity friction grows with the sliding
    speed and vanishes at rest. The offset and velocity friction are fitted together and named when velocity friction
    explains some of what the offset leaves (S below the offset's alone) and is resolved. Returns the pair or
    ``chosen``."""
    first = next((e for e in chosen.effects if e.id in _TENSION_OFFSETS), None)
    if first is None or "velocity_friction" in chosen.ids or not singles.has("velocity_friction") \
            or first.id not in singles:
        return chosen
    channel = first.id.split(":")[1]
    corrected = np.asarray(getattr(data, channel), dtype=float) - chosen.values[0][first.parameters[0].name]
    taken = (dataclasses.replace(data, T_in=corrected) if channel == "T_in"
             else dataclasses.replace(data, T_out=corrected))
    reading = speed_or_lag(taken)
    if (reading is None or reading["delay"] >= th.HAND_LAG_MIN or reading["speed_t"] < th.HAND_T_MIN
            or reading["speed"] < th.HAND_SPEED_MIN * max(reading["K"], 0.05)):
        return chosen
    singles.need("velocity_friction")
    f = _pair_fit(ctx, base, singles, first.id, "velocity_friction")
    if f.S < singles[first.id].S and not any(unresolved(f.effects, v, ctx.floor) for v in f.values):
        return f
    return chosen


def _acceptable(ctx: Context, f: Fit, singles: dict[str, Fit], ids: tuple[str, str]) -> bool:
    """The pair's price and resolution as :func:`consider_pairs` asks them: S + PENALTY x (its parameters) < 1, each
    effect earning its own parameters against the other alone, neither fitted below what the recording resolves."""
    if not f.complete and f.sole_fold is None:
        return False        # stopped after one fold: it cannot be accepted
    own = all(f.S / singles[e].S + th.PENALTY * (f.n_params - singles[e].n_params) < 1.0 for e in ids)
    return (f.S + th.PENALTY * f.n_params < 1.0 and own
            and not any(unresolved(f.effects, v, ctx.floor, dominant=f.S < th.DOMINANT_SCORE) for v in f.values))


def offset_beside_physical(ctx: Context, base: Fit, singles: dict[str, Fit], chosen: Fit) -> Fit:
    """A load-cell offset beside the physical effect chosen first, fitted with the route free.

    Symptom: the model kept so far is one physical effect (not a sensor effect) and leaves structure (above
    STRUCTURE_RATIO on a signal, the base above it too). A constant offset on T_in or T_out changes the apparent
    capstan ratio ln T_in - ln T_out by an amount that falls with the tension; the base's route bends to explain it
    (the wrap pushed to one end of the sheath), and every single fit, the physical effect's among them, inherits the
    bent route. Fitted beside the offset on that route, the physical effect still cannot bring the distal
    elongation to the floor, and the pair's offset alone is too weak a single to enter the pairs' pool
    (:func:`consider_pairs`). Remedy: the chosen effect beside each tension offset, the route free, from the chosen
    values with the offset's single fit and from the same values on the uniform route (as a single's route refit,
    :func:`estimator.offline.diagnosis.rules.refit_routes`), both starts refined (the uniform one is how the fit
    leaves a corner of the bent route, whichever costs less at the start), in each form of the physical effect (its
    held ``variants``: forms its single scores alike, as velocity friction's two speeds can, differ beside the
    offset). A pair is kept on the terms of :func:`consider_pairs` (its price, each effect earning its parameters,
    resolved) when it ranks below the model so far (log S + log(RANK_FACTOR) x parameters). Returns the pair or
    ``chosen``."""
    if (not ctx.route or len(chosen.effects) != 1 or chosen.effects[0].channel
            or worst(chosen, ctx.floor) <= th.STRUCTURE_RATIO or worst(base, ctx.floor) <= th.STRUCTURE_RATIO):
        return chosen
    physical = chosen.effects[0]
    uniform, alone = uniform_route(ctx.route), {**singles, physical.id: chosen}
    best, best_rank = chosen, _rank(chosen)
    for offset in (eid for eid in _TENSION_OFFSETS if eid in singles):
        fx = [physical, CATALOGUE[offset]]
        held, need = settings_keys(fx), 1.0 - th.PENALTY * sum(len(e.parameters) for e in fx)
        for form in forms(ctx, physical):
            v0 = {**singles[offset].values[0], **chosen.values[0], **form}
            kept = {k: v for k, v in v0.items() if k in held}
            starts = [v0, {**v0, **uniform}]
            f = Fit(fx, ctx.folds, starts, route=ctx.route, fixed=kept or None, base=base, floor=ctx.floor,
                    need=need, refined=len(starts))
            if _acceptable(ctx, f, alone, (physical.id, offset)) and _rank(f) < best_rank:
                best, best_rank = f, _rank(f)
    return best
