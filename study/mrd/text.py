"""The printed table and ``report.md`` of ``teleop analyze --mrd`` (:mod:`study.mrd.report`).

Data: MRD Lab data repository, University of Minnesota (O'Neill, Stephens, Kowalewski, IEEE RA-L
3(4):3027-3034, 2018; ODbL 1.0 / DbCL 1.0; docs/how-to/get-the-data.md).
"""
from __future__ import annotations

import math
from pathlib import Path

from estimator.offline.spindle.fit import EXTENSIONS
from recorded.mrd import MrdRun

__all__ = ["format_mrd", "write_mrd_report"]


def format_mrd(s: dict) -> str:
    """The table printed by ``teleop analyze --mrd`` (RMSE and max |error| as fractions of full scale)."""
    cal = s["calibration"]
    head = (f"calibrated on the first {cal['seconds']:g} s of each run" if cal["mode"] == "segment"
            else f"calibrated on run {cal['run']}")
    if "design_load_gain" in cal:
        dg = cal["design_load_gain"]
        if "tool" in dg:
            head += f", load gain {dg['value']:.3f} from tool {dg['tool']} (measured on {dg['measured_on']})"
        else:
            head += (f", load gain {dg['value']:.3f} from {dg['source']} (another folder's, not from these data)"
                     if "source" in dg else f", load gain {dg['value']:.3f} given (a design value, not from the data)")
    if "fixed" in cal:
        head += f" with rho = 1 / n_k = {cal['fixed']['rho']['value']:.3f} from its encoders"
    found = s["found"].values()
    freqs = ", ".join(f"{f:g}" for f in sorted({round(v["frequency_hz"], 2) for v in found}))
    cmds = sorted({round(v["load_command_A"], 3) for v in found})
    lines = [f"MRD da Vinci runs ({s['attribution']})",
             f"found {len(s['found'])} runs: sine frequencies {freqs} Hz (from the spindle angle), "
             f"{len(cmds)} load levels (front-end command {cmds[0]:g}-{cmds[-1]:g} A), "
             f"{min(v['duration_s'] for v in found):.1f}-{max(v['duration_s'] for v in found):.1f} s each",
             f"full scale {s['full_scale_Nm'] * 1e3:.1f} mN m; {head} (inputs spindle torque "
             "+ encoder, targets jaw torque + encoder); scored from each run's first reversal (the centre map once "
             "its band reading holds both edges)",
             _choice_line(s.get("model_choice")),
             f"{'run':>4}{'f [Hz]':>8}{'load':>5}{'RMSE':>7}{'max':>7}{'angle':>7}   constant   linear    phase"
             f"{'shared':>8}{'LORO':>7}"]
    for name, r in s["runs"].items():
        bl = r["baselines"]
        sh = s.get("shared", {}).get("runs", {}).get(name, {}).get("torque_rmse_fs", math.nan)
        lo = s.get("loro", {}).get("runs", {}).get(name, {}).get("torque_rmse_fs", math.nan)
        lines.append(f"{name:>4}{r['frequency_hz']:>8.3f}{r['load_level']:>5}{r['torque_rmse_fs']:>7.3f}"
                     f"{r['torque_max_fs']:>7.3f}{r['angle_rmse_deg']:>7.2f}{bl['constant']['torque_rmse_fs']:>11.3f}"
                     f"{bl['linear']['torque_rmse_fs']:>9.3f}{bl['phase']['torque_rmse_fs']:>9.3f}{sh:>8.3f}{lo:>7.3f}")
    m = s["summary"]
    lines.append(f"better than the linear baseline on every run: {m['better_than_linear_every_run']}")
    rows = {**{f"model {n}": a for n, a in m["models"].items()},
            **{f"baseline {n}": a for n, a in m["baselines"].items()}}
    for key, label in (("shared", "one parameter set (in-sample)"), ("loro", "one parameter set, leave-one-run-out")):
        if key in s:
            rows[f"{label}: {s[key]['model']}"] = s[key]["summary"]
    for n, a in rows.items():
        lines.append(f"  {n:<58} RMSE median {a['median_torque_rmse_fs']:.3f} worst {a['max_torque_rmse_fs']:.3f}, "
                     f"max |error| {a['max_torque_max_fs']:.3f} FS; angle median {a['median_angle_rmse_deg']:.2f} deg")
    for label, a in (("centre map, this calibration", m.get("centre")),
                     ("centre map, one set (in-sample)", s.get("centre_map", {}).get("summary")),
                     ("centre map, leave-one-run-out", s.get("centre_map", {}).get("loro", {}).get("summary"))):
        if a:
            lines.append(f"  {label:<58} RMSE median {a['median_torque_rmse_fs']:.3f} worst "
                         f"{a['max_torque_rmse_fs']:.3f}, max |error| {a['max_torque_max_fs']:.3f} FS")
    lg = s.get("centre_map", {}).get("load_gain")
    if lg:
        if lg["several_loads"]:
            unc = (f" (jackknife SE {lg['jackknife_se']:.3f}; left out {lg['leave_one_run_out_range'][0]:.3f}-"
                   f"{lg['leave_one_run_out_range'][1]:.3f})" if "jackknife_se" in lg else "")
            lines.append(f"load gain across this folder's loads {lg['value']:.3f}{unc}, b_0 {lg['b_0']:.3f}: "
                         "pass it to another tool of this model as --calibration gain=G:RUN (or gain=<this JSON>:RUN)")
        else:
            lines.append("load gain across this folder's loads: not identifiable (one load level)")
    wg = s.get("centre_calibration", {}).get("within_run_gain")
    fw = s.get("centre_map", {}).get("within_run_gain", {}).get("summary")
    if wg or fw:
        part = []
        if wg:
            lo, hi = (1.0 / v if v > 0 else math.inf for v in wg["profile_ci95"][::-1])
            part.append(f"calibration run {wg['gain']:.3f} (95 % {lo:.2f}-{hi:.2f})")
        if fw:
            part.append(f"over the runs {fw['gain_min']:.2f}-{fw['gain_max']:.2f} "
                        f"against {fw.get('folder_gain', math.nan):.3f} fitted across loads "
                        f"({fw.get('runs_within_4pc_of_folder_gain', 0)} of {len(s['found'])} within 4 %)")
        lines.append("load gain from one run's own signals (not used): " + "; ".join(part))
    lines.append("not identifiable from the spindle side alone: " + ", ".join(s["not_from_proximal"]))
    lines.append("extensions: " + "; ".join(f"{k} ({v[0]})" for k, v in EXTENSIONS.items()))
    lines.append(f"analysed in {s['elapsed_s']:.1f} s")
    return "\n".join(lines)



