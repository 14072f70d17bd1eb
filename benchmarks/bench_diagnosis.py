"""Diagnosis benchmark: the confusion matrix on both simulators, development and final seeds; speed.

Every catalogue effect is hidden at several magnitudes (positions in its realistic range,
study.scenarios.realistic_range) and seeds, plus clean recordings and one uncatalogued effect
(the answer must be ``unknown``); each recording is diagnosed and the answer compared with the
hidden effect. Two simulators, reported apart:

* ``rig``: the project's quasi-static rig (study/scenarios.py), the one the diagnosis shares its
  physics with;
* ``lumped``: the independent dynamic lumped-mass simulator (study/lumped/scenarios.py: random
  routes of arcs and straight runs, random distal loads, 200-2000 Hz, its own noise).

Seed sets (``SEED_BASE``): ``dev`` (effects 100+, clean 500+, uncatalogued 900+), ``dev2`` ... ``dev54`` (the
same offsets + 100000 each), ``final`` (offsets + 5400000), ``final2`` (offsets + 5700000), ``final3`` (offsets
+ 5800000) and ``final4`` (offsets + 5900000). The ``dev`` sets are development data: the rules are chosen on them.
``final`` ... ``final4`` are held-out sets: fixed in advance, diagnosed once by the frozen rules, never tuned on (the
step and compound families of ``final2`` and ``final3`` are development data, docs/results/diagnosis.md).

``--family`` chooses what is hidden: ``catalogue`` (default: every catalogue effect, clean, uncatalogued), ``step``
(the friction step, :data:`STEP_FAMILY`, beside its look-alike, a steady drift of K, and clean recordings: right is
the friction step named first with its instant within :data:`INSTANT_TOL` of the truth, the drift named a drift) or
``compound`` (two physical causes at once, :data:`COMPOUND`: right is both named, neither after ``unknown``). A
family's effect k, level j, repeat s uses base + 60000 + 1000 k + 10 j + s, its clean recordings base + 60500 + s.

Every hidden-effect recording has its own seed, so its own simulated rig (route, K, EA, load, rate,
noise): effect k of EFFECT_IDS, level j, repeat s uses base + 100 + 1000 k + 10 j + s (``--shared-rigs``: every
effect of a set on the four rigs base + 100 + 10 j + s).
``--route-known`` gives every diagnosis its rig's true route shape (``wrap_shape``), as a user who
knows the instrument's route does with ``teleop analyze --route CONFIG``: where the friction sits is then held,
not fitted, and the figures say what that knowledge buys.
Prints per effect and per channel: accuracy (strict, and up to the inseparable pairs of
estimator.offline.effects.catalogue.EQUIVALENT), gains, false alarms on clean data; never fails on the figures (the
pass/fail checks are in tests/estimator/test_diagnosis*.py).

    .venv/bin/python benchmarks/bench_diagnosis.py [--sim rig|lumped|both] [--set dev|...|dev54|final|...|final4]
        [--seeds 2]
        [--levels 0.2,0.8] [--clean 12] [--duration 90] [--rate 1000] [--jobs 2] [--json OUT] [--speed-only] [--twins]
        [--shared-rigs] [--family catalogue|step|compound]
    .venv/bin/python benchmarks/bench_diagnosis.py --floor-table OUT.json [OUT.json ...]

``--floor-table`` prints estimator.offline.diagnosis.thresholds.FLOOR_SCORE as computed from the clean recordings
(and clean twins) of runs of this benchmark whose base model is at the floor (``--json`` files of development sets
only), per effect the lowest score and the bound.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace

import numpy as np
from diagnosis_tables import (  # noqa: F401 - re-exported
    INSTANT_TOL,
    UNCATALOGUED,
    family_right,
    family_table,
    named_right,
    proportion_interval,
    table,
)

from estimator.data import noise_level
from estimator.offline.diagnosis.fit import quantum
from estimator.offline.diagnosis.selection import diagnose
from estimator.offline.diagnosis.thresholds import FLOOR_FACTOR, MID_SCORE, STRUCTURE_RATIO, floor_scores
from estimator.offline.effects.catalogue import CATALOGUE, EFFECT_IDS
from estimator.offline.effects.types import NONE

#: seed offset of each set: ``dev``, ``dev2`` ... ``dev54`` (development data), ``final`` ... ``final4`` (held out:
#: diagnosed once by the frozen rules, never tuned on)
SEED_BASE = {"dev": 0, **{f"dev{k}": 100000 * (k - 1) for k in range(2, 55)}, "final": 5400000, "final2": 5700000,
             "final3": 5800000, "final4": 5900000}
#: the change-point family: the friction step and its look-alike, a steady drift of K
STEP_FAMILY = ("friction_step", "curvature_drift")
#: the compound family: two physical causes at once (ids joined by "+")
COMPOUND = ("pretension+curvature_drift", "velocity_friction+sensor_offset:T_in",
            "velocity_friction+sensor_offset:T_out")


def effect_seed(base: int, k: int, j: int, s: int, shared_rigs: bool = False) -> int:
    """Seed of the recording of effect number ``k`` (in EFFECT_IDS), level number ``j``, repeat ``s``:
    base + 100 + 1000 k + 10 j + s (its own rig), or base + 100 + 10 j + s with ``shared_rigs``."""
    return base + 100 + (0 if shared_rigs else 1000 * k) + 10 * j + s


def _record(sim: str):
    if sim == "rig":
        from study.scenarios import record
    else:
        from study.lumped.scenarios import record
    return record


CHANNELS = ("T_in", "T_out", "x_in", "x_out")
def _sigma(a: np.ndarray) -> float:
    """Noise sigma of a recorded channel, from the recording: white noise (second differences) and the
    quantisation step (the smallest non-zero sample-to-sample step) [unit of a]."""
    d = np.abs(np.diff(a))
    q = quantum(a) or (float(np.min(d[d > 0])) if np.any(d > 0) else 0.0)
    return max(math.hypot(noise_level(a), q / math.sqrt(12.0)), 1e-12)


def footprint(data, twin) -> dict[str, float]:
    """Model-free footprint of a hidden effect: rms of (recording - clean twin) per channel, in units of
    that channel's noise sigma estimated on the twin (:func:`_sigma`)."""
    out = {}
    for ch in CHANNELS:
        a, b = getattr(data, ch), getattr(twin, ch)
        if a is not None and b is not None:
            a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
            out[ch] = float(np.sqrt(np.mean((a - b) ** 2)) / _sigma(b))
    return out


