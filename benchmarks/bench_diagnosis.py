"""Diagnosis benchmark: the confusion matrix over hidden effects, magnitudes and seeds; speed.

Every catalogue effect is hidden at several magnitudes (positions in its realistic range, see
slave/scenarios.py) and seeds, plus clean recordings; each recording is diagnosed and the answer
compared with the hidden effect. Prints the accuracy per effect, the overall accuracy, the false-alarm
rate on clean data, the held-out gains, and the time for a 10-minute 1 kHz recording. Prints figures,
never fails on them (the pass/fail checks are in tests/estimator/test_diagnosis.py).

    .venv/bin/python benchmarks/bench_diagnosis.py [--seeds 4] [--levels 0,0.5,1] [--duration 90]
                                                  [--rate 1000] [--jobs 2] [--skip-speed]
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from collections import Counter, defaultdict
from concurrent.futures import ProcessPoolExecutor

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from estimator.diagnosis import diagnose  # noqa: E402
from estimator.effects import EFFECT_IDS, NONE  # noqa: E402
from slave.scenarios import UNCATALOGUED, record  # noqa: E402


def one(case: tuple[str, float | None, int, float, float]) -> dict:
    effect, level, seed, duration, rate = case
    rec = record(None if effect == NONE else effect, seed=seed, level=level, duration=duration, rate_hz=rate)
    t0 = time.perf_counter()
    res = diagnose(rec.data)
    return {"effect": effect, "level": rec.truth["level"], "seed": seed, "cause": res["cause"],
            "causes": res["causes"], "gain": res["gain"], "seconds": time.perf_counter() - t0,
            "truth": rec.truth["parameters"], "fitted": {k: v["value"] for k, v in res["parameters"].items()},
            "scores": {k: round(v["score"], 3) for k, v in res["candidates"].items()},
            "structure": max(res["structure"]["base"].values())}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--levels", default="0,0.5,1", help="magnitude positions in the realistic range")
    ap.add_argument("--clean", type=int, default=24, help="clean recordings (seeds)")
    ap.add_argument("--duration", type=float, default=90.0)
    ap.add_argument("--rate", type=float, default=1000.0)
    ap.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1))
    ap.add_argument("--skip-speed", action="store_true")
    ap.add_argument("--speed-only", action="store_true", help="only time a 10-minute 1 kHz recording")
    ap.add_argument("--verbose", action="store_true")
    ap.add_argument("--only", default="", help="comma-separated hidden effects to run (default: all)")
    args = ap.parse_args(argv)
    if args.speed_only:
        speed()
        return
    levels = [float(x) for x in args.levels.split(",")]
    cases = [(e, lv, 100 + s, args.duration, args.rate) for e in EFFECT_IDS for lv in levels for s in range(args.seeds)]
    cases += [(NONE, None, 500 + s, args.duration, args.rate) for s in range(args.clean)]
    cases += [(u, lv, 900 + s, args.duration, args.rate) for u in UNCATALOGUED for lv in levels for s in range(2)]
    if args.only:
        cases = [c for c in cases if c[0] in args.only.split(",")]
    t0 = time.perf_counter()
    with ProcessPoolExecutor(args.jobs) as pool:
        rows = list(pool.map(one, cases, chunksize=1))
    wall = time.perf_counter() - t0

    by = defaultdict(list)
    for r in rows:
        by[r["effect"]].append(r)
    print(f"# diagnosis confusion matrix: {len(rows)} recordings of {args.duration:.0f} s at {args.rate:.0f} Hz, "
          f"levels {levels} x {args.seeds} seeds per effect, {args.clean} clean; {wall:.0f} s wall on {args.jobs} "
          f"processes, {np.mean([r['seconds'] for r in rows]):.2f} s mean diagnosis time\n")
    print(f"| hidden effect | n | accuracy | min gain | median gain | answers |")
    print(f"|---|---|---|---|---|---|")
    correct = total = 0
    for eff in list(EFFECT_IDS) + [NONE] + list(UNCATALOGUED):
        rs = by.get(eff, [])
        if not rs:
            continue
        want = "unknown" if eff in UNCATALOGUED else eff
        ok = [r["cause"] == want for r in rs]
        gains = [r["gain"] for r in rs if r["cause"] == want and eff not in (NONE,) + UNCATALOGUED]
        ans = ", ".join(f"{k} {v}" for k, v in Counter(r["cause"] for r in rs).most_common())
        g = f"{min(gains):.2f} | {np.median(gains):.2f}" if gains else "- | -"
        print(f"| {eff} | {len(rs)} | {np.mean(ok):.2f} | {g} | {ans} |")
        if eff in EFFECT_IDS or eff == NONE:
            correct += sum(ok)
            total += len(ok)
    clean = by.get(NONE, [])
    fa = np.mean([r["cause"] != NONE for r in clean]) if clean else float("nan")
    print(f"\noverall accuracy (catalogue + clean): {correct / max(total, 1):.3f}  ({correct}/{total})")
    print(f"false-alarm rate on clean data: {fa:.3f}  ({sum(r['cause'] != NONE for r in clean)}/{len(clean)})")
    if clean:
        best = [min(r["scores"].values()) for r in clean]
        print(f"clean data: lowest candidate score S {min(best):.3f} (median {np.median(best):.3f}; an extension "
              f"needs S + price < 1), highest base structure ratio {max(r['structure'] for r in clean):.2f}")
    hit = [r["scores"][r["effect"]] for r in rows if r["effect"] in EFFECT_IDS]
    if hit:
        print(f"hidden effects: score S of the right extension, median {np.median(hit):.3f}, worst {max(hit):.3f}")
    low = [r for r in rows if r["effect"] in EFFECT_IDS and r["cause"] == r["effect"] and r["gain"] < 0.3]
    print(f"correct answers with held-out gain < 0.3: {len(low)}")
    if args.verbose:
        for r in rows:
            if r["cause"] != ("unknown" if r["effect"] in UNCATALOGUED else r["effect"]):
                print("  miss:", r["effect"], f"level {r['level']:.2f} seed {r['seed']} ->", r["causes"],
                      f"gain {r['gain']:.2f}", r["truth"], r["scores"])
    if not args.skip_speed:
        speed()


def speed() -> None:
    """Time one diagnosis of a 10-minute 1 kHz recording (after a warm-up that compiles the kernels)."""
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
