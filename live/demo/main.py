"""``teleop demo``: the whole system end to end on one machine, then an accuracy summary, for any instrument.

One flow (:func:`main_demo`) for a single tendon (``configs/sim.yaml``, the default) and for a joint
instrument (``--config configs/instrument-3dof.yaml``); the same processes and node classes run
both (:class:`slave.node.SlaveNode`, :class:`master.node.MasterNode` over the instrument's axes):

1. ``runs/<id>/`` (id = timestamp) gets the resolved config with ``calibration.dir`` set to
   ``runs/<id>/calibration``; on a machine of fewer than
   :data:`teleop.timing.realtime.CO_LOCATED_MIN_CPUS` CPUs the sides' ``realtime_priority`` is 0 there, said in
   one line (:func:`live.demo.run.co_located`; ``--keep-realtime`` keeps the configured priorities);
2. ``teleop calibrate`` (in this process, simulated as fast as it computes) runs the instrument's
   power-up routine (a tendon pulled into its joint limit, a pair both directions, a spindle over its
   stroke) and writes ``runs/<id>/calibration/<id>.yaml``:
   the calibration life cycle of every instrument, the slave reloads that file at start. With
   another rig (``rig.type: zenoh``, e.g. ``teleop bridge``) the file is missing and the slave
   calibrates at power-up through the rig, then saves it there;
3. the slave (``python -m live.cli slave``: simulated rig, estimators, CSV + Rerun) listens
   on a free TCP port on 127.0.0.1; once the port accepts connections the master (``... master``:
   scripted operator, ``--protocol``) connects. Both are OS processes talking Zenoh
   (:func:`live.demo.run.run_processes`). When the master has finished its protocol it
   announces STOPPING and the slave exits too; either running past ``--timeout`` is stopped with
   SIGTERM (recordings are flushed) and reported;
4. the instrument's evaluation: a single tendon (:class:`TendonDemo`) per experiment (marker 1 =
   paper's, 2 = minor loops) and per estimator (the online profile-memory estimate recorded in
   ``slave.csv``; the paper's phase formulas re-run over the recorded T_in with the calibrated K
   and L/EA) the full-scale errors of the distal tension and the elongation (max and mean of
   |estimate - truth| over the range of the true signal in the experiment), the haptic loop's
   chatter and transparency (:mod:`teleop.timing.loop_metrics`) and a figure; a joint instrument
   (:class:`live.demo.joints.JointDemo`) per joint and pulled tendon the full-scale errors
   of the distal joint torque and the angle errors (``slave_joints.csv``). Both report the
   calibration against the simulator's true K and M_e;
5. a table is printed and ``summary.json`` written: the evaluation, the master's console (engage,
   clutch, align counts, safe events, largest force) and recording, the latency and overruns of
   both sides, the checks.
"""
from __future__ import annotations

import argparse
import dataclasses
import shutil
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from estimator.capstan import phase_formula_batch
from estimator.errors import DataError
from live.demo.run import (
    check_protocol,
    co_located,
    finish,
    full_scale_errors,
    loop_lines,
    master_console_line,
    read_json,
    run_processes,
    verdict_lines,
)
from live.kinds import kind_of
from teleop.config.files import resolve_config, shipped_config
from teleop.config.load import load_config, write_config
from teleop.config.schema import Config
from teleop.recording.measured_csv import read_measured_csv

__all__ = ["PAPER_BOUNDS", "baseline_deadband", "evaluate", "checks", "TendonDemo", "demo_kind", "format_summary",
           "main_demo"]

#: The seed paper's reported accuracy: max force error, max elongation error, mean error (full scale).
PAPER_BOUNDS = {"force_error_max_fs": 0.07, "elongation_error_max_fs": 0.03, "mean_error_fs": 0.02}
EXPERIMENTS = {1: "paper", 2: "minor"}
DEFAULT_CONFIG = shipped_config("sim.yaml")     # configs/sim.yaml of the checkout, or of the installed package
DEFAULT_TIMEOUT = 50.0       # [s] --timeout of a simulated instrument's demo
RECORDING_MARGIN = 120.0     # [s] --timeout past a recording's length: the slave's calibration fit and the start-up


