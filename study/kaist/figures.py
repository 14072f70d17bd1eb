"""The KAIST figures of the base pair model against the baselines, and the model-free tension figure.

* ``kaist_rmse.png``            held-out error of each model, the dead zone after each reversal, the capstan band;
* ``kaist_loops.png``           distal angle against the command on cycle 2, measured and the models;
* ``kaist_residuals.png``       the seed pair model's residual on cycle 2;
* ``kaist_tension_angle.png``   model-free: the proximal tension difference against the distal angle.

Each function takes what :func:`study.analyze.analyze_kaist` read and returned (``recs``, ``details``,
``summary``), the output directory ``d`` and pyplot, and returns the path it wrote (docs/results/kaist.md).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from teleop.recording.figures import save_figure

__all__ = ["rmse_figure", "loops_figure", "residuals_figure", "tension_angle_figure", "MODELS"]

#: the base pair model and its baselines, in the order of the figures' bars
MODELS = ("seed pair model", "force path", "linear map", "linear map + play")


def _style(ax) -> None:
    ax.grid(alpha=0.3)


def rmse_figure(recs, details, summary, d: Path, plt) -> Path:
    """kaist_rmse.png: held-out error of each model, the dead zone after each reversal and the capstan band
    against the configuration (docs/results/kaist.md)."""
    Ns = [c["config_deg"] for c in summary["configurations"]]
    fig, (ax1, ax2, ax3) = plt.subplots(1, 3, figsize=(15, 4.3), gridspec_kw={"width_ratios": [1.5, 1, 1]})
    x = np.arange(len(Ns))
    wb = 0.8 / len(MODELS)
    for i, name in enumerate(MODELS):
        vals = [c["models"][name]["rmse_test_deg"] for c in summary["configurations"]]
        bars = ax1.bar(x + (i - (len(MODELS) - 1) / 2) * wb, vals, wb, label=name)
        ax1.bar_label(bars, fmt="%.1f", fontsize=7)
    ax1.set(xticks=x, xticklabels=[str(n) for n in Ns], xlabel="configuration N [deg]",
            ylabel="distal angle RMSE on cycle 2 [deg]", title="Held-out error (calibrated on cycle 1)")
    ax1.legend(fontsize=8)
    for c, n in zip(summary["configurations"], Ns, strict=False):
        for q in c["dead_zones"]:
            if q["command_travel_deg"] is None:
                continue
            top = q["command_deg"] > 0           # after a maximum: A released, B pulled
            ax2.plot(n, q["command_travel_deg"], "ks", mfc="k" if top else "none", ms=5)
            ax3.plot(n, q["K_release"], "o", color="tab:blue", mfc="tab:blue" if top else "none", ms=5)
            ax3.plot(n, q["K_pull"], "^", color="tab:orange", mfc="tab:orange" if top else "none", ms=5)
        ax3.plot(n, c["models"]["force path"]["params"]["K"], "D", color="tab:green", ms=6)
    ax2.plot([], [], "ks", label="after a command maximum")
    ax2.plot([], [], "ks", mfc="none", label="after a command minimum")
    ax2.set(xlabel="configuration N [deg]", ylabel="command travel before the angle moves 1 deg [deg]",
            title="Model-free: dead zone after each reversal")
    ax2.legend(fontsize=7)
    ax3.plot([], [], "o", color="tab:blue", label="K_release = 0.5 ln(T_rel at reversal / at motion)")
    ax3.plot([], [], "^", color="tab:orange", label="K_pull = 0.5 ln(T_pull at motion / at reversal)")
    ax3.plot([], [], "D", color="tab:green", label="K fitted by the force path (cycle 1)")
    if "trend" in summary:
        nn = np.linspace(0, max(Ns), 2)
        t = summary["trend"]
        ax3.plot(nn, t["K_release_at_0"] + t["K_release_per_rad"] * np.radians(nn), "-", color="tab:blue", lw=1)
    ax3.set(xlabel="configuration N [deg]", ylabel="friction exponent K [-]",
            title="Capstan band (filled: after a maximum)")
    ax3.legend(fontsize=7, loc="upper left")
    for a in (ax2, ax3):
        a.grid(alpha=0.3)
    return save_figure(fig, d / "kaist_rmse.png", 110)


def loops_figure(recs, details, summary, d: Path, plt) -> Path:
    """kaist_loops.png: distal angle against the command on cycle 2, measured and three models."""
    deg = np.degrees
    fig, axes = plt.subplots(1, len(recs), figsize=(3.3 * len(recs), 3.7), squeeze=False)
    for ax, rec, det in zip(axes[0], recs, details, strict=False):
        c2 = det["cycles"][1]
        ax.plot(deg(rec.command[c2]), deg(rec.angle[c2]), "k", lw=1.6, label="measured")
        ax.plot(deg(rec.command[c2]), deg(det["fits"]["seed pair model"].prediction[c2]), "r", lw=1, label="seed pair")
        ax.plot(deg(rec.command[c2]), deg(det["fits"]["force path"].prediction[c2]), ":",
                color="tab:green", lw=1.2, label="force path")
        ax.plot(deg(rec.command[c2]), deg(det["fits"]["linear map + play"].prediction[c2]), "--",
                color="tab:blue", lw=1, label="linear + play")
        ax.set(title=f"N = {rec.config_deg} deg (cycle 2)", xlabel="command [deg]")
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("distal angle [deg]")
    axes[0][0].legend(fontsize=7)
    return save_figure(fig, d / "kaist_loops.png", 100)


def residuals_figure(recs, details, summary, d: Path, plt) -> Path:
    """kaist_residuals.png: the seed pair model's residual on cycle 2 against phase, command and tension."""
    deg = np.degrees
    colors = plt.cm.viridis(np.linspace(0.0, 0.85, len(recs)))
    fig, ax = plt.subplots(2, 2, figsize=(11, 7.5))
    for col, rec, det in zip(colors, recs, details, strict=False):
        c2 = det["cycles"][1]
        r = deg(det["fits"]["seed pair model"].prediction[c2] - rec.angle[c2])
        t = rec.time[c2] - rec.time[c2.start]
        ph = 360.0 * t / (rec.time[c2.stop] - rec.time[c2.start])
        kw = {"color": col, "lw": 1}
        ax[0, 0].plot(ph, r, label=f"N = {rec.config_deg}", **kw)
        ax[0, 1].plot(deg(rec.command[c2]), r, **kw)
        ax[1, 0].plot((rec.T_a - rec.T_b)[c2], r, ".", color=col, ms=3)
        ax[1, 1].plot(ph, deg(rec.angle[c2]), **kw)
        ax[1, 1].plot(ph, deg(det["fits"]["seed pair model"].prediction[c2]), ":", **kw)
    for a in (ax[0, 0], ax[1, 1]):
        for v in (90, 270):
            a.axvline(v, color="k", lw=0.8, ls="--")
        a.set_xlabel("phase of the command cycle [deg] (reversals at 90, 270)")
    ax[0, 0].set(ylabel="seed pair residual [deg]", title="Residual (predicted - measured), cycle 2")
    ax[0, 0].legend(fontsize=7)
    ax[0, 1].set(xlabel="command [deg]", ylabel="residual [deg]", title="Residual vs command")
    ax[1, 0].set(xlabel="T_a - T_b [N]", ylabel="residual [deg]", title="Residual vs proximal tension difference")
    ax[1, 1].set(ylabel="distal angle [deg]", title="Measured (solid) and seed pair (dotted)")
    for a in ax.ravel():
        a.grid(alpha=0.3)
    return save_figure(fig, d / "kaist_residuals.png", 90)


def tension_angle_figure(recs, details, summary, d: Path, plt) -> Path:
    """kaist_tension_angle.png: T_a - T_b [N] against the distal angle [deg], every sample, one panel
    per configuration (no model): a parallelogram whose vertical sides are the friction band held
    after each reversal and whose branches end in a rise of the tension difference while the joint
    stalls (docs/results/kaist.md)."""
    n = len(recs)
    fig, axes = plt.subplots(1, n, figsize=(3.4 * n, 3.6), squeeze=False)
    for ax, rec in zip(axes[0], recs, strict=False):
        ax.plot(np.degrees(rec.angle), rec.T_a - rec.T_b, "k", lw=0.9)
        ax.set(title=f"N = {rec.config_deg} deg", xlabel="distal angle [deg]")
        _style(ax)
    axes[0][0].set_ylabel("T_a - T_b, proximal [N]")
    fig.suptitle("Model-free: proximal tension difference against the distal angle (every sample)")
    return save_figure(fig, d / "kaist_tension_angle.png", 90)