def _load_kind(truth: dict) -> str:
    """The distal load of a recording's rig (the lumped simulator's ``truth["load"]["kind"]``; "rig" else)."""
    load = truth.get("load")
    return str(load.get("kind", "?")) if isinstance(load, dict) else "rig"


def _scores(res: dict) -> dict[str, float]:
    """Validation score S of every candidate of a diagnosis, rounded for the JSON."""
    return {k: round(v["score"], 3) for k, v in res["candidates"].items()}


def known_route(truth: dict) -> np.ndarray | None:
    """The route shape of a simulated rig as a user who knows the instrument's route would pass it
    (``diagnose(..., wrap_shape=...)``, as ``teleop analyze --route CONFIG`` does): the normalised cumulative
    wrap angle of ``truth["route"]`` ((length [m], radius [m]) pieces), shape (257,)."""
    from estimator.geometry import SheathGeometry
    from slave.calibrate import wrap_shape
    return wrap_shape(SheathGeometry(truth["route"]))


def _twin_diagnosis(data, shape: np.ndarray | None = None) -> dict:
    """Diagnosis of a clean twin (with the route ``shape`` held when given): its causes, base structure ratio
    and candidate scores (an error counts as an answer)."""
    try:
        res = diagnose(data, wrap_shape=shape)
    except Exception as err:          # noqa: BLE001 - reported as the twin's answer
        return {"twin_cause": f"error: {type(err).__name__}", "twin_causes": ["error"], "twin_structure": float("nan"),
                "twin_scores": {}}
    return {"twin_cause": res["cause"], "twin_causes": res["causes"],
            "twin_structure": max(res["structure"]["base"].values()),
            "twin_scores": _scores(res), "twin_detail": _detail(res)}


