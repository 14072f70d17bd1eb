"""``teleop analyze --mrd DIR``: the spindle pair model against measured jaw torque and angle.

Data: MRD Lab data repository, University of Minnesota (O'Neill, Stephens, Kowalewski, IEEE RA-L
3(4):3027-3034, 2018; ODbL 1.0 / DbCL 1.0; docs/how-to/get-the-data.md).

Protocol (docs/results/mrd.md):

* calibration ``RUN`` (default: the slowest, lightest run), ``kinematic:RUN`` (the same with the
  torque scale rho fixed to 1 / n_k, the pulley radii ratio read from the calibration run's spindle
  and jaw encoders) or ``segment:SECONDS`` (the first SECONDS of every run, scored on the rest). The model's *inputs*
  are always the spindle torque and angle; the calibration's jaw torque and angle are the fit *targets* (the spindle
  side alone cannot give the torque scale, the jaw-side offset or the friction beyond the jaw pulley; the JSON lists
  them under ``not_from_proximal``). Scored runs never contribute a distal sample. ``gain=G:`` before any run
  calibration gives the centre map a design load gain G (:func:`split_design_gain`).
* score: torque RMSE and max |error| as fractions of full scale (range of the measured jaw torque
  over the folder), angle RMSE [deg], from ``SCORE_FROM_S`` on (the load motor ramps in first).
* across the folder: model-free band measurements per run (E3 frequency, E8 load, distal-side
  friction, E12 backlash), one shared parameter set fitted on all runs and scored leave-one-run-out.
* beside the pair model, the centre map (:mod:`recorded.mrd_centre`): the load level read from the
  scored run's own spindle band centre; on the calibration (one run: gain 1 / n_k and its cost profile)
  and over the folder (in-sample and leave-one-run-out). ``--calibration mid`` picks the run whose band
  centre (spindle torque only) is nearest the middle of the folder's.
"""
from __future__ import annotations

import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from estimator.errors import DataError
from estimator.offline.spindle.fit import band_centre
from estimator.offline.spindle.shared import (
    RunData,
    kinematic_ratio,
    leave_one_out,
    load_sweep,
    select_extensions,
    shared_fit,
)
from estimator.online.spindle import (
    SpindleParams,
    first_reversal,
    make_batch,
    predict_angle,
    predict_torque,
    spindle_rate,
)
from recorded.mrd import ATTRIBUTION, MrdRun
from recorded.mrd_calibration import (
    CAL_INPUTS,
    SCORE_FROM_S,
    calibrate,
    calibrate_on_runs,
    design_gain,
    parse_calibration,
    run_data,
)
from recorded.mrd_centre import (
    CENTRE,
    centre_agg,
    centre_folder,
    profile_on_scored,
    score_centre,
)
from study.mrd.text import format_mrd
from study.mrd.tools import tool_calibration, tool_entry
from teleop.config.tools import Tool
from teleop.errors import ConfigError

__all__ = ["analyze_mrd", "band_measurements"]

SHARED_STEP = 50           # decimation of the folder-wide fits (1 kHz -> 20 Hz)
NOT_FROM_PROXIMAL = {
    "rho": "torque scale (r_d / r_p times the ratio of the two sensors' gains): one run at one load level shows "
           "the load only through rho times the load; needs at least two load levels with jaw torque",
    "b": "jaw torque at zero cable torque difference (internal preload, sensor zero): no proximal signature",
    "f": "friction beyond the jaw pulley (jaw pivot, load motor) lies inside the spindle's friction band, "
         "indistinguishable from cable friction without a jaw-side measurement",
    "theta0": "jaw zero of the distal encoder",
}


class _Progress:
    def __init__(self, enabled: bool, total: int):
        self.enabled, self.total, self.n = enabled, max(total, 1), 0

    def __call__(self, label: str) -> None:
        self.n += 1
        if self.enabled:
            k = int(30 * min(self.n, self.total) / self.total)
            sys.stderr.write(f"\ranalyze --mrd [{'#' * k}{'.' * (30 - k)}] {min(self.n, self.total)}/{self.total} "
                             f"{label:<24.24}")
            sys.stderr.flush()

    def done(self) -> None:
        if self.enabled:
            sys.stderr.write("\n")


