"""Every folder of the MRD Lab repository through `teleop analyze --mrd`, with and without a sister folder's load gain.

The study behind docs/results/mrd.md: the source repository (https://github.com/MRDLab/
mis-tool-characterization, commit 03658b2; ODbL 1.0 / DbCL 1.0; "MRD Lab data repository, University of Minnesota";
O'Neill, Stephens, Kowalewski, IEEE RA-L 3(4):3027-3034, 2018) holds fifteen folders of one rig. Point ``--repo`` at
a clone (its root or its ``data/`` folder; docs/how-to/get-the-data.md), read in place, nothing copied. Each folder is
split into its stroke windows (:func:`recorded.mrd.stroke_groups`: the roll and pitch folders stop the jaw at several
positions) and each window is analysed twice, in process and one thread:

* the default calibration (the slowest, lightest run, no number from outside), with the folder fit and its
  leave-one-run-out, which also measures the window's own load gain across its loads (``centre_map.load_gain``);
* ``gain=G:mid``: one run and the load gain G of another folder (``--gain JSON`` written by ``teleop analyze --mrd
  OTHER --json JSON``, or ``--gain-value G``; default: the shipped folder's, measured first).

Prints one row per window and the pooled lines; ``--json OUT`` keeps the rows. Prints figures, never fails on them.
About 25 min on one thread for all fifteen folders (the two 50-run folders take 2 min per pass).

    .venv/bin/python benchmarks/study_mrd_folders.py --repo CLONE [--only NAME,NAME] [--gain JSON] [--json OUT]
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
from pathlib import Path

ONE_THREAD = {k: "1" for k in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS", "NUMBA_NUM_THREADS")}
os.environ.update(ONE_THREAD)
ROOT = Path(__file__).resolve().parents[1]

from recorded.folders import MRD, skip_reason  # noqa: E402 - after the thread settings
from recorded.mrd import load_mrd_dir, runs_selection, stroke_groups  # noqa: E402 - after the thread settings
from recorded.mrd_files import default_mrd_dir  # noqa: E402 - after the thread settings
from study.mrd.report import analyze_mrd  # noqa: E402 - after the thread settings

#: The one-run calibration's target: median and worst-run torque RMSE [fraction of full scale].
LINE = (0.03, 0.10)


def _windows(folder: Path) -> list[tuple[str, list]]:
    runs, bad = load_mrd_dir(folder)
    for line in bad:
        print(f"  skipped: {line}")
    groups = stroke_groups(runs)
    by = {r.name: r for r in runs}
    if len(groups) == 1:
        return [(folder.name, runs)]
    return [(f"{folder.name} [{runs_selection(g, list(by))}]", [by[n] for n in g]) for g in groups]


def _row(name: str, runs: list, gain: float) -> dict:
    d, _ = analyze_mrd(runs)
    g, _ = analyze_mrd(runs, f"gain={gain!r}:mid", folder=False)
    lg, lo = d["centre_map"]["load_gain"], d["centre_map"]["loro"]["summary"]
    m, md = g["summary"]["model"], d["summary"]["model"]
    return {"window": name, "runs": len(runs), "full_scale_Nm": d["full_scale_Nm"],
            "load_gain": lg["value"], "load_gain_se": lg.get("jackknife_se"), "several_loads": lg["several_loads"],
            "one_run": {"run": g["calibration"]["run"], "median": m["median_torque_rmse_fs"],
                        "worst": m["max_torque_rmse_fs"], "largest": m["max_torque_max_fs"],
                        "better_than_linear": sum(r["torque_rmse_fs"] < r["baselines"]["linear"]["torque_rmse_fs"]
                                                  for r in g["runs"].values()), "scored": len(g["runs"])},
            "default": {"run": d["calibration"]["run"], "chosen": d["model_choice"]["chosen"],
                        "median": md["median_torque_rmse_fs"], "worst": md["max_torque_rmse_fs"]},
            "left_out": {"median": lo["median_torque_rmse_fs"], "worst": lo["max_torque_rmse_fs"]}}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repo", required=True, help="a clone (its root or data/: one sub-folder per tool and setting)")
    ap.add_argument("--only", default=None, help="comma-separated folder names (default: every sub-folder)")
    ap.add_argument("--gain", default=None, help="JSON of `teleop analyze --mrd OTHER --json JSON` (its load gain)")
    ap.add_argument("--gain-value", type=float, default=None, help="the load gain itself")
    ap.add_argument("--json", default=None, help="write the rows here")
    args = ap.parse_args(argv)
    repo = Path(args.repo)
    repo = repo / "data" if (repo / "data").is_dir() else repo
    if not repo.is_dir():
        print(f"study_mrd_folders: skipped, {skip_reason(MRD, repo)}")
        return
    if args.gain_value is not None:
        gain, source = args.gain_value, "--gain-value"
    elif args.gain is not None:
        gain, source = json.loads(Path(args.gain).read_text())["centre_map"]["load_gain"]["value"], args.gain
    else:
        ship, _ = analyze_mrd(load_mrd_dir(default_mrd_dir())[0], folder=True, loro=False)
        gain, source = ship["centre_map"]["load_gain"]["value"], f"{default_mrd_dir()} (the shipped folder)"
    print(f"load gain given to every one-run calibration: {gain:.4f} from {source}")
    names = args.only.split(",") if args.only else sorted(p.name for p in repo.iterdir() if p.is_dir())
    rows = []
    print(f"{'window':<46}{'runs':>5}{'gain':>7}{'SE':>7}   one run + G: median / worst / largest, >linear"
          f"   default (chosen)         left out")
    for n in names:
        for name, runs in _windows(repo / n):
            r = _row(name, runs, gain)
            rows.append(r)
            o, d, lo = r["one_run"], r["default"], r["left_out"]
            se = f"{r['load_gain_se']:.3f}" if r["load_gain_se"] is not None else "-"
            print(f"{name:<46}{r['runs']:>5}{r['load_gain']:>7.3f}{se:>7}   {o['median']:.3f} / {o['worst']:.3f} / "
                  f"{o['largest']:.3f}, {o['better_than_linear']}/{o['scored']}        {d['median']:.3f} / "
                  f"{d['worst']:.3f} ({d['chosen']})   {lo['median']:.3f} / {lo['worst']:.3f}", flush=True)
    if not rows:
        return
    gains = [r["load_gain"] for r in rows if r["several_loads"]]
    met = [r for r in rows if r["one_run"]["median"] <= LINE[0] and r["one_run"]["worst"] <= LINE[1]]
    print(f"windows {len(rows)}; load gain across loads: mean {statistics.mean(gains):.3f}, range {min(gains):.3f}-"
          f"{max(gains):.3f}, {sum(abs(g / gain - 1.0) <= 0.04 for g in gains)} within +-4 % of {gain:.3f}")
    print(f"one run + G: the line (median <= {LINE[0]}, worst <= {LINE[1]} FS) met on {len(met)} of {len(rows)}, "
          f"with every scored run better than linear on "
          f"{sum(r['one_run']['better_than_linear'] == r['one_run']['scored'] for r in met)}")
    print(f"default: median {min(r['default']['median'] for r in rows):.3f}-"
          f"{max(r['default']['median'] for r in rows):.3f}"
          f" FS; left out: median {min(r['left_out']['median'] for r in rows):.3f}-"
          f"{max(r['left_out']['median'] for r in rows):.3f} FS")
    if args.json:
        Path(args.json).write_text(json.dumps({"gain": gain, "gain_from": source, "rows": rows}, indent=1) + "\n")
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