def one(case: tuple) -> dict:
    sim, effect, level, seed, duration, rate, twins, route, without = case
    kw = {"seed": seed, "level": level, "duration": duration, **({"rate_hz": rate} if sim == "rig" or rate else {})}
    rec = _record(sim)(None if effect == NONE else tuple(effect.split("+")) if "+" in effect else effect, **kw)
    # the clean twin of a hidden effect (same seed, level and rate): how far the effect moves the recording;
    # with --twins it is diagnosed too (one more clean rig per hidden-effect recording: false alarms)
    twin = _record(sim)(None, **kw) if effect in EFFECT_IDS or "+" in effect else None
    if without:         # --without: a rig that does not record these distal channels
        dropped = {ch: None for ch in without}
        rec = replace(rec, data=replace(rec.data, **dropped))
        twin = replace(twin, data=replace(twin.data, **dropped)) if twin is not None else None
    fp = footprint(rec.data, twin.data) if twin is not None else {}
    extra = {"load": _load_kind(rec.truth)}             # the twin's rig is the recording's
    shape = known_route(rec.truth) if route else None   # --route-known: the route held, not fitted
    if twin is not None and twins:
        extra.update(_twin_diagnosis(twin.data, shape))
    t0 = time.perf_counter()
    try:
        res = diagnose(rec.data, wrap_shape=shape)
    except Exception as err:            # a recording the diagnosis cannot take counts as a miss, the run goes on
        return {"sim": sim, "effect": effect, "level": rec.truth["level"], "seed": seed,
                "cause": f"error: {type(err).__name__}: {err}", "causes": ["error"], "equivalent": [], "gain": 0.0,
                "seconds": time.perf_counter() - t0, "n": len(rec.data), "truth": rec.truth["parameters"],
                "fitted": {}, "scores": {}, "structure": float("nan"), "structure_ext": float("nan"), "detail": {},
                "footprint": fp, **extra}
    return {"sim": sim, "effect": effect, "level": rec.truth["level"], "seed": seed, "cause": res["cause"],
            "causes": res["causes"], "equivalent": res["equivalent"], "gain": res["gain"],
            "seconds": time.perf_counter() - t0, "n": len(rec.data), "truth": rec.truth["parameters"],
            "t_first": float(rec.data.time[0]),
            "fitted": {k: v["value"] for k, v in res["parameters"].items() if v["effect"] != "base"},
            "scores": _scores(res),
            "structure": max(res["structure"]["base"].values()),
            "structure_ext": max(res["structure"]["extended"].values()),
            "at_end": (res["settings"].get("distal_at_end") or {}).get("share"),
            "pair_rule": res["settings"].get("pair_rule"),
            "footprint": fp, **extra,
            "detail": _detail(res)}


def _detail(res: dict) -> dict:
    """A diagnosis' structure ratios, noise floors and every candidate's validation figures (for the JSON)."""
    return {"structure": res["structure"], "noise": res["noise"],
            "stick_slip": {k: res["stick_slip"][k] for k in ("ratio", "named", "weak", "overruled")},
            "rest_offset": {k: res["rest_offset"][k] for k in ("reads", "named")},
            "judged_folds": res["split"]["judged_folds"],
            "candidates": {k: {m: v[m] for m in ("validation_rmse_T_out_N", "validation_rmse_x_out_m",
                                                 "score", "penalised_score", "fold_values", "fold_scores")}
                           for k, v in res["candidates"].items()}}


def shows_without(effect: str, without: tuple[str, ...]) -> bool:
    """Whether a hidden effect can show in a recording without the distal channels ``without``: not when the
    effect needs one of them (``Effect.requires``: distal backlash and the x_out sensor effects need x_out, the
    T_out sensor effects need T_out)."""
    return effect not in EFFECT_IDS or not set(CATALOGUE[effect].requires) & set(without)


def clean_scores(rows: list[dict]) -> list[dict[str, float]]:
    """Candidate scores of the clean recordings and clean twins of benchmark rows whose base model is at the floor
    (structure ratio <= STRUCTURE_RATIO on every signal: where FLOOR_SCORE applies), whatever they were answered."""
    out = [r["scores"] for r in rows if r["effect"] == NONE and r["scores"] and r["structure"] <= STRUCTURE_RATIO]
    return out + [r["twin_scores"] for r in rows
                  if r.get("twin_scores") and r.get("twin_structure", math.inf) <= STRUCTURE_RATIO]