def band_measurements(run: MrdRun, bins_deg: float = 2.0) -> dict:
    """Model-free loop measurements of one run, in spindle-angle bins over the middle 60 % of the
    stroke where both directions are in full motion (|omega| > 0.05 rad/s): the spindle torque
    band's half-width and centre [N m], the jaw torque's mean and half difference between the
    directions [N m], the jaw angle's half difference between the directions [deg]."""
    k = first_reversal(run.theta_p, run.dt, SCORE_FROM_S)
    th, tp, td, ad = run.theta_p[k:], run.tau_p[k:], run.tau_d[k:], run.theta_d[k:]
    om = spindle_rate(run.theta_p, run.dt)[k:]
    lo, hi = np.percentile(th, [20, 80])
    edges = np.arange(lo, hi, math.radians(bins_deg))
    rows = []
    for a, b in zip(edges[:-1], edges[1:], strict=False):
        m = (th >= a) & (th < b)
        up, dn = m & (om > 0.05), m & (om < -0.05)
        if up.sum() > 5 and dn.sum() > 5:
            rows.append((tp[up].mean(), tp[dn].mean(), td[up].mean(), td[dn].mean(), ad[up].mean(), ad[dn].mean()))
    if not rows:
        raise DataError(f"{run.source}: the spindle never moves both ways through the middle of its stroke")
    r = np.asarray(rows)
    return {"band_half_width_Nm": float(np.mean(np.abs(r[:, 0] - r[:, 1])) / 2),
            "band_centre_Nm": float(np.mean(r[:, 0] + r[:, 1]) / 2),
            "jaw_torque_mean_Nm": float(np.mean(r[:, 2] + r[:, 3]) / 2),
            "jaw_torque_direction_half_diff_Nm": float(np.mean(r[:, 2] - r[:, 3]) / 2),
            "jaw_angle_direction_half_diff_deg": float(math.degrees(np.mean(r[:, 4] - r[:, 5]) / 2))}


def _score(pt, pa, run: MrdRun, k0: int, fs: float) -> dict:
    e, ea = pt[k0:] - run.tau_d[k0:], pa[k0:] - run.theta_d[k0:]
    return {"torque_rmse_fs": float(np.sqrt(np.mean(e ** 2)) / fs), "torque_max_fs": float(np.max(np.abs(e)) / fs),
            "angle_rmse_deg": float(math.degrees(np.sqrt(np.mean(ea ** 2))))}


def _agg(rows: list[dict]) -> dict:
    t = [r["torque_rmse_fs"] for r in rows]
    return {"median_torque_rmse_fs": float(np.median(t)), "max_torque_rmse_fs": float(np.max(t)),
            "max_torque_max_fs": float(max(r["torque_max_fs"] for r in rows)),
            "median_angle_rmse_deg": float(np.median([r["angle_rmse_deg"] for r in rows]))}


def _one_stroke(runs: list[MrdRun]) -> None:
    """Raise DataError when the runs stroke over separate spindle-angle windows (jaw stopping positions:
    :func:`recorded.mrd.stroke_groups`), naming the windows and the ``--runs`` selection of each: the centre
    map and the pair model describe one stroke, and one window's calibration says nothing of another's."""
    from recorded.mrd import runs_selection, stroke_groups, stroke_window
    groups = stroke_groups(runs)
    if len(groups) < 2:
        return
    win = {r.name: stroke_window(r) for r in runs}
    parts = []
    for g in groups:
        a, b = min(win[n][0] for n in g), max(win[n][1] for n in g)
        parts.append(f"{round(math.degrees(a))}..{round(math.degrees(b))} deg: {runs_selection(g, list(win))} "
                     f"({len(g)} runs)")
    raise DataError(f"the runs stroke over {len(groups)} separate spindle-angle windows (jaw stopping positions); "
                    "the models describe one stroke, analyse one window at a time: " + "; ".join(parts))