def baseline_deadband(cfg: Config) -> float:
    """Reversal deadband of the paper-formula baseline [N]: 10 load-cell noise sigmas, at least 0.1 N.

    A running extremum of noisy samples sits ~3.5 sigma out and a later sample ~3.5 sigma the other
    way, so a smaller band declares reversals on noise alone and is unfair to the baseline.
    """
    return max(0.1, 10.0 * cfg.rig.simulated.sensors.load_cell_noise)


def evaluate(csv_path: str | Path, calibration: dict, cfg: Config) -> dict:
    """Full-scale errors per experiment and estimator from the slave's recording.

    Parameters
    ----------
    csv_path : path of ``slave.csv`` (columns of :data:`slave.tendon_axis.CSV_COLUMNS`, with truth).
    calibration : the contents of ``calibration.json`` (``K``, ``compliance_m_per_N``).
    cfg : the run's config (baseline deadband from the load-cell noise).

    Returns
    -------
    dict
        ``{"paper": {"profile_memory": {...}, "paper_formulas": {...}, "samples": n, "duration_s": ...,
        "force_full_scale_N": ..., "elongation_full_scale_m": ...}, "minor": {...}}``, each estimator
        with ``force_error_max_fs``, ``force_error_mean_fs``, ``elongation_error_max_fs``,
        ``elongation_error_mean_fs``.

    Raises
    ------
    DataError
        The CSV is unreadable or lacks the truth or estimate columns.
    """
    data = read_measured_csv(csv_path)
    need = ("marker", "T_out_hat", "elongation_hat")
    missing = [c for c in need if c not in data.extra]
    if data.T_out is None or data.x_out is None or missing:
        raise DataError(f"{csv_path}: needs truth columns x_out, T_out and estimate columns {', '.join(need)}")
    elong = data.extra.get("elongation", data.x_in - data.x_out)
    marker = data.extra["marker"].astype(int)
    T_pf, e_pf, _ = phase_formula_batch(data.T_in, float(calibration["K"]), float(calibration["compliance_m_per_N"]),
                                        deadband=baseline_deadband(cfg))
    out: dict = {}
    for m, name in EXPERIMENTS.items():
        sel = marker == m
        if not sel.any():
            continue
        T, e = data.T_out[sel], elong[sel]
        row: dict[str, Any] = {"samples": int(sel.sum()), "duration_s": float(data.time[sel][-1] - data.time[sel][0]),
               "force_full_scale_N": float(np.ptp(T)), "elongation_full_scale_m": float(np.ptp(e))}
        for est, T_hat, e_hat in (("profile_memory", data.extra["T_out_hat"][sel], data.extra["elongation_hat"][sel]),
                                  ("paper_formulas", T_pf[sel], e_pf[sel])):
            fmax, fmean = full_scale_errors(T_hat, T)
            emax, emean = full_scale_errors(e_hat, e)
            row[est] = {"force_error_max_fs": fmax, "force_error_mean_fs": fmean,
                        "elongation_error_max_fs": emax, "elongation_error_mean_fs": emean,
                        "force_rmse_N": float(np.sqrt(np.mean((T_hat - T) ** 2)))}
        out[name] = row
    return out


def checks(experiments: dict) -> dict[str, bool]:
    """The demo's acceptance checks, for the experiments that were run (NaN errors fail).

    paper: the profile-memory estimator within the paper's 0.07 (force) and 0.03 (elongation) of
    full scale; minor: its max errors below those of the paper's formulas, force and elongation.
    """
    res: dict[str, bool] = {}
    p = experiments.get("paper", {}).get("profile_memory")
    if p:
        res["paper: profile-memory force error max <= 0.07 FS"] = bool(p["force_error_max_fs"] <= 0.07)
        res["paper: profile-memory elongation error max <= 0.03 FS"] = bool(p["elongation_error_max_fs"] <= 0.03)
    m = experiments.get("minor", {})
    a, b = m.get("profile_memory"), m.get("paper_formulas")
    if a and b:
        for q in ("force", "elongation"):
            k = f"{q}_error_max_fs"
            res[f"minor: profile memory beats paper formulas on {q} (max error)"] = bool(a[k] < b[k])
    return res