def _choice_line(c: dict | None) -> str:
    """The headline's model and the calibration-only scores it was chosen by."""
    if not c:
        return "RMSE / max / angle: the pair model"
    if len(c["candidates"]) < 2:
        return f"RMSE / max / angle: {c['chosen']} ({c['rule']})"
    scores = ", ".join(f"{n} {v:.4f}" for n, v in c["candidates"].items())
    check = ""
    if "load_gain_check" in c:
        lc = c["load_gain_check"]
        check = "; load gain eligible (1 / gain inside the calibration runs' own reading): " + ", ".join(
            f"{n} {g:.3f} {'yes' if lc['eligible'][n] else 'no'}" for n, g in lc["implied_load_gain"].items())
        if "fallback" in lc:
            check += f"; none eligible: {c['chosen']}, the nearest to that reading"
    return (f"RMSE / max: {c['chosen']}, chosen on calibration data only (time split of the calibration runs, "
            f"torque RMSE [FS]: {scores}{check}); angle: the pair model")


def write_mrd_report(runs: list[MrdRun], summary: dict, details: dict, directory: str | Path) -> Path:
    """``report.md`` with the printed table and the figures in ``directory``; returns its path."""
    from study.mrd.figures import write_mrd_figures
    from teleop.recording.figures import output_dir
    d = output_dir(directory, "--report")
    figs = write_mrd_figures(runs, summary, details, d)
    text = ["# Jaw torque of a da Vinci tool from its spindle (teleop analyze --mrd)", "",
            f"Data: {summary['attribution']}.", "", "```", format_mrd(summary), "```", ""]
    text += [f"![{p.stem}]({p.name})" for p in figs]
    out = d / "report.md"
    out.write_text("\n".join(text) + "\n")
    return out