def floor_table(paths: list[str]) -> dict[str, float]:
    """Print and return :func:`estimator.offline.diagnosis.thresholds.floor_scores` of the clean rows in ``paths``
    (benchmark ``--json`` files); ValueError naming a file that is not a list of benchmark rows."""
    clean: list[dict[str, float]] = []
    for path in paths:
        with open(path) as fh:
            rows = json.load(fh)
        if not isinstance(rows, list) or not all(isinstance(r, dict) and "effect" in r and "cause" in r for r in rows):
            raise ValueError(f"{path}: not a list of benchmark rows (--json output)")
        got = clean_scores(rows)
        print(f"{path}: {len(got)} clean recordings at the floor")
        clean += got
    table = floor_scores(clean)
    low = floor_scores(clean, factor=1.0, cap=math.inf)
    print(f"{len(clean)} clean recordings at the floor; bound = min({MID_SCORE}, {FLOOR_FACTOR} x lowest score)")
    for eid, v in table.items():
        print(f"  {eid:22s} lowest {low[eid]:.3f}  bound {v:.3f}")
    # rounded down: the printed table is never looser than the computed one
    print("FLOOR_SCORE = {" + ", ".join(f'"{k}": {math.floor(v * 100.0) / 100.0:.2f}' for k, v in table.items()) + "}")
    return table


