"""Every run of an MRD folder through the live path (``rig.type: recording``), beside ``teleop analyze --mrd``.

The slave's recording rig and recorded spindle axis (slave/recording/rig.py, slave/recording/spindle.py) play each
run in process, one cycle per recorded sample (1 kHz), with the calibration the slave fits on start (the tool
file's rule, ``mid``, with its load gain). The offline figure of each run is ``teleop analyze --mrd DIR --tool
NAME``'s own (:func:`study.mrd.report.analyze_mrd`, same calibration run and load gain, the folder-wide fits
off). Prints per run the live jaw-torque RMSE [FS], the offline one and their difference, the median and worst
over the scored runs (the calibration run is in-sample and listed apart), and the step time of the loop (rig
step and estimate, p50 / p99 / max, and the share over the 1 ms period; wall time and the thread's CPU time, which
leaves out what other processes take on a shared machine). DIR defaults to the folder Tool_4_Maryland_L_2 of the
data folder (``TSM_TELEOP_DATA``, docs/how-to/get-the-data.md); skips (prints why and what to do) when it is
absent. Data: MRD Lab data repository, University of Minnesota (ODbL 1.0 / DbCL 1.0). Prints figures, never
fails on them.

    .venv/bin/python benchmarks/bench_recording_rig.py [--dir DIR] [--tool NAME] [--runs GLOB]

``--kaist [DIR]`` plays the KAIST recordings instead (slave/recording/pair.py: the pair axis's online estimator on
each configuration's test cycle, beside the offline seed pair model on the same cycles); ``--extended JSON`` (the
JSON of ``teleop analyze --kaist --json OUT``) adds the offline analysis's extended model and what leaving it
out costs in degrees.
"""
from __future__ import annotations

import argparse
import dataclasses
import os
import time
from pathlib import Path