def analyze_mrd(runs: list[MrdRun], calibration: str | None = None, progress: bool = False,
                loro: bool = True, folder: bool = True, tool: Tool | None = None) -> tuple[dict, dict]:
    """Calibrate, predict and score every run; the folder-wide diagnosis (module docstring).

    Returns (summary, details): summary is JSON-ready (``runs.<name>.{torque_rmse_fs, torque_max_fs,
    angle_rmse_deg}`` for the model chosen on the calibration data, ``.models.<name>`` for every model,
    ``.baselines.<name>`` the same keys; ``shared`` / ``loro`` the folder-wide fit); details hold
    per-sample predictions for the figures (never written to JSON).

    ``folder`` False, or a single run, skips the folder-wide selection and fit (and ``loro``). ``tool``: the load gain
    of the one-run calibration comes from this tool file (:func:`study.mrd.tools.tool_calibration`;
    ``summary["tool"]``). Raises DataError for no runs, ConfigError for a bad ``calibration`` or one that gives a gain
    beside ``tool``.
    """
    t_start = time.perf_counter()
    if not runs:
        raise DataError("no MRD runs to analyse")
    _one_stroke(runs)
    given, calibration, source = design_gain(tool_calibration(calibration, tool))
    mode, cal = parse_calibration(calibration, runs)
    fs = float(max(r.tau_d.max() for r in runs) - min(r.tau_d.min() for r in runs))
    n_cal = len(runs) if mode == "segment" else 1
    tick = _Progress(progress, n_cal * 14 + len(runs) + 15 + (2 * len(runs) if loro else 0))
    out = _header(runs, fs)
    details: dict[str, dict] = {"pred": {}, "shared_pred": {}, "loro_pred": {}, "k0": {}}
    cmap: Any = None
    cal_runs: list[RunData] = []
    if mode in ("run", "kinematic"):
        plan, cmap, cal_runs = calibrate_on_runs(runs, mode, str(cal), calibration, (given, source), fs, tick, out)
    else:
        plan = _calibrate_on_segments(runs, float(cal), tick, out)
    if tool is not None:
        out["tool"] = tool_entry(tool)
        out["calibration"]["design_load_gain"].update({"tool": tool.name, "measured_on": tool.load_gain.measured_on,
                                                       "uncertainty": tool.load_gain.uncertainty,
                                                       "from": f"load_gain of the tool file {tool.name}"})
    _predict(plan, mode, cmap, fs, out, details, tick)
    _summarise(out, mode, plan, cal_runs, fs)
    out["bands"] = {r.name: band_measurements(r) for r in runs}
    out["load_sweep"] = _load_sweep(runs)
    if folder and len(runs) > 1:     # one parameter set across runs, scored leave-one-run-out: two runs or more
        _shared(runs, out, details, fs, tick, loro)
    tick.done()
    out["elapsed_s"] = time.perf_counter() - t_start
    return out, details


def _header(runs: list[MrdRun], fs: float) -> dict[str, Any]:
    """The summary's fixed entries: the folder, its full scale [N m] and attribution, and what is scored from."""
    return {"mode": "mrd", "full_scale_Nm": fs, "attribution": ATTRIBUTION, "not_from_proximal": NOT_FROM_PROXIMAL,
            "scored_from": "the first reversal of the spindle after 0.5 s (the stroke before it initialises the "
                           "estimator, as the paper's calibration pull does); the centre map from the first sample "
                           "after it at which its band-centre reading holds both edges (centre_ready: before, "
                           "the centre rests on one edge and the calibration's half-width, its initialisation; "
                           "the score from the first reversal is kept under centre.from_k0)", "runs": {},
            "found": {r.name: {"frequency_hz": r.frequency_hz, "load_level": r.load_level,
                               "load_command_A": r.load_command, "n_samples": len(r),
                               "duration_s": float(r.time[-1])} for r in runs}}


