"""Figures and the Markdown report of ``teleop analyze --mrd`` (summary plots, docs/results/mrd.md).

* ``mrd_loops.png``     jaw torque against jaw angle, measured beside predicted (leave-one-run-out
  and calibrated on one run), for the four corner runs (slowest / fastest x lightest / heaviest);
* ``mrd_residuals.png`` torque RMSE [FS] over frequency x load: one-run calibration, the linear
  baseline, the folder model left out, and its residual against the phase of the spindle stroke;
* ``mrd_bands.png``     model-free: spindle friction band half-width and jaw-side friction against
  load and speed (E3, E8), the jaw angle gap between the directions (E12 / cable stretch), and the
  band edges against the jaw torque across loads (capstan e^(+-K) + E8, beside the encoders' ratio);
* ``mrd_centre.png``    the centre map (load read from the spindle's band centre): leave-one-run-out
  RMSE over frequency x load, and the one-run calibration's cost profile over the load gain beside the
  scored runs' error at each gain (the identifiability evidence), and each run's load gain from its own
  signals with its 95 % profile interval beside the gain fitted across loads.

Data: MRD Lab data repository, University of Minnesota (ODbL 1.0 / DbCL 1.0); the attribution is
written into every figure and the report.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from recorded.mrd import MrdRun
from teleop.recording.figures import output_dir, pyplot, save_figure

__all__ = ["write_mrd_figures", "FIGURES"]

FIGURES = ("mrd_loops.png", "mrd_residuals.png", "mrd_bands.png", "mrd_centre.png")
_CREDIT = "data: MRD Lab, University of Minnesota (ODbL/DbCL)"


def _grid(runs: list[MrdRun], values: dict[str, float]) -> tuple[np.ndarray, list[float], list[int]]:
    freqs = sorted({round(r.frequency_hz, 2) for r in runs})
    loads = sorted({r.load_level for r in runs})
    g = np.full((len(loads), len(freqs)), np.nan)
    for r in runs:
        if r.name in values:
            g[loads.index(r.load_level), freqs.index(round(r.frequency_hz, 2))] = values[r.name]
    return g, freqs, loads


def _heat(ax, g, freqs, loads, title, vmax):
    im = ax.imshow(g, origin="lower", cmap="viridis", vmin=0.0, vmax=vmax, aspect="auto")
    for (i, j), v in np.ndenumerate(g):
        if math.isfinite(v):
            ax.text(j, i, f"{v:.3f}", ha="center", va="center", fontsize=7, color="w" if v < 0.6 * vmax else "k")
    ax.set_xticks(range(len(freqs)), [f"{f:g}" for f in freqs])
    ax.set_yticks(range(len(loads)), [str(x) for x in loads])
    ax.set_xlabel("sine frequency [Hz]")
    ax.set_ylabel("load level")
    ax.set_title(title, fontsize=9)
    return im


def _corners(runs: list[MrdRun]) -> list[MrdRun]:
    fr = sorted({round(r.frequency_hz, 2) for r in runs})
    ld = sorted({r.load_level for r in runs})
    out = []
    for f in (fr[0], fr[-1]):
        for lv in (ld[0], ld[-1]):
            out += [r for r in runs if round(r.frequency_hz, 2) == f and r.load_level == lv][:1]
    return out


def _edges(ax, runs: list[MrdRun], bands: dict, sweep: dict) -> None:
    """Spindle band edges against the jaw torque, every run; the capstan + E8 lines of the load sweep and the
    slope the kinematic ratio would give (through the lightest slow run's centre)."""
    j = np.array([1e3 * bands[r.name]["jaw_torque_mean_Nm"] for r in runs])
    c = np.array([1e3 * bands[r.name]["band_centre_Nm"] for r in runs])
    w = np.array([1e3 * bands[r.name]["band_half_width_Nm"] for r in runs])
    ax.plot(j, c + w, "^", color="C3", ms=4, label="edge driving the load")
    ax.plot(j, c - w, "v", color="C0", ms=4, label="edge back-driven")
    ax.plot(j, c, ".", color="0.4", ms=4, label="band centre")
    if sweep:
        x = np.linspace(0.0, j.max() * 1.05, 20)
        c0, f0 = 1e3 * sweep["centre_at_zero_jaw_torque_Nm"], 1e3 * sweep["intercept_half_width_Nm"]
        ax.plot(x, c0 + f0 + sweep["slope_high"] * x, "-", color="C3", lw=0.8,
                label=f"r e^K = {sweep['slope_high']:.2f} (r {sweep['r']:.2f}, K {sweep['K']:.2f})")
        ax.plot(x, c0 - f0 + sweep["slope_low"] * x, "-", color="C0", lw=0.8,
                label=f"r e^-K = {sweep['slope_low']:.2f}")
        k = int(np.argmin(j))
        ax.plot(x, c[k] + sweep["n_k"] * (x - j[k]), "--", color="0.3", lw=0.8,
                label=f"centre slope from the encoders, n_k = {sweep['n_k']:.3f}")
    ax.set_xlabel("mean jaw torque [mN m]")
    ax.set_ylabel("spindle torque [mN m]")
    ax.set_title("capstan + E8: band edges across loads", fontsize=9)
    ax.legend(fontsize=6)


def _save(plt, fig, title: str, path: Path) -> Path:
    """Title, layout, write ``path`` (80 dpi) and close ``fig``; returns ``path``."""
    fig.suptitle(title, fontsize=10)
    return save_figure(fig, path, 80)


def write_mrd_figures(runs: list[MrdRun], summary: dict, details: dict, directory: str | Path) -> list[Path]:
    """Write :data:`FIGURES` to ``directory``; returns their paths. Raises ConfigError when the
    directory cannot be created."""
    plt = pyplot()
    d = output_dir(directory, "--figures")
    return [_torque(plt, runs, details, d / FIGURES[0]), _failures(plt, runs, summary, details, d / FIGURES[1]),
            _bands(plt, runs, summary, d / FIGURES[2]), _centre(plt, runs, summary, d / FIGURES[3])]


def _torque(plt, runs: list[MrdRun], details: dict, path: Path) -> Path:
    """Jaw torque of the corner runs, measured and predicted from the spindle only: against the jaw angle,
    and over the first two cycles beside the spindle torque."""
    k0 = details["k0"]
    corners = _corners(runs)
    fig, axes = plt.subplots(2, len(corners), figsize=(3.6 * len(corners), 6.2), squeeze=False)
    for j, r in enumerate(corners):
        k = k0.get(r.name, 0)
        ax = axes[0, j]
        ax.plot(np.degrees(r.theta_d[k:]), 1e3 * r.tau_d[k:], color="0.3", lw=0.6, label="measured")
        if r.name in details["loro_pred"]:
            pt, pa = details["loro_pred"][r.name]
            ax.plot(np.degrees(pa[k:]), 1e3 * pt[k:], color="tab:orange", lw=0.6, label="folder model, left out")
        if r.name in details["pred"]:
            pt, pa = details["pred"][r.name]
            ax.plot(np.degrees(pa[k:]), 1e3 * pt[k:], color="tab:blue", lw=0.5, alpha=0.6,
                    label="calibrated on one run")
        ax.set_title(f"run {r.name}: {r.frequency_hz:.1f} Hz, load {r.load_level}", fontsize=9)
        ax.set_xlabel("jaw angle [deg]")
        ax.set_ylabel("jaw torque [mN m]")
        ax = axes[1, j]
        t = r.time[k:]
        m = t < t[0] + 2.2 / max(r.frequency_hz, 1e-3)
        ax.plot(t[m], 1e3 * r.tau_d[k:][m], color="0.3", lw=0.6)
        if r.name in details["loro_pred"]:
            ax.plot(t[m], 1e3 * details["loro_pred"][r.name][0][k:][m], color="tab:orange", lw=0.7)
        ax2 = ax.twinx()
        ax2.plot(t[m], 1e3 * r.tau_p[k:][m], color="tab:green", lw=0.5, alpha=0.5)
        ax2.set_ylabel("spindle torque [mN m] (green)", fontsize=8)
        ax.set_xlabel("time [s]")
        ax.set_ylabel("jaw torque [mN m]")
    axes[0, -1].legend(fontsize=7)
    return _save(plt, fig, f"Jaw torque: measured and predicted from the spindle only ({_CREDIT})", path)


def _failures(plt, runs: list[MrdRun], summary: dict, details: dict, path: Path) -> Path:
    """Torque RMSE over frequency x load (headline, linear baseline, folder model left out) and the left-out
    folder model's mean residual over the spindle cycle."""
    k0 = details["k0"]
    fig, axes = plt.subplots(1, 4, figsize=(17, 3.8))
    cal = {n: v["torque_rmse_fs"] for n, v in summary["runs"].items()}
    lin = {n: v["baselines"]["linear"]["torque_rmse_fs"] for n, v in summary["runs"].items()}
    lo = {n: v["torque_rmse_fs"] for n, v in summary.get("loro", {}).get("runs", {}).items()}
    vmax = max([0.1] + [v for v in lo.values()])
    c = summary["calibration"]
    ctitle = f"calibrated on run {c['run']}" if c["mode"] == "run" else f"first {c['seconds']:g} s of each run"
    head = next(iter(summary["runs"].values()))["model"]          # the headline's model (model_choice)
    for ax, vals, title, vm in ((axes[0], cal, f"{head}, {ctitle}", max(cal.values())),
                                (axes[1], lin, f"linear baseline, {ctitle}", max(lin.values())),
                                (axes[2], lo, "folder model, leave-one-run-out", vmax)):
        im = _heat(ax, *_grid(runs, vals), f"{title}: torque RMSE [FS]", vm)
        fig.colorbar(im, ax=ax, fraction=0.046)
    ax = axes[3]
    nb = 24
    for r in _corners(runs):
        if r.name not in details["loro_pred"]:
            continue
        k = k0.get(r.name, 0)
        e = (details["loro_pred"][r.name][0] - r.tau_d)[k:] / summary["full_scale_Nm"]
        ph = (2 * math.pi * r.frequency_hz * r.time[k:]) % (2 * math.pi)
        idx = np.minimum((ph / (2 * math.pi) * nb).astype(int), nb - 1)
        mean = np.array([e[idx == i].mean() if np.any(idx == i) else np.nan for i in range(nb)])
        ax.plot((np.arange(nb) + 0.5) * 360 / nb, mean, marker=".", label=r.name)
    ax.axhline(0, color="0.5", lw=0.5)
    ax.set_xlabel("phase of the spindle sine [deg]")
    ax.set_ylabel("mean residual [FS]")
    ax.set_title("folder model left out: residual over the cycle", fontsize=9)
    if ax.get_lines()[:-1]:         # a folder model was left out (two runs or more): one line per corner run
        ax.legend(fontsize=7)
    return _save(plt, fig, f"Where the jaw torque estimate fails ({_CREDIT})", path)


def _bands(plt, runs: list[MrdRun], summary: dict, path: Path) -> Path:
    """Model-free loop measurements in the middle of the stroke: friction band, direction gaps, band edges."""
    fig, axes = plt.subplots(1, 4, figsize=(17, 3.6))
    bands = summary["bands"]
    freqs = sorted({round(r.frequency_hz, 2) for r in runs})
    cols = plt.cm.viridis(np.linspace(0, 0.85, len(freqs)))
    for f, col in zip(freqs, cols, strict=False):
        rs = sorted([r for r in runs if round(r.frequency_hz, 2) == f], key=lambda r: r.load_level)
        x = [1e3 * bands[r.name]["jaw_torque_mean_Nm"] for r in rs]
        axes[0].plot(x, [1e3 * bands[r.name]["band_half_width_Nm"] for r in rs], "o-", color=col, label=f"{f:g} Hz")
        axes[1].plot([math.degrees(r.peak_speed) for r in rs],
                     [1e3 * abs(bands[r.name]["jaw_torque_direction_half_diff_Nm"]) for r in rs], "o", color=col)
        axes[2].plot(x, [abs(bands[r.name]["jaw_angle_direction_half_diff_deg"]) for r in rs], "o-", color=col)
    axes[0].set_xlabel("mean jaw torque [mN m]")
    axes[0].set_ylabel("spindle band half-width [mN m]")
    axes[0].set_title("E8 / E3: friction band against load and frequency", fontsize=9)
    axes[0].legend(fontsize=7)
    axes[1].set_xlabel("peak spindle speed [deg/s]")
    axes[1].set_ylabel("jaw torque half-gap between directions [mN m]")
    axes[1].set_title("friction beyond the jaw pulley (load motor)", fontsize=9)
    axes[2].set_xlabel("mean jaw torque [mN m]")
    axes[2].set_ylabel("jaw angle half-gap between directions [deg]")
    axes[2].set_title("E12 / stretch: angle gap against load", fontsize=9)
    _edges(axes[3], runs, bands, summary.get("load_sweep", {}))
    return _save(plt, fig, f"Model-free loop measurements, middle of the stroke ({_CREDIT})", path)


def _centre(plt, runs: list[MrdRun], summary: dict, path: Path) -> Path:
    """``mrd_centre.png`` (module docstring); empty panels say what is missing."""
    fig, axes = plt.subplots(1, 3, figsize=(16, 3.8))
    lo = {n: v["torque_rmse_fs"] for n, v in summary.get("centre_map", {}).get("loro", {}).get("runs", {}).items()}
    if lo:
        im = _heat(axes[0], *_grid(runs, lo), "centre map, leave-one-run-out: torque RMSE [FS]", max(lo.values()))
        fig.colorbar(im, ax=axes[0], fraction=0.046)
    else:
        axes[0].set_title("no leave-one-run-out run", fontsize=9)
    ax = axes[1]
    cal = summary.get("centre_calibration", {})
    prof = cal.get("profile", [])
    if prof:
        g = [p["load_gain"] for p in prof]
        ax.plot(g, [p["fit_rms_fs"] for p in prof], "k.-",
                label=f"calibration run {summary['calibration']['run']}: fit cost")
        if "scored_median_rmse_fs" in prof[0]:
            ax.plot(g, [p["scored_median_rmse_fs"] for p in prof], "o-", label="other runs: median RMSE")
            ax.plot(g, [p["scored_worst_rmse_fs"] for p in prof], "s--", label="other runs: worst RMSE")
        ax.axhline(0.03, color="0.5", lw=0.6, ls=":")
        used = cal["load_gain"]
        label = ("1 / n_k (encoders)" if "n_k" in used else
                 f"given {used['value']:.3f} (design or another folder)" if used["from"].startswith("given") else
                 f"fitted {used['value']:.3f}")
        ax.axvline(used["value"], color="r", lw=0.8, label=label)
        lg = summary.get("centre_map", {}).get("load_gain", {})
        if lg.get("several_loads"):
            ax.axvline(lg["value"], color="g", lw=0.8, ls="--", label=f"this folder across its loads {lg['value']:.3f}")
        ax.set_xlabel("load gain: jaw torque per spindle band-centre torque [-]")
        ax.set_ylabel("torque RMSE [FS]")
        ax.legend(fontsize=7)
    ax.set_title("one run: the gain is not in its own cost", fontsize=9)
    _within(axes[2], runs, summary.get("centre_map", {}).get("within_run_gain", {}))
    return _save(plt, fig, f"Load level read from the spindle band centre ({_CREDIT})", path)



def _within(ax, runs: list[MrdRun], wg: dict) -> None:
    """Each run's load gain from its own signals with its 95 % profile interval, beside the folder's gain."""
    rows = wg.get("runs", {})
    ax.set_title("load gain from each run alone", fontsize=9)
    if not rows:
        return
    lv = {r.name: r.load_level for r in runs}
    names = sorted(rows, key=lambda n: (lv.get(n, 0), n))
    x = np.arange(len(names))
    g = np.array([rows[n]["gain"] for n in names])
    ci = np.array([[1.0 / v if v > 0 else 3.0 for v in rows[n]["profile_ci95"][::-1]] for n in names])
    g, ci = np.nan_to_num(g, nan=0.0), np.clip(np.nan_to_num(ci, nan=0.0), 0.0, 3.0)
    err = [np.clip(g - ci[:, 0], 0.0, None), np.clip(ci[:, 1] - g, 0.0, None)]
    ax.errorbar(x, g, yerr=err, fmt="o", ms=4, lw=0.8, capsize=2,
                label="one run: spindle on jaw torque, shape out (95 % profile)")
    ax.plot(x, [1.0 / rows[n]["n_k"] for n in names], "r_", ms=10, label="1 / n_k of each run's encoders")
    fg = wg.get("summary", {}).get("folder_gain")
    if fg:
        ax.axhspan(0.96 * fg, 1.04 * fg, color="0.85", label=f"fitted across loads {fg:.3f} +- 4 %")
    ax.set_xticks(x, names, fontsize=7)
    ax.set_xlabel("run (sorted by load level)")
    ax.set_ylabel("load gain [-]")
    ax.set_ylim(0.0, 2.0)
    ax.legend(fontsize=7)
