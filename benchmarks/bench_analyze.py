"""`teleop analyze` speed: a 10-minute 1 kHz recording with a hidden effect, diagnosed and reported.

Generates the recording with :func:`study.scenarios.record` (not timed), writes it as a measured-data CSV, then runs
``teleop analyze FILE --json OUT --report DIR`` ``--runs`` times as a separate process pinned to one thread
(OMP/MKL/OpenBLAS/NUMBA threads = 1) and prints each run's wall time (the first may fill numba's cache) and their
median, split into reading, diagnosis and report from the same steps run in-process (the rest of the wall time is
the command's start), and the machine's speed on a fixed reference (the plain memory kernel over 100000 samples, best
of 5, before and after the runs), by which figures taken on different machines or days compare: a shared VM's speed
varies from one to the next, and within a run. Prints figures, never fails on them.

    .venv/bin/python benchmarks/bench_analyze.py [--minutes 10] [--rate 1000] [--effect friction_offset] [--runs 3]
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ONE_THREAD = {k: "1" for k in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS", "NUMBA_NUM_THREADS")}
os.environ.update(ONE_THREAD)           # before numpy loads: the in-process split runs on one thread too
ROOT = Path(__file__).resolve().parents[1]

import numpy as np  # noqa: E402 - after the thread settings

from estimator.offline.diagnosis.selection import diagnose  # noqa: E402 - after the thread settings
from estimator.offline.effects.kernels import run_extended  # noqa: E402 - after the thread settings
from estimator.sheath import SheathModel  # noqa: E402 - after the thread settings
from study.report import write_report  # noqa: E402 - after the thread settings
from study.scenarios import record  # noqa: E402 - after the thread settings
from teleop.recording.measured import write_measured_csv  # noqa: E402 - after the thread settings
from teleop.recording.measured_csv import read_measured_csv  # noqa: E402 - after the thread settings


def reference_ms(n: int = 100_000, nodes: int = 33, repeats: int = 5) -> float:
    """The machine's speed: the plain memory kernel over ``n`` samples of a fixed triangle-wave pull on ``nodes``
    nodes, best of ``repeats`` runs after a warm-up [ms]."""
    t = np.arange(n) * 1e-3
    T_in = 10.0 + 8.0 * (2.0 / np.pi) * np.arcsin(np.sin(2.0 * np.pi * 0.5 * t))
    v = np.gradient(T_in, t) * 1e-4
    u, w = SheathModel(K=1.0, compliance=1.0).nodes(nodes - 1)       # a uniform wrap: the trapezoid rule
    best = float("inf")
    for _ in range(repeats + 1):
        t0 = time.perf_counter()
        run_extended(T_in, v, t, u, w, K=1.0)
        best = min(best, time.perf_counter() - t0)
    return 1e3 * best


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=10.0)
    ap.add_argument("--rate", type=float, default=1000.0)
    ap.add_argument("--effect", default="friction_offset")
    ap.add_argument("--runs", type=int, default=3, help="timed runs of the command (default 3)")
    args = ap.parse_args([] if argv is None else argv)
    ref_before = reference_ms()
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        rec = record(args.effect, seed=1, level=0.5, duration=60.0 * args.minutes, rate_hz=args.rate)
        csv = d / "run.csv"
        write_measured_csv(csv, rec.data)
        mb = csv.stat().st_size / 1e6
        # the CLI as a user runs it, one thread
        env = {**os.environ, **ONE_THREAD}
        cmd = [sys.executable, "-m", "live.cli", "analyze", str(csv), "--json", str(d / "d.json"),
               "--report", str(d / "report")]
        walls = []
        for _ in range(max(args.runs, 1)):
            t0 = time.perf_counter()
            proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True)
            walls.append(time.perf_counter() - t0)
            if proc.returncode != 0:
                print(f"teleop analyze failed ({proc.returncode}): {proc.stderr.strip()}")
                return
        res = json.loads((d / "d.json").read_text())
        # the same steps in-process, for the split (numba caches are warm by now)
        t0 = time.perf_counter()
        data = read_measured_csv(csv)
        t1 = time.perf_counter()
        result = diagnose(data)
        t2 = time.perf_counter()
        write_report(result, data, d / "report2")
        t3 = time.perf_counter()
    n = len(rec.data)
    print(f"teleop analyze, {args.minutes:g} min at {args.rate:g} Hz ({n} samples, {mb:.0f} MB CSV, hidden "
          f"{args.effect}): {float(np.median(walls)):.1f} s wall on one thread (median of {len(walls)}: "
          f"{', '.join(f'{w:.1f}' for w in walls)} s), cause {res['cause']}, gain {res['gain']:.2f} "
          f"(model choice at {res['settings']['selection_rate_hz']:.0f} Hz, refit and test at "
          f"{res['settings']['target_rate_hz']:.0f} Hz)")
    rest = float(np.median(walls)) - (t3 - t0)
    print(f"  in-process split: read {t1 - t0:.1f} s, diagnose {t2 - t1:.1f} s, report {t3 - t2:.1f} s; the rest of "
          f"the median wall time, {rest:.1f} s, is the command's start (the interpreter and its imports)")
    print(f"  machine reference: the plain memory kernel, 100000 samples on 33 nodes: {ref_before:.1f} ms before, "
          f"{reference_ms():.1f} ms after")


if __name__ == "__main__":
    main(sys.argv[1:])