def _calibrate_on_segments(runs: list[MrdRun], cal: float, tick, out: dict) -> list:
    """Calibrate each run on its first ``cal`` seconds [s] and record the calibration in ``out``; returns the plan."""
    plan = []
    out["model_choice"] = {"rule": "segment calibration: the pair model only (the centre map reads the load "
                                   "level across runs; it has no per-run segment calibration)",
                           "candidates": {"pair model (selected per run)": None}, "chosen": "pair model"}
    out["calibration"] = {"mode": "segment", "seconds": cal, **CAL_INPUTS,
                          "scored": f"t >= {cal} s of the same run, from its spindle signals only"}
    out["parameters"] = {}
    for r in runs:
        n = int(round(float(cal) / r.dt))
        fits, base, sel, centre, ref = calibrate([run_data(r, n)], tick)
        plan.append((r, fits, base, centre, ref, n))
        out["parameters"][r.name] = {k: p.as_dict() for k, p in fits.items()}
    return plan


def _predict(plan: list, mode: str, cmap: Any, fs: float, out: dict, details: dict, tick) -> None:
    """Predict and score every planned run with each calibrated model and baseline (``out["runs"]``)."""
    for r, fits, base, centre, ref, k0 in plan:
        b = make_batch([(r.tau_p, r.theta_p)], centre, ref, r.dt)
        models = {}
        for name, p in fits.items():
            pt, pa = predict_torque(p, b), predict_angle(p, b)
            models[name] = _score(pt, pa, r, k0, fs)
            details["pred"][r.name] = (pt, pa)          # the last one is the selected model
        pair = list(fits)[-1]
        bl = {}
        for n, m in base.items():
            bt_, ba_ = m.predict(b)
            bl[n] = _score(bt_, ba_, r, k0, fs)
        row = {"frequency_hz": r.frequency_hz, "load_level": r.load_level, "model": pair, **models[pair],
               "models": models, "baselines": bl}
        if mode != "segment":
            row["centre"] = score_centre(cmap, run_data(r), k0, fs)
            if out["model_choice"]["chosen"] == CENTRE:     # torque from the centre map; it has no angle estimate
                row.update(model=CENTRE, angle_from=pair, torque_rmse_fs=row["centre"]["torque_rmse_fs"],
                           torque_max_fs=row["centre"]["torque_max_fs"])
        out["runs"][r.name] = row
        details["k0"][r.name] = k0
        tick(f"predict {r.name}")


def _summarise(out: dict, mode: str, plan: list, cal_runs: list[RunData], fs: float) -> None:
    """The scores aggregated over the scored runs (``out["summary"]``) and the centre map's cost profile."""
    scored = list(out["runs"].values())
    names = sorted({n for s in scored for n in s["models"]})
    out["summary"] = {"model": _agg(scored),
                      "models": {n: _agg([s["models"][n] for s in scored if n in s["models"]]) for n in names},
                      "baselines": {n: _agg([s["baselines"][n] for s in scored]) for n in scored[0]["baselines"]},
                      "better_than_linear_every_run": bool(all(
                          s["torque_rmse_fs"] < s["baselines"]["linear"]["torque_rmse_fs"] for s in scored))}
    if mode != "segment":
        out["summary"]["centre"] = {**_agg([{**s["centre"], "angle_rmse_deg": math.nan} for s in scored]),
                                    "from_k0": centre_agg([s["centre"]["from_k0"] for s in scored]),
                                    "better_than_linear_every_run": bool(all(s["centre"]["torque_rmse_fs"] < s[
                                        "baselines"]["linear"]["torque_rmse_fs"] for s in scored))}
        del out["summary"]["centre"]["median_angle_rmse_deg"]
        profile_on_scored(cal_runs, [(run_data(r), k0) for r, *_, k0 in plan], fs, out["centre_calibration"])


def _load_sweep(runs: list[MrdRun]) -> dict:
    """The band edges against the jaw torque across loads (:func:`load_sweep`, one group per frequency) beside
    the kinematic ratio n_k; {} when no frequency has two loads. A diagnosis on every run's jaw channels."""
    groups: dict[float, list[RunData]] = {}
    for r in runs:
        groups.setdefault(round(r.frequency_hz, 2), []).append(run_data(r))
    if max(len(g) for g in groups.values()) < 2:
        return {}
    sw = load_sweep(list(groups.values()))
    n_k = kinematic_ratio([d for g in groups.values() for d in g])
    return {**sw, "n_k": n_k, "r_over_n_k": sw["r"] / n_k,
            "uses": "jaw torque and encoder of every run (folder diagnosis, not a calibration)"}