def _calibration_summary(calib: dict, cfg: Config) -> dict:
    from slave.simulated import SimulatedRig
    rig = SimulatedRig.from_config(cfg)
    K, M_e = float(calib["K"]), float(calib["M_e_m_per_N"])
    return {"K": K, "K_true": rig.K, "K_error_rel": K / rig.K - 1.0,
            "M_e_m_per_N": M_e, "M_e_true_m_per_N": rig.M_e, "M_e_error_rel": M_e / rig.M_e - 1.0,
            "knee_T_in_N": calib.get("knee_T_in_N"), "use_route": calib.get("use_route")}


class TendonDemo:
    """What the demo evaluates and prints for a single tendon (module docstring, step 4)."""

    files = ("slave.csv (measured-data format, truth + estimates per cycle)", "master.csv")

    @staticmethod
    def evaluate(summary: dict, run_dir: Path, cfg: Config, problems: list[str]) -> dict[str, bool]:
        """Fill ``summary`` (calibration, experiments, figure, haptic loop); the checks."""
        summary.update({"baseline_deadband_N": baseline_deadband(cfg), "paper_bounds": PAPER_BOUNDS})
        calib = read_json(run_dir / "calibration.json")
        if calib:
            summary["calibration"] = _calibration_summary(calib, cfg)
            try:
                summary["experiments"] = evaluate(run_dir / "slave.csv", calib, cfg)
                if summary["experiments"]:
                    from live.demo.figures import demo_figure
                    summary["figure"] = str(demo_figure(run_dir / "slave.csv", calib, baseline_deadband(cfg),
                                                        run_dir / "estimates.png", EXPERIMENTS))
            except DataError as e:
                problems.append(str(e))
            try:            # chatter and transparency of the haptic loop (teleop/timing/loop_metrics.py)
                from teleop.timing.loop_metrics import run_loop_metrics
                summary["haptic_loop"] = run_loop_metrics(run_dir, cfg.master.mapping.force_scale, EXPERIMENTS)
            except DataError as e:
                problems.append(str(e))
        else:
            problems.append(f"no calibration.json in {run_dir}: the slave did not start")
        if calib and not summary.get("experiments") and not problems:
            problems.append("the recording has no experiment rows (marker 1 or 2): the protocol did not run")
        from teleop.timing.loop_metrics import chatter_checks
        return {**checks(summary.get("experiments", {})), **chatter_checks(summary.get("haptic_loop", {}))}

    @staticmethod
    def lines(s: dict) -> list[str]:
        """The evaluation's lines of the printed table."""
        L = []
        c = s.get("calibration")
        if c:
            L.append(f"calibration   K   = {c['K']:.4f}       (simulator {c['K_true']:.4f}, "
                     f"{100 * c['K_error_rel']:+.1f} %)")
            L.append(f"              M_e = {c['M_e_m_per_N']:.4e} m/N (simulator {c['M_e_true_m_per_N']:.4e}, "
                     f"{100 * c['M_e_error_rel']:+.1f} %)")
        L.append("")
        L.append("full-scale errors      estimator        force max  force mean  elong max  elong mean")
        for name, row in s.get("experiments", {}).items():
            title = f"{name} ({row['duration_s']:.1f} s)"
            for i, est in enumerate(("profile_memory", "paper_formulas")):
                r = row[est]
                L.append(f"{title if i == 0 else '':22s} {est.replace('_', ' '):16s} {r['force_error_max_fs']:9.3f} "
                         f"{r['force_error_mean_fs']:11.3f} {r['elongation_error_max_fs']:10.3f} "
                         f"{r['elongation_error_mean_fs']:11.3f}")
            L.append(f"{'':22s} {'paper reports':16s} {0.07:9.3f} {'<0.02':>11s} {0.03:10.3f} {'<0.02':>11s}")
        L.append(f"(full scale = range of the true signal in the experiment; paper-formula reversal deadband "
                 f"{s.get('baseline_deadband_N', float('nan')):.2f} N)")
        L += _tension_rmse_lines(s)
        if s.get("haptic_loop"):
            from teleop.timing.loop_metrics import loop_metric_lines
            L.append("")
            L += loop_metric_lines(s["haptic_loop"])
        return L


