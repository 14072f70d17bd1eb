"""Diagnosis benchmark of the lab conditions: hand motion and nonlinear or contact loads, on both simulators.

Families, each scored per simulator (``study/scenarios.py`` the rig, ``study/lumped/scenarios.py`` the lumped one):

* ``hand``: operator-like motion (``record(..., motion="hand")``: random moves with holds, up to 25 mm/s) with a
  pretension or velocity friction hidden (the acceptance effects), beside the effects that look like them under
  that motion (an x_in offset, a T_out lag) and clean recordings;
* ``tissue``, ``contact``: clean recordings on nonlinear (stiffening) tissue and on free space then contact, under
  the protocol and under hand motion (answer ``none``).

Seed sets (``SEED_BASE``): ``hdev``, ``hdev2``, ``hdev3``, ``hfinal`` and ``hfinal2`` are development data (the
rules are chosen on them); ``hfinal3`` is held out (diagnosed once by the frozen rules, never tuned on). Effect k
of :data:`HAND_EFFECTS`, level j, repeat s uses base + 1000 k + 10 j + s; clean recordings base + 500 + s (hand),
base + 600 + s (tissue), base + 700 + s (contact).

    .venv/bin/python benchmarks/bench_diagnosis_hand.py [--sim rig|lumped|both] [--set hdev|...|hfinal3]
        [--seeds 4] [--levels 0.2,0.8] [--clean 4] [--duration 60] [--jobs 2] [--only ID,...] [--json OUT]

Prints per family and hidden effect the share named right with its 95 % interval and what was named, and for a
hidden effect the share among the visible recordings (footprint against the clean twin) and the misses' footprints;
never fails on the figures.
"""
from __future__ import annotations

import argparse
import json
import os
import time
from collections import Counter, defaultdict
from concurrent.futures import ProcessPoolExecutor

from bench_diagnosis import footprint
from diagnosis_tables import VISIBLE_SIGMAS, peak_footprint, proportion_interval

from estimator.offline.diagnosis.selection import diagnose
from estimator.offline.effects.types import NONE

#: seed offset of each set: ``hdev`` ... ``hfinal2`` (development data) and ``hfinal3`` (held out)
SEED_BASE = {"hdev": 7000000, "hdev2": 7100000, "hdev3": 7200000, "hfinal": 7500000, "hfinal2": 8600000,
             "hfinal3": 8700000}
#: hidden effects under hand motion: the acceptance pair first, then their look-alikes under that motion
HAND_EFFECTS = ("pretension", "velocity_friction", "sensor_offset:x_in", "sensor_lag:T_out")


def _record(sim: str):
    if sim == "rig":
        from study.scenarios import record
    else:
        from study.lumped.scenarios import record
    return record


def one(case: tuple) -> dict:
    """Diagnose one recording: (sim, family, effect, level, seed, duration, motion, load)."""
    sim, family, effect, level, seed, duration, motion, load = case
    kw = {"seed": seed, "level": level, "duration": duration, "motion": motion}
    if load:
        kw["load"] = load
    if sim == "rig":
        kw["rate_hz"] = 1000.0
    rec = _record(sim)(None if effect == NONE else effect, **kw)
    # the clean twin (same seed, rig, motion and noise): how far the hidden effect moves the recording
    fp = {} if effect == NONE else footprint(rec.data, _record(sim)(None, **kw).data)
    t0 = time.perf_counter()
    try:
        res = diagnose(rec.data)
        cause, causes = res["cause"], res["causes"]
    except Exception as err:            # noqa: BLE001 - a recording the diagnosis cannot take counts as a miss
        cause, causes = f"error: {type(err).__name__}: {err}", ["error"]
        res = {}
    return {"sim": sim, "family": family, "effect": effect, "level": rec.truth["level"], "seed": seed,
            "motion": motion, "load": load or "", "cause": cause, "causes": causes,
            "seconds": time.perf_counter() - t0, "truth": rec.truth["parameters"],
            "scores": {k: round(v["score"], 3) for k, v in res.get("candidates", {}).items()},
            "structure": res.get("structure", {}), "footprint": fp}