ONE_THREAD = {k: "1" for k in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS", "NUMBA_NUM_THREADS")}
os.environ.update(ONE_THREAD)
ROOT = Path(__file__).resolve().parents[1]

import numpy as np  # noqa: E402 - after the thread settings

from live.demo.recording_score import play_run, score_run  # noqa: E402
from recorded.folders import KAIST, MRD, skip_reason  # noqa: E402
from recorded.mrd import load_mrd_dir  # noqa: E402
from recorded.mrd_files import DEFAULT_FOLDER, mrd_folder  # noqa: E402
from slave.recording.spindle import fit_recorded_model  # noqa: E402
from study.mrd.report import analyze_mrd  # noqa: E402
from teleop.config.load import load_config  # noqa: E402
from teleop.config.tools import load_tool  # noqa: E402

PERIOD_S = 1e-3


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dir", default=str(mrd_folder(DEFAULT_FOLDER)))
    ap.add_argument("--tool", default="davinci-maryland-left")
    ap.add_argument("--runs", default=None, help="only the runs whose name matches this glob")
    ap.add_argument("--kaist", nargs="?", const="", default=None, metavar="DIR")
    ap.add_argument("--extended", default=None, metavar="JSON")
    args = ap.parse_args(argv)
    if args.kaist is not None:
        kaist(args.kaist or None, args.extended)
        return
    if not Path(args.dir).is_dir():
        print(f"bench_recording_rig: skipped, {skip_reason(MRD, args.dir)}")
        return
    runs, _ = load_mrd_dir(args.dir, args.runs)
    base = load_config(ROOT / "configs" / "recording-mrd.yaml")
    cfg = dataclasses.replace(base, instrument=dataclasses.replace(base.instrument, tool=args.tool),
                              rig=dataclasses.replace(base.rig, recording=dataclasses.replace(
                                  base.rig.recording, path=runs[0].source)))
    t0 = time.perf_counter()
    model = fit_recorded_model(cfg)
    t_fit = time.perf_counter() - t0
    t0 = time.perf_counter()
    offline, _ = analyze_mrd(runs, None, tool=load_tool(args.tool), folder=False, loro=False)
    t_off = time.perf_counter() - t0
    fs = float(offline["full_scale_Nm"])
    cal = Path(model.run).stem
    print(f"MRD folder {args.dir} ({len(runs)} runs), tool {args.tool}; calibrated on run {cal} "
          f"(live fit {t_fit:.1f} s, offline analysis {t_off:.1f} s, run {offline['calibration']['run']}); "
          f"torque from the {model.chosen}; full scale {fs * 1e3:.1f} mN m")
    print(" run   live RMSE  offline RMSE  live-offline  angle [deg]  step p50/p99/max [ms]")
    rows, steps, cpus = [], [], []
    for r in runs:
        played = play_run(cfg, model, r)
        s = score_run(cfg, model, r, fs, played)
        steps.append(played.step_s)
        cpus.append(played.cpu_s)
        off = offline["runs"].get(r.name, {}).get("torque_rmse_fs", float("nan"))
        d = s["live_rmse_fs"] - off
        tag = "  (calibration run, in-sample)" if r.name == cal else ""
        print(f"  {r.name}   {s['live_rmse_fs']:8.4f}  {off:11.4f}  {d:+12.4f}  {s['angle_rmse_deg']:10.2f}   "
              f"{s['step_p50_s'] * 1e3:.3f}/{s['step_p99_s'] * 1e3:.3f}/{s['step_max_s'] * 1e3:.1f}{tag}")
        if r.name != cal:
            rows.append((s["live_rmse_fs"], off, d))
    a = np.asarray(rows)
    st, cp = np.concatenate(steps), np.concatenate(cpus)
    print(f"scored runs {len(rows)}: live RMSE median {np.median(a[:, 0]):.4f} worst {a[:, 0].max():.4f} FS; "
          f"offline median {np.median(a[:, 1]):.4f} worst {a[:, 1].max():.4f} FS; "
          f"max |live - offline| {np.abs(a[:, 2]).max():.4f} FS")
    print(f"step time over {st.size} cycles: p50 {np.percentile(st, 50) * 1e3:.3f} ms, "
          f"p99 {np.percentile(st, 99) * 1e3:.3f} ms, "
          f"max {st.max() * 1e3:.1f} ms; {np.mean(st > PERIOD_S) * 100:.2f} % over the {PERIOD_S * 1e3:.0f} ms period")
    print(f"CPU time per cycle (the wall time less what other processes took): "
          f"p50 {np.percentile(cp, 50) * 1e3:.3f} ms, p99 {np.percentile(cp, 99) * 1e3:.3f} ms, "
          f"max {cp.max() * 1e3:.1f} ms; {np.mean(cp > PERIOD_S) * 100:.3f} % over the period; "
          f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")


def kaist(directory: str | None, extended: str | None) -> None:
    """The KAIST table (module docstring)."""
    import json

    from recorded.kaist import load_all
    from recorded.kaist_files import default_kaist_dir, find_configs
    from slave.recording.pair import kaist_live
    d = Path(directory) if directory else default_kaist_dir()
    if not find_configs(d):
        print(f"bench_recording_rig --kaist: skipped, {skip_reason(KAIST, d)}")
        return
    ext = {}
    if extended:
        ext = {c["config_deg"]: c["diagnosis"]["extended"]["rmse_test_deg"]
               for c in json.loads(Path(extended).read_text())["configurations"]}
    print(f"KAIST {d}: distal angle RMSE [deg] on command cycle 2, calibrated on cycle 1")
    print("config  live (pair axis)  offline seed pair  live-offline  offline extended  left out costs")
    for rec in load_all(d):
        r = kaist_live(rec, ext.get(rec.config_deg))
        tail = (f"  {r['extended_offline_rmse_deg']:15.2f}  {r['left_out_cost_deg']:+13.2f}"
                if "extended_offline_rmse_deg" in r else "")
        print(f"{rec.config_deg:6}  {r['live_rmse_deg']:16.2f}  {r['seed_offline_rmse_deg']:17.2f}  "
              f"{r['live_rmse_deg'] - r['seed_offline_rmse_deg']:+12.2f}{tail}")


if __name__ == "__main__":
    main()