def _parser() -> argparse.ArgumentParser:
    """The benchmark's command line."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sim", choices=("rig", "lumped", "both"), default="both")
    ap.add_argument("--set", choices=tuple(SEED_BASE), default="dev", dest="seed_set")
    ap.add_argument("--seeds", type=int, default=2, help="seeds per effect and level")
    ap.add_argument("--levels", default="0.2,0.8", help="magnitude positions in the realistic range")
    ap.add_argument("--clean", type=int, default=12, help="clean recordings (seeds)")
    ap.add_argument("--unknown", type=int, default=4, help="recordings with the uncatalogued effect")
    ap.add_argument("--duration", type=float, default=90.0)
    ap.add_argument("--rate", type=float, default=None, help="rig: default 1000 Hz; lumped: its own random rate")
    ap.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1))
    ap.add_argument("--only", default="", help="comma-separated hidden effects (default: all, clean, unknown)")
    ap.add_argument("--json", default="", help="write every row as JSON to this file")
    ap.add_argument("--verbose", action="store_true")
    ap.add_argument("--twins", action="store_true",
                    help="diagnose the clean twin of every hidden-effect recording too (false alarms on that many "
                         "more clean rigs; about twice the run time)")
    ap.add_argument("--route-known", action="store_true",
                    help="give the diagnosis each rig's true route shape (a user who knows the instrument's route: "
                         "`teleop analyze --route CONFIG`) instead of fitting where the friction sits")
    ap.add_argument("--without", action="append", default=[], choices=("x_out", "T_out"),
                    help="drop this distal channel from every recording (a rig without a distal encoder or load "
                         "cell); effects that need it are left out of the set")
    ap.add_argument("--shared-rigs", action="store_true",
                    help="every effect of a set on the same four rigs (seed base + 100 + 10 j + s)")
    ap.add_argument("--family", choices=("catalogue", "step", "compound"), default="catalogue",
                    help="what is hidden: every catalogue effect, the friction step beside a drift, or two causes")
    ap.add_argument("--speed-only", action="store_true", help="only time a 10-minute 1 kHz recording")
    ap.add_argument("--floor-table", nargs="+", default=None, metavar="JSON",
                    help="print the per-effect floor bounds (diagnosis.FLOOR_SCORE) from the clean recordings of "
                         "these --json files of development sets, and exit")
    return ap


def _cases(args, levels: list[float], without: tuple[str, ...]) -> list[tuple]:
    """The recordings of a run: every effect at every level and seed, the clean and the uncatalogued ones."""
    b = SEED_BASE[args.seed_set]
    cases: list[tuple] = []
    if args.family != "catalogue":
        hidden = STEP_FAMILY if args.family == "step" else COMPOUND
        for sim in _sims(args):
            rate = args.rate if args.rate or sim == "lumped" else 1000.0
            cases += [(sim, e, lv, b + 60000 + 1000 * k + 10 * j + s, args.duration, rate, False, args.route_known,
                       without) for k, e in enumerate(hidden) for j, lv in enumerate(levels) for s in range(args.seeds)]
            cases += [(sim, NONE, None, b + 60500 + s, args.duration, rate, False, args.route_known, without)
                      for s in range(args.clean)]
        return cases
    for sim in _sims(args):
        rate = args.rate if args.rate or sim == "lumped" else 1000.0
        cases += [(sim, e, lv, effect_seed(b, k, j, s, args.shared_rigs), args.duration, rate, args.twins,
                   args.route_known, without)
                  for k, e in enumerate(EFFECT_IDS) if shows_without(e, without)
                  for j, lv in enumerate(levels) for s in range(args.seeds)]
        cases += [(sim, NONE, None, b + 500 + s, args.duration, rate, False, args.route_known, without)
                  for s in range(args.clean)]
        cases += [(sim, UNCATALOGUED, 1.0, b + 900 + s, args.duration, rate, False, args.route_known, without)
                  for s in range(args.unknown)]
    if args.only:
        keep = args.only.split(",")
        cases = [c for c in cases if c[1] in keep]
    return cases


def _sims(args) -> tuple[str, ...]:
    return ("rig", "lumped") if args.sim == "both" else (args.sim,)


def _print_misses(rows: list[dict]) -> None:
    """Every wrong answer and every false alarm on a clean twin, one line each (``--verbose``)."""
    for r in rows:
        if not family_right(r):
            print("  miss:", r["sim"], r["effect"], f"level {r['level']:.2f} seed {r['seed']} ->", r["causes"],
                  f"gain {r['gain']:.2f}", r["truth"], r["fitted"],
                  dict(sorted(r["scores"].items(), key=lambda kv: kv[1])[:3]),
                  f"structure {r['structure']:.1f}/{r['structure_ext']:.1f}",
                  "footprint " + " ".join(f"{k} {v:.1f}" for k, v in r["footprint"].items()))
    for r in rows:
        if r.get("twin_cause", NONE) != NONE:
            print("  twin false alarm:", r["sim"], f"seed {r['seed']} (clean twin of {r['effect']}) ->",
                  r["twin_causes"], f"load {r['load']}", f"structure {r['twin_structure']:.1f}")


def main(argv: list[str] | None = None) -> None:
    ap = _parser()
    args = ap.parse_args(argv)
    if args.floor_table:
        floor_table(args.floor_table)
        return
    if args.speed_only:
        speed()
        return
    levels = [float(x) for x in args.levels.split(",")]
    if len(set(args.without)) == 2:
        ap.error("--without: a recording needs at least one distal channel (x_out or T_out)")
    without = tuple(sorted(set(args.without)))
    cases = _cases(args, levels, without)
    t0 = time.perf_counter()
    with ProcessPoolExecutor(args.jobs) as pool:
        rows = list(pool.map(one, cases, chunksize=1))
    wall = time.perf_counter() - t0
    print(f"# diagnosis confusion matrix, {args.seed_set} seeds: {len(rows)} recordings of {args.duration:.0f} s, "
          f"levels {levels} x {args.seeds} seeds per effect, {args.clean} clean, {args.unknown} "
          f"{UNCATALOGUED}; {wall:.0f} s wall on {args.jobs} processes"
          + ("; the route known (held at each rig's true shape, not fitted)" if args.route_known else "")
          + (f"; recorded without {' and '.join(without)} (effects that need it left out)" if without else ""))
    for sim in _sims(args):
        rs = [r for r in rows if r["sim"] == sim]
        title = {"rig": "rig (study/scenarios.py, the diagnosis' own physics)",
                 "lumped": "lumped (study/lumped/scenarios.py, independent simulator)"}[sim]
        if args.family == "catalogue":
            table(rs, f"{title}, {args.seed_set} seeds")
        else:
            family_table(rs, f"{title}, {args.family} family, {args.seed_set} seeds")
    if args.verbose:
        _print_misses(rows)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(rows, fh, indent=1, default=float)


def speed() -> None:
    """Time one diagnosis of a 10-minute 1 kHz recording (after a warm-up that compiles the kernels)."""
    from study.scenarios import record
    rec = record("stiction", seed=1, level=0.5, duration=600.0, rate_hz=1000.0)
    diagnose(rec.data.slice(0, 20000))
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    t0 = time.perf_counter()
    c0 = time.process_time()
    res = diagnose(rec.data, progress=True)
    dt, cpu = time.perf_counter() - t0, time.process_time() - c0
    print(f"\nspeed: 10 min at 1 kHz ({len(rec.data)} samples) diagnosed in {dt:.1f} s wall, {cpu:.1f} s CPU "
          f"(load average {load:.1f} on {os.cpu_count()} cores; answer {res['cause']}, gain {res['gain']:.2f})")


if __name__ == "__main__":
    main()