def _shared(runs, out, details, fs, tick, loro: bool) -> None:
    """Extensions chosen on a time split of all runs, one parameter set for the folder, leave-one-run-out."""
    rd = [run_data(r) for r in runs]
    centre = float(np.mean([band_centre(r.tau_p) for r in runs]))
    ref = float(np.mean([np.mean(r.theta_p) for r in runs]))
    sel = select_extensions(rd, centre, ref, SHARED_STEP, progress=tick)
    free = tuple(sel["chosen"])
    p = shared_fit(rd, free, centre, ref, SHARED_STEP, start=SpindleParams(**sel["params"]))
    tick("shared fit")
    sh: dict[str, Any] = {"model": "pair" + "".join("+" + c for c in free), "selection": sel, "parameters": p.as_dict(),
          "fitted_on": "every run from its first reversal (in-sample)", "runs": {}}
    for r, d in zip(runs, rd, strict=False):
        b = make_batch([(r.tau_p, r.theta_p)], centre, ref, r.dt)
        pt, pa = predict_torque(p, b), predict_angle(p, b)
        sh["runs"][r.name] = _score(pt, pa, r, d.k0, fs)
        details["shared_pred"][r.name] = (pt, pa)
        details["k0"].setdefault(r.name, d.k0)
    sh["summary"] = _agg(list(sh["runs"].values()))
    out["shared"] = sh
    out["centre_map"] = centre_folder(rd, fs, tick, loro)
    if not loro:
        return
    lo: dict[str, Any] = {"model": sh["model"],
                          "note": "extensions chosen on the time split of all runs; parameters refitted "
                                  "without the scored run", "runs": {}, "parameters": {}}
    for r, d, (q, pt, pa) in zip(runs, rd, leave_one_out(rd, free, centre, ref, p, SHARED_STEP, progress=tick),
                                 strict=False):
        lo["runs"][r.name] = _score(pt, pa, r, d.k0, fs)
        lo["parameters"][r.name] = q.as_dict()
        details["loro_pred"][r.name] = (pt, pa)
    lo["summary"] = _agg(list(lo["runs"].values()))
    out["loro"] = lo


def main_mrd(args) -> int:
    """``teleop analyze --mrd [DIR] [--tool NAME] [--calibration RUN|segment:SECONDS] [--json OUT] [--figures DIR]
    [--report DIR]``: load, analyse (window by window when the runs stroke over separate spindle-angle windows,
    :mod:`study.mrd.windows`), print; one line per unreadable file. Returns 0."""
    import json

    from recorded.mrd import load_mrd_dir, stroke_groups
    from study.mrd.windows import analyze_windows, write_outputs
    from teleop.config.tools import load_tool

    if args.json is not None and not Path(args.json).resolve().parent.is_dir():
        raise ConfigError(f"--json {args.json}: directory {Path(args.json).resolve().parent} does not exist")
    from study.mrd.model_file import check_model_out, write_mrd_model
    check_model_out(args)
    tool = load_tool(args.tool) if getattr(args, "tool", None) else None
    runs, bad = load_mrd_dir(args.mrd or None, getattr(args, "runs", None))
    for line in bad:
        print(f"skipped: {line}")
    cal, progress = getattr(args, "calibration", None), sys.stderr.isatty()
    if len(stroke_groups(runs)) > 1:
        if getattr(args, "model_out", None) is not None:
            raise ConfigError(f"--model-out {args.model_out}: the runs stroke over separate spindle-angle windows; "
                              "choose one window's runs with --runs GLOB")
        summary = analyze_windows(analyze_mrd, runs, cal, tool, progress, args)
    else:
        summary, details = analyze_mrd(runs, cal, progress=progress, tool=tool)
        print(format_mrd(summary))
        write_outputs(runs, summary, details, args)
        if getattr(args, "model_out", None) is not None:
            print(f"wrote {write_mrd_model(args, runs, summary)}")
    summary["skipped"] = bad
    if args.json is not None:
        Path(args.json).write_text(json.dumps(summary, indent=2, allow_nan=False,
                                              default=lambda o: o.item() if hasattr(o, "item") else str(o)) + "\n")
        print(f"wrote {args.json}")
    return 0
