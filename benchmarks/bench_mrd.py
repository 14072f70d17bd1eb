"""`teleop analyze --mrd` speed on the MRD da Vinci folder (20 runs of 20 s at 1 kHz).

Runs ``teleop analyze --mrd DIR --json OUT`` as a separate process pinned to one thread
(OMP/MKL/OpenBLAS/NUMBA threads = 1) and prints its wall and CPU time against the 60 s goal of the
issue; then the import and the analysis timed in-process. DIR defaults to the MRD data of the data folder
(``TSM_TELEOP_DATA``, docs/how-to/get-the-data.md); skips (prints why and what to do) when it is absent. Data: MRD Lab
data repository, University of Minnesota (ODbL 1.0 / DbCL 1.0). Prints figures, never fails on them.

    .venv/bin/python benchmarks/bench_mrd.py [--dir DIR] [--calibration RUN|segment:SECONDS]
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ONE_THREAD = {k: "1" for k in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS", "NUMBA_NUM_THREADS")}
os.environ.update(ONE_THREAD)
ROOT = Path(__file__).resolve().parents[1]

from recorded.folders import MRD, skip_reason  # noqa: E402 - after the thread settings
from recorded.mrd import load_mrd_dir  # noqa: E402 - after the thread settings
from recorded.mrd_files import default_mrd_dir  # noqa: E402 - after the thread settings
from study.mrd.report import analyze_mrd  # noqa: E402 - after the thread settings

GOAL_S = 60.0


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dir", default=str(default_mrd_dir()))
    ap.add_argument("--calibration", default=None)
    args = ap.parse_args([] if argv is None else argv)
    if not Path(args.dir).is_dir():
        print(f"bench_mrd: skipped, {skip_reason(MRD, args.dir)}")
        return
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "mrd.json"
        cmd = [sys.executable, "-m", "live.cli", "analyze", "--mrd", args.dir, "--json", str(out)]
        if args.calibration:
            cmd += ["--calibration", args.calibration]
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True, cwd=ROOT, env={**os.environ, **ONE_THREAD}, stdout=subprocess.DEVNULL)
        wall = time.perf_counter() - t0
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
        s = json.loads(out.read_text())
    print(f"teleop analyze --mrd (one thread): wall {wall:.1f} s, CPU {cpu:.1f} s, goal {GOAL_S:.0f} s -> "
          f"{'ok' if cpu < GOAL_S else 'over'}; {len(s['bands'])} runs; left-out median torque RMSE "
          f"{s['loro']['summary']['median_torque_rmse_fs']:.3f} FS (pair model), "
          f"{s['centre_map']['loro']['summary']['median_torque_rmse_fs']:.3f} FS (centre map)")
    lo = s["centre_map"]["loro"]["summary"]
    print(f"centre map left out (scored once its band-centre reading holds both edges): median "
          f"{lo['median_torque_rmse_fs']:.3f} / worst {lo['max_torque_rmse_fs']:.3f} / "
          f"largest {lo['max_torque_max_fs']:.3f} FS; from the first reversal "
          f"{lo['from_k0']['median_torque_rmse_fs']:.3f} / {lo['from_k0']['max_torque_rmse_fs']:.3f} "
          f"/ {lo['from_k0']['max_torque_max_fs']:.3f}")
    mc = s["model_choice"]
    lc = mc.get("load_gain_check", {})
    print(f"headline model: {mc['chosen']} (calibration time split, torque RMSE [FS]: "
          + ", ".join(f"{n} {v:.3f}" for n, v in mc["candidates"].items())
          + "; load gain implied / eligible: "
          + ", ".join(f"{n} {g:.3f} {'yes' if lc['eligible'][n] else 'no'}"
                      for n, g in lc.get("implied_load_gain", {}).items())
          + f"); headline median {s['summary']['model']['median_torque_rmse_fs']:.3f} / worst "
          f"{s['summary']['model']['max_torque_rmse_fs']:.3f} / largest "
          f"{s['summary']['model']['max_torque_max_fs']:.3f} FS")
    t0 = time.perf_counter()
    runs, _ = load_mrd_dir(args.dir)
    t1 = time.perf_counter()
    analyze_mrd(runs, args.calibration)
    t2 = time.perf_counter()
    print(f"in process: import {t1 - t0:.1f} s, analysis {t2 - t1:.1f} s (wall)")


if __name__ == "__main__":
    main(sys.argv[1:])