def _tension_rmse_lines(s: dict) -> list[str]:
    """The live estimate's distal-tension RMSE against the simulator's truth per experiment and, with a model file,
    its id, hash and run: the figures two runs (with and without a model) compare."""
    rows = [f"{name} {row['profile_memory']['force_rmse_N']:.4f} N" for name, row in s.get("experiments", {}).items()
            if "force_rmse_N" in row.get("profile_memory", {})]
    m, ran = s.get("model"), s.get("slave", {}).get("model")
    L = [f"distal tension RMSE, live estimate vs truth: {', '.join(rows)}"] if rows else []
    if m:
        runs = "" if not ran else f"; {ran['cycles']} cycles, {ran['fallbacks']} fell back to the base estimator"
        L.append(f"model {m['id']} (sha256 {m['sha256'][:12]}..., {Path(m['path']).name}): the live estimate is "
                 f"the model file's{runs}")
    else:
        L.append("model: none (the base estimator)")
    return L


def demo_kind(cfg: Config) -> Any:
    """The evaluation of the configured instrument: :class:`TendonDemo`, or
    :class:`live.demo.joints.JointDemo`: the instrument kind's (:mod:`live.kinds`), a recording's own."""
    if cfg.rig.type == "recording":
        from live.demo.recording import RecordingDemo
        return RecordingDemo
    if kind_of(cfg).demo == "joints":
        from live.demo.joints import JointDemo
        return JointDemo
    return TendonDemo


def rerun_command() -> str:
    """How to start the Rerun viewer installed with this package: ``rerun`` when it is on PATH, else the
    executable beside this Python's (a virtual environment that is not activated)."""
    if shutil.which("rerun"):
        return "rerun"
    beside = Path(sys.executable).parent / "rerun"
    return str(beside) if beside.is_file() else "rerun"


def format_summary(s: dict) -> str:
    """The printed table of a summary dict (see :func:`main_demo`), for either kind of instrument."""
    joints = s.get("kind") == "joints"
    if joints:
        from live.demo.joints import JointDemo
    kind: Any = JointDemo if joints else TendonDemo
    if s.get("kind") == "recording":
        from live.demo.recording import RecordingDemo
        kind = RecordingDemo
    axes = ", ".join(s.get("axes", ()))
    L = [f"teleop demo ({s.get('instrument', '?')}: {axes}): {s['run_dir']}", ""]
    L += kind.lines(s)
    L.append("")
    L.append(master_console_line(s.get("master", {})))
    L += loop_lines(s, detailed=True)
    L.append("")
    L += verdict_lines(s)
    L.append("")
    rec = s.get("master", {}).get("recording") or f"{s['run_dir']}/master.csv"
    L.append(f"recording: {s['run_dir']}/{s.get('slave_file') or kind.files[0]}; master: {rec}")
    L.append(f"rerun:     open with `{rerun_command()} {s['run_dir']}/slave.rrd {s['run_dir']}/master.rrd` "
             f"(no display: docs/how-to/rerun-view.md)")
    if s.get("figure"):
        L.append(f"figure:    {s['figure']}  (distal tension and elongation: truth vs estimates)")
    L.append(f"summary:   {s['run_dir']}/summary.json")
    return "\n".join(L)


