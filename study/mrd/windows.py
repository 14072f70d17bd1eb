"""``teleop analyze --mrd DIR`` on a folder whose runs stroke over separate spindle-angle windows.

The source repository's roll and pitch folders stop the jaw at several positions (runs ``ZXY.TXT``, Z the
position): the runs of one position stroke over one window of the spindle angle, and a calibration at one
position says nothing of the friction path at another. Such a folder is split into its windows
(:func:`recorded.mrd.stroke_groups`) and each window is analysed on its own, with its own calibration run chosen by
the same rule (``--calibration`` is applied to every window) and its own full scale: one table per window, then
a summary across them (every scored run of every window).
"""
from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from recorded.mrd import ATTRIBUTION, MrdRun, runs_selection, stroke_groups, stroke_window
from study.mrd.text import format_mrd, write_mrd_report
from teleop.config.tools import Tool

__all__ = ["analyze_windows", "format_across", "write_outputs"]


def _window(group: list[str], runs: list[MrdRun]) -> dict[str, Any]:
    """Label, run names and spindle-angle window [deg] of one group of run names."""
    win = [stroke_window(r) for r in runs if r.name in group]
    lo, hi = math.degrees(min(w[0] for w in win)), math.degrees(max(w[1] for w in win))
    sel = runs_selection(group, [r.name for r in runs])
    return {"label": f"{round(lo)}..{round(hi)} deg ({sel})", "runs": group, "spindle_window_deg": [lo, hi],
            "selection": sel}


def analyze_windows(analyze: Callable[..., tuple[dict, dict]], runs: list[MrdRun], calibration: str | None,
                    tool: Tool | None, progress: bool, outputs: Any = None) -> dict[str, Any]:
    """Analyse each stroke window of ``runs`` (``analyze``: :func:`study.mrd.report.analyze_mrd`, on its runs),
    print its table, write its figures and report (``outputs``: the parsed arguments, :func:`write_outputs`) and
    return the JSON-ready summary: ``windows`` (one entry per window, its whole summary under ``summary``) and
    ``across``.

    Raises ConfigError when ``calibration`` names a run that is not in every window (give a rule: the default
    or ``mid``), DataError as ``analyze``.
    """
    groups = stroke_groups(runs)
    windows = []
    for i, g in enumerate(groups):
        w = _window(g, runs)
        sub = [r for r in runs if r.name in g]
        print(f"window {i + 1} of {len(groups)}: spindle {w['label']}, {len(sub)} runs")
        summary, details = analyze(sub, calibration, progress=progress, tool=tool)
        print(format_mrd(summary))
        if outputs is not None:
            write_outputs(sub, summary, details, outputs, f"window{i + 1}")
        windows.append({**w, "summary": summary})
    out = {"mode": "mrd-windows", "attribution": ATTRIBUTION, "windows": windows, "across": _across(windows),
           "why": "the runs stroke over separate spindle-angle windows (jaw stopping positions); the models describe "
                  "one stroke, so each window is calibrated and scored on its own"}
    print(format_across(out))
    return out


def _across(windows: list[dict]) -> dict[str, Any]:
    """Every scored run of every window: pooled median and worst torque RMSE [FS], the largest |error|, the window
    medians, and whether every run beats the linear baseline."""
    rows = [r for w in windows for r in w["summary"]["runs"].values()]
    t = [r["torque_rmse_fs"] for r in rows]
    return {"windows": len(windows), "scored_runs": len(rows), "median_torque_rmse_fs": float(np.median(t)),
            "max_torque_rmse_fs": float(np.max(t)), "max_torque_max_fs": float(max(r["torque_max_fs"] for r in rows)),
            "window_medians": [w["summary"]["summary"]["model"]["median_torque_rmse_fs"] for w in windows],
            "window_worst": [w["summary"]["summary"]["model"]["max_torque_rmse_fs"] for w in windows],
            "better_than_linear_every_run": bool(all(
                r["torque_rmse_fs"] < r["baselines"]["linear"]["torque_rmse_fs"] for r in rows)),
            "full_scale": "each window's own (the range of its measured jaw torque)"}


def format_across(s: dict) -> str:
    """The summary lines printed after the windows' tables."""
    a = s["across"]
    lines = [f"across {a['windows']} stroke windows ({a['scored_runs']} scored runs, each scored against its "
             f"window's full scale): torque RMSE median {a['median_torque_rmse_fs']:.3f} worst "
             f"{a['max_torque_rmse_fs']:.3f}, max |error| {a['max_torque_max_fs']:.3f} FS; better than the linear "
             f"baseline on every run: {a['better_than_linear_every_run']}"]
    for w, m, x in zip(s["windows"], a["window_medians"], a["window_worst"], strict=False):
        cal = w["summary"]["calibration"]
        on = cal["run"] if "run" in cal else f"the first {cal['seconds']:g} s of each run"
        lines.append(f"  window {w['label']:<32} calibrated on {on:<6} RMSE median {m:.3f} worst {x:.3f}")
    return "\n".join(lines)


def write_outputs(runs: list[MrdRun], summary: dict, details: dict, args: Any, sub: str | None = None) -> None:
    """The figures (``args.figures``) and Markdown report (``args.report``) of one analysis, in ``DIR/sub`` when
    ``sub`` is given (one sub-folder per window)."""
    from study.mrd.figures import write_mrd_figures
    figures, report = getattr(args, "figures", None), getattr(args, "report", None)
    if figures:
        for p in write_mrd_figures(runs, summary, details, Path(figures) / sub if sub else Path(figures)):
            print(f"wrote {p}")
    if report is not None:
        print(f"wrote {write_mrd_report(runs, summary, details, Path(report) / sub if sub else Path(report))}")