def cases(sims: tuple[str, ...], seed_set: str, seeds: int, levels: list[float], clean: int,
          duration: float) -> list[tuple]:
    """The recordings of a run (module docstring for the seeds)."""
    b = SEED_BASE[seed_set]
    out: list[tuple] = []
    for sim in sims:
        out += [(sim, "hand", e, lv, b + 1000 * k + 10 * j + s, duration, "hand", None)
                for k, e in enumerate(HAND_EFFECTS) for j, lv in enumerate(levels) for s in range(seeds)]
        out += [(sim, "hand", NONE, None, b + 500 + s, duration, "hand", None) for s in range(clean)]
        for fam, off in (("tissue", 600), ("contact", 700)):
            out += [(sim, fam, NONE, None, b + off + s, duration, ("protocol", "hand")[s % 2], fam)
                    for s in range(clean)]
    return out


def report(rows: list[dict]) -> None:
    """Per simulator, family and hidden effect: right / n, the 95 % interval and the answers; for a hidden effect
    also right / n among the visible recordings (footprint against the clean twin above VISIBLE_SIGMAS noise sigmas
    on some channel) and each miss's footprint."""
    by: dict[tuple, list[dict]] = defaultdict(list)
    for r in rows:
        by[(r["sim"], r["family"], r["effect"])].append(r)
    for (sim, fam, eff), rs in sorted(by.items()):
        k = sum(r["cause"] == eff for r in rs)
        lo, hi = proportion_interval(k, len(rs))
        answers = Counter(r["cause"] for r in rs if r["cause"] != eff)
        line = (f"{sim:6s} {fam:8s} {eff:20s} {k:3d} / {len(rs):3d}  ({lo:.2f}-{hi:.2f})  "
                + ", ".join(f"{a} {n}" for a, n in answers.most_common()))
        if eff != NONE:
            vis = [r for r in rs if peak_footprint(r) > VISIBLE_SIGMAS]
            misses = ", ".join(f"{peak_footprint(r):.1f}" for r in rs if r["cause"] != eff)
            line += (f"; visible {sum(r['cause'] == eff for r in vis)} / {len(vis)}"
                     + (f", misses' footprints [sigma] {misses}" if misses else ""))
        print(line)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sim", choices=("rig", "lumped", "both"), default="both")
    ap.add_argument("--set", choices=tuple(SEED_BASE), default="hdev", dest="seed_set")
    ap.add_argument("--seeds", type=int, default=4, help="seeds per effect and level")
    ap.add_argument("--levels", default="0.2,0.8", help="magnitude positions in the realistic range")
    ap.add_argument("--clean", type=int, default=4, help="clean recordings per family")
    ap.add_argument("--duration", type=float, default=60.0)
    ap.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1))
    ap.add_argument("--only", default="", help="comma-separated hidden effects or families (default: all)")
    ap.add_argument("--json", default="", help="write every row as JSON to this file")
    args = ap.parse_args(argv)
    sims = ("rig", "lumped") if args.sim == "both" else (args.sim,)
    levels = [float(x) for x in args.levels.split(",")]
    todo = cases(sims, args.seed_set, args.seeds, levels, args.clean, args.duration)
    if args.only:
        keep = set(args.only.split(","))
        todo = [c for c in todo if c[2] in keep or c[1] in keep]
    t0 = time.perf_counter()
    with ProcessPoolExecutor(args.jobs) as pool:
        rows = list(pool.map(one, todo, chunksize=1))
    print(f"# hand motion and loads, {args.seed_set} seeds: {len(rows)} recordings of {args.duration:.0f} s, levels "
          f"{levels} x {args.seeds} seeds per effect, {args.clean} clean per family; "
          f"{time.perf_counter() - t0:.0f} s wall on {args.jobs} processes")
    report(rows)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(rows, fh, indent=1, default=float)


if __name__ == "__main__":
    main()