def main_demo(args) -> int:
    """``teleop demo``: returns 0 when the run finished and every check passed, else 1 (module docstring)."""
    from live.calibrate import run_calibrate
    from live.sides import prepare_run_dir
    from slave.calibration_file import calibration_path
    from teleop.config.bounds import waiver_lines, waivers
    cfg_path = resolve_config(args.config) if args.config else (DEFAULT_CONFIG if DEFAULT_CONFIG.is_file() else None)
    from teleop.arms import is_bimanual
    timeout_given = getattr(args, "timeout", None) is not None
    if not timeout_given:
        args.timeout = DEFAULT_TIMEOUT
    if cfg_path is not None and is_bimanual(cfg_path):       # two arms, two hands: live/demo/bimanual.py
        if getattr(args, "model", None):
            raise ValueError(f"--model {args.model}: {cfg_path} is bimanual; set estimator.model in an arm's config")
        from live.demo.bimanual import main_bimanual
        return main_bimanual(args, Path(cfg_path))
    cfg = load_config(cfg_path)
    from live.demo.recording import with_recording
    cfg = with_recording(cfg, args)     # --rig / --recording: a recording checked before any process starts
    from slave.estimator_model import configured_model, with_model
    cfg = with_model(cfg, getattr(args, "model", None))     # --model over estimator.model
    model = configured_model(cfg)       # the model file checked before any process starts (one line, exit 2)
    check_protocol(cfg, args.protocol)
    if cfg.rig.type == "recording" and not timeout_given:   # the slave plays the whole recording after its fit
        from recorded.detect import recorded_motion
        args.timeout = float(recorded_motion(cfg)[0][-1]) + RECORDING_MARGIN
    for line in waiver_lines(cfg):
        print(line, flush=True)
    run_dir = prepare_run_dir(args, cfg)
    kind = demo_kind(cfg)
    # the run's own calibration file, made now and reloaded by the slave; the sides' CSVs get every cycle (the
    # evaluation's chatter above 30 Hz needs them; the demo lasts seconds, recording.csv_every bounds long sessions)
    cfg = dataclasses.replace(cfg, calibration=dataclasses.replace(cfg.calibration, dir=str(run_dir / "calibration")),
                              recording=dataclasses.replace(cfg.recording, csv_every=1))
    cfg, scheduling = (cfg, None) if getattr(args, "keep_realtime", False) else co_located(cfg)
    if scheduling is not None:
        print(scheduling, flush=True)
    cfg_file = write_config(cfg, run_dir / "config.yaml")
    t0 = time.monotonic()
    problems: list[str] = []
    names = [j.name for j in cfg.instrument.joints] or ["tendon"]
    summary: dict = {"run_dir": str(run_dir), "config": str(cfg_file), "instrument": cfg.instrument.id,
                     "kind": kind_of(cfg).summary, "axes": names,
                     "protocol": args.protocol, "calibration_file": str(calibration_path(cfg)),
                     "safety_waivers": waivers(cfg),   # teleop/config/bounds.py: keys run past their hard bound
                     "scheduling": scheduling or "as configured",
                     "model": None if model is None else {"id": model.model_id, "sha256": model.sha256,
                                                          "path": model.path}}
    try:
        if cfg.rig.type == "simulated":      # another rig: the slave calibrates at power-up (file missing)
            from slave.kinds import axis_kind
            print(f"calibrating {cfg.instrument.id} ({', '.join(names)}): {axis_kind(cfg).routine_text} ...",
                  flush=True)
            run_calibrate(argparse.Namespace(config=str(cfg_file), out=None))
        doing = "the slave fits its calibration (rig.recording.calibration_run), then plays the recording; the " \
            "operator retraces its motion" if cfg.rig.type == "recording" else None
        run_processes(args, cfg_file, run_dir, problems, bridge=cfg.rig.type == "zenoh", doing=doing)
    except KeyboardInterrupt:
        print(f"teleop demo: interrupted; partial recordings in {run_dir}", file=sys.stderr)
        raise
    summary["master"] = read_json(run_dir / "master_stats.json")
    summary["slave"] = read_json(run_dir / "slave_stats.json")
    verdicts = kind.evaluate(summary, run_dir, cfg, problems)
    return finish(summary, verdicts, problems, t0, run_dir, format_summary)
