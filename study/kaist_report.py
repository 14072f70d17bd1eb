"""Figures and the Markdown report of ``teleop analyze --kaist`` (summary plots only, no data).

The base pair model against the baselines (docs/results/kaist.md): ``kaist_rmse.png``, ``kaist_loops.png``,
``kaist_residuals.png``. The pair diagnosis and the shared fit:

* ``kaist_pair_loops.png``      distal angle against the command on the test cycle, per
  configuration: measured, seed model, extended model, shared fit;
* ``kaist_pair_residuals.png``  residual (predicted - measured) against the phase of the test
  cycle, seed and extended model, per configuration;
* ``kaist_pair_tensions.png``   measured proximal tensions beside the extended model's prediction
  (the capstan-joint model predicts them from the command; the test cycle's are never fitted, cycle 1's only
  for a ``/T`` model, whose angle-only fit the tension check refused);
* ``kaist_shared.png``          K against the bend angle (shared fit, per-configuration fits,
  model-free band) and the held-out RMSE of every model per configuration;
* ``kaist_tension_angle.png``   model-free: the proximal tension difference against the distal angle,
  per configuration (Finding 3, session 4: the friction band and the stall before each reversal).

The recordings have no licence: only these plots and summary numbers are written.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from teleop.figure_files import output_dir, pyplot

__all__ = ["write_kaist_figures", "write_kaist_report", "FIGURES"]

_MODELS = ("seed pair model", "force path", "linear map", "linear map + play")
FIGURES = ("kaist_rmse.png", "kaist_loops.png", "kaist_residuals.png", "kaist_pair_loops.png",
           "kaist_pair_residuals.png", "kaist_pair_tensions.png", "kaist_shared.png", "kaist_tension_angle.png")


def _finding1_figures(recs, details, summary, d: Path, plt) -> list[Path]:
    """kaist_rmse.png, kaist_loops.png, kaist_residuals.png (docs/results/kaist.md)."""
    deg = np.degrees
    colors = plt.cm.viridis(np.linspace(0.0, 0.85, len(recs)))
    Ns = [c["config_deg"] for c in summary["configurations"]]
    paths = []

    fig, (ax1, ax2, ax3) = plt.subplots(1, 3, figsize=(15, 4.3), gridspec_kw={"width_ratios": [1.5, 1, 1]})
    x = np.arange(len(Ns))
    wb = 0.8 / len(_MODELS)
    for i, name in enumerate(_MODELS):
        vals = [c["models"][name]["rmse_test_deg"] for c in summary["configurations"]]
        bars = ax1.bar(x + (i - (len(_MODELS) - 1) / 2) * wb, vals, wb, label=name)
        ax1.bar_label(bars, fmt="%.1f", fontsize=7)
    ax1.set(xticks=x, xticklabels=[str(n) for n in Ns], xlabel="configuration N [deg]",
            ylabel="distal angle RMSE on cycle 2 [deg]", title="Held-out error (calibrated on cycle 1)")
    ax1.legend(fontsize=8)
    for c, n in zip(summary["configurations"], Ns):
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
    fig.tight_layout()
    paths.append(d / "kaist_rmse.png")
    fig.savefig(paths[-1], dpi=110)
    plt.close(fig)

    fig, axes = plt.subplots(1, len(recs), figsize=(3.3 * len(recs), 3.7), squeeze=False)
    for ax, rec, det in zip(axes[0], recs, details):
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
    fig.tight_layout()
    paths.append(d / "kaist_loops.png")
    fig.savefig(paths[-1], dpi=100)
    plt.close(fig)

    fig, ax = plt.subplots(2, 2, figsize=(11, 7.5))
    for col, rec, det in zip(colors, recs, details):
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
    fig.tight_layout()
    paths.append(d / "kaist_residuals.png")
    fig.savefig(paths[-1], dpi=90)
    plt.close(fig)
    return paths


def _std(row: dict) -> float:
    """Bootstrap std [deg] of a reported figure (``rmse_test_bootstrap``), nan when there is none."""
    b = row.get("rmse_test_bootstrap")
    return float(b["std_deg"]) if b else math.nan


def _style(ax) -> None:
    ax.grid(alpha=0.3)


def _pair_figures(recs, details, summary, d: Path, plt) -> list[Path]:
    """kaist_pair_loops.png, kaist_pair_residuals.png, kaist_pair_tensions.png, kaist_shared.png."""
    deg = np.degrees
    confs = summary["configurations"]
    n = len(recs)
    paths = []

    fig, axes = plt.subplots(1, n, figsize=(3.6 * n, 4.4), squeeze=False)
    for ax, rec, det, c in zip(axes[0], recs, details, confs):
        te = det["cycles"][1]
        x = deg(rec.command[te])
        dg = c["diagnosis"]
        ax.plot(x, deg(rec.angle[te]), "k", lw=2.4, label="measured")
        ax.plot(x, deg(det["pair_fits"]["seed"].angle[te]), color="tab:red", lw=1.1, label="seed model")
        ax.plot(x, deg(det["pair_fits"][det["extended"]].angle[te]), color="tab:blue", lw=1.3,
                label="extended model (fitted per configuration)")
        title = f"N = {rec.config_deg} deg\nRMSE: seed {dg['seed']['rmse_test_deg']:.1f}, " \
                f"ext. {dg['extended']['rmse_test_deg']:.1f}"
        if "shared_angle" in det:
            ax.plot(x, deg(det["shared_angle"][te]), "--", color="tab:green", lw=1.3,
                    label="shared model (one parameter set, K = K0 + mu N)")
            title += f", shared {c['shared']['rmse_test_deg']:.1f}"
        ax.set_title(title + " deg", fontsize=10)
        ax.set_xlabel("command [deg]")
        _style(ax)
    axes[0][0].set_ylabel("distal angle [deg]")
    h, lab = axes[0][0].get_legend_handles_labels()
    fig.legend(h, lab, loc="lower center", ncol=len(lab), fontsize=9, frameon=False)
    fig.suptitle("Test cycle (command cycle 2): measured distal angle against the models")
    fig.tight_layout(rect=(0, 0.07, 1, 1))
    paths.append(d / "kaist_pair_loops.png")
    fig.savefig(paths[-1], dpi=100)
    plt.close(fig)

    fig, axes = plt.subplots(1, n, figsize=(3.6 * n, 3.6), squeeze=False, sharey=True)
    for ax, rec, det in zip(axes[0], recs, details):
        te = det["cycles"][1]
        t = rec.time[te] - rec.time[te.start]
        ph = 360.0 * t / (rec.time[te.stop] - rec.time[te.start])
        for key, col, lab in (("seed", "tab:red", "seed"), (det["extended"], "tab:blue", "extended")):
            ax.plot(ph, deg(det["pair_fits"][key].angle[te] - rec.angle[te]), color=col, lw=1.2, label=lab)
        for v in (90, 270):
            ax.axvline(v, color="k", lw=0.8, ls="--")
        ax.axhline(0, color="k", lw=0.6)
        ax.set(title=f"N = {rec.config_deg} deg", xlabel="phase of the test cycle [deg]", xticks=[0, 90, 180, 270, 360])
        _style(ax)
    axes[0][0].set_ylabel("residual, predicted - measured [deg]")
    axes[0][0].legend(fontsize=8)
    fig.suptitle("Residuals on the test cycle (dashed: command reversals)")
    fig.tight_layout()
    paths.append(d / "kaist_pair_residuals.png")
    fig.savefig(paths[-1], dpi=100)
    plt.close(fig)

    fig, axes = plt.subplots(1, n, figsize=(3.6 * n, 3.8), squeeze=False, sharey=True)
    for ax, rec, det, c in zip(axes[0], recs, details, confs):
        te = det["cycles"][1]
        x = deg(rec.command[te])
        fx = det["pair_fits"][det["extended"]]
        ax.plot(x, rec.T_a[te], "k", lw=1.8, label="T_a measured")
        ax.plot(x, rec.T_b[te], "k--", lw=1.8, label="T_b measured")
        if fx.T_in is not None:
            ax.plot(x, fx.T_in[te, 0], color="tab:blue", lw=1.2, label="T_a extended model")
            ax.plot(x, fx.T_in[te, 1], "--", color="tab:blue", lw=1.2, label="T_b extended model")
            r = c["diagnosis"]["extended"]["rmse_T_in_N"]
            ax.set_title(f"N = {rec.config_deg} deg (RMSE {r:.1f} N{', /T' if fx.tension_weight > 0 else ''})")
        else:
            ax.set_title(f"N = {rec.config_deg} deg")
        ax.set_xlabel("command [deg]")
        _style(ax)
    axes[0][0].set_ylabel("proximal tension [N]")
    axes[0][0].legend(fontsize=7, loc="upper center")
    fig.suptitle("Proximal tensions on the test cycle: measured, and predicted by the extended model from the "
                 "command (not fitted on this cycle; /T: fitted on cycle 1)")
    fig.tight_layout()
    paths.append(d / "kaist_pair_tensions.png")
    fig.savefig(paths[-1], dpi=100)
    plt.close(fig)

    if "shared" not in summary:
        return paths
    sh = summary["shared"]
    Ns = np.array([c["config_deg"] for c in confs], dtype=float)
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(15, 5.0), gridspec_kw={"width_ratios": [1, 1.6]})
    p = {k: v["value"] for k, v in sh["models"]["capstan"]["params"].items()}
    nn = np.linspace(0, Ns.max() if Ns.size else 1.0, 50)
    for j, col in (("a", "tab:blue"), ("b", "tab:orange")):
        ax1.plot(nn, p[f"K0_{j}"] + p["mu"] * np.radians(nn), color=col, lw=2,
                 label=f"shared fit: K_{j} = {p[f'K0_{j}']:.2f} + {p['mu']:.3f} N")
        ext = [c["diagnosis"]["extended"]["params"].get(f"K_{j}", {}).get("value") for c in confs]
        ax1.plot([N for N, k in zip(Ns, ext) if k is not None], [k for k in ext if k is not None], "o", color=col,
                 mfc="none", ms=8, label=f"K_{j} fitted per configuration")
    kr = [np.mean([z["K_release"] for z in c["dead_zones"] if z["K_release"] is not None] or [np.nan])
          for c in confs]
    ax1.plot(Ns, kr, "ks", ms=6, label="model-free K_release (tension ratios)")
    ax1.set(xlabel="configuration: accumulated bend N [deg]", ylabel="friction exponent K [-]",
            title=f"K grows with the bend (mu = {p['mu']:.3f} per rad)")
    ax1.legend(fontsize=8, loc="upper left")
    _style(ax1)
    bars = [("seed, per configuration", [c["diagnosis"]["seed"]["rmse_test_deg"] for c in confs], "tab:red"),
            ("extended, per configuration", [c["diagnosis"]["extended"]["rmse_test_deg"] for c in confs], "tab:blue"),
            (f"shared, chosen: {sh.get('chosen', 'capstan')}", [c["shared"]["rmse_test_deg"] for c in confs],
             "tab:green"),
            ("shared, configuration left out", [c["shared"]["leave_one_out_rmse_test_deg"] for c in confs],
             "yellowgreen"),
            ("shared, G also falls with N (+T)",
             [r["rmse_test_deg"] for r in sh["models"]["capstan+T, G falls with N"]["configurations"]], "teal"),
            ("shared seed + backlash (E12)",
             [r["rmse_test_deg"] for r in sh["models"]["seed+joint_backlash"]["configurations"]], "tab:gray")]
    # bootstrap std of the reported figures (rmse_test_bootstrap, when the analysis ran one): error bars
    loco = sh["leave_one_out"].get(sh.get("chosen", ""), [])
    errs = {1: [_std(c["diagnosis"]["extended"]) for c in confs], 3: [_std(r) for r in loco]}
    x = np.arange(len(confs))
    w = 0.8 / len(bars)
    for i, (lab, vals, col) in enumerate(bars):
        e = errs.get(i)
        b = ax2.bar(x + (i - (len(bars) - 1) / 2) * w, vals, w, label=lab, color=col,
                    yerr=e if e and len(e) == len(vals) and not np.all(np.isnan(e)) else None, capsize=2,
                    error_kw={"lw": 0.8})
        ax2.bar_label(b, fmt="%.1f", fontsize=6.5)
    mu0 = sh["models"]["capstan, mu = 0"]["rmse_test_deg"]
    ax2.set(xticks=x, xticklabels=[f"{int(N)}" for N in Ns], xlabel="configuration N [deg]",
            ylabel="distal angle RMSE on the test cycle [deg]",
            title=f"Held-out error (shared without K growth, mu = 0: {mu0:.1f} deg overall"
                  + ("; error bars: bootstrap std)" if any(np.isfinite(v).any() for v in errs.values() if v) else ")"))
    ax2.legend(fontsize=8, ncol=3, loc="upper left")
    ax2.set_ylim(0, 1.35 * max(max(v) for _, v, _ in bars))
    _style(ax2)
    fig.tight_layout()
    paths.append(d / "kaist_shared.png")
    fig.savefig(paths[-1], dpi=100)
    plt.close(fig)
    return paths


def _tension_angle_figure(recs, d: Path, plt) -> list[Path]:
    """kaist_tension_angle.png: T_a - T_b [N] against the distal angle [deg], every sample, one panel
    per configuration (no model): a parallelogram whose vertical sides are the friction band held
    after each reversal and whose branches end in a rise of the tension difference while the joint
    stalls (docs/results/kaist.md)."""
    n = len(recs)
    fig, axes = plt.subplots(1, n, figsize=(3.4 * n, 3.6), squeeze=False)
    for ax, rec in zip(axes[0], recs):
        ax.plot(np.degrees(rec.angle), rec.T_a - rec.T_b, "k", lw=0.9)
        ax.set(title=f"N = {rec.config_deg} deg", xlabel="distal angle [deg]")
        _style(ax)
    axes[0][0].set_ylabel("T_a - T_b, proximal [N]")
    fig.suptitle("Model-free: proximal tension difference against the distal angle (every sample)")
    fig.tight_layout()
    path = d / "kaist_tension_angle.png"
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return [path]


def write_kaist_figures(recs, details: list[dict], summary: dict, directory: str | Path,
                        option: str = "--figures") -> list[Path]:
    """Write every ``kaist_*.png`` of :data:`FIGURES` into ``directory`` (created).

    Parameters
    ----------
    recs, details, summary : what :func:`study.analyze.analyze_kaist` read and returned
    directory : output directory

    Returns
    -------
    list of Path, the files written.

    Raises
    ------
    ConfigError
        ``directory`` exists and is not a directory, or cannot be created.
    """
    plt = pyplot()
    d = output_dir(directory, option)
    return (_finding1_figures(recs, details, summary, d, plt) + _pair_figures(recs, details, summary, d, plt)
            + _tension_angle_figure(recs, d, plt))


def write_kaist_report(recs, details: list[dict], summary: dict, directory: str | Path) -> Path:
    """Write ``report.md`` and the figures of the KAIST analysis into ``directory``; returns its path.

    Raises
    ------
    ConfigError
        ``directory`` cannot be created.
    """
    from estimator.offline.pair_models import PAIR_EFFECTS
    from study.kaist_summary import format_kaist

    figs = write_kaist_figures(recs, details, summary, directory, option="--report")
    d = figs[0].parent
    confs = summary["configurations"]
    md = ["# KAIST antagonistic pair: what the seed model gets wrong, and the extended model", "",
          "Every model is fitted on command cycle 1 and scored on the later cycles (distal-angle RMSE [deg]); "
          "model choice uses cycle 1 only.", "",
          "| N [deg] | seed | extended | gain | shared | shared, left out | causes | extended model |",
          "|---:|---:|---:|---:|---:|---:|---|---|"]
    for c in confs:
        g, s = c["diagnosis"], c.get("shared", {})
        md.append(f"| {c['config_deg']} | {g['seed']['rmse_test_deg']:.2f} | {g['extended']['rmse_test_deg']:.2f} | "
                  f"{g['gain']:.2f} | {s.get('rmse_test_deg', math.nan):.2f} | "
                  f"{s.get('leave_one_out_rmse_test_deg', math.nan):.2f} | {', '.join(g['causes']) or 'none'} | "
                  f"`{g['extended']['model']}` |")
    causes = sorted({e for c in confs for e in c["diagnosis"]["causes"] if e in PAIR_EFFECTS})
    md += ["", "## Causes", ""]
    md += [f"* **{e}** ({PAIR_EFFECTS[e].literature}): {PAIR_EFFECTS[e].cause}. Signature: "
           f"{PAIR_EFFECTS[e].signature}." for e in causes]
    if any("unknown" in c["diagnosis"]["causes"] for c in confs):
        md.append("* **unknown**: the extended model's test error is still above 3 times the tracker noise.")
    md += ["", "## Printed summary", "", "```", format_kaist(summary), "```", ""]
    md += [f"![{p.stem}]({p.name})\n" for p in figs]
    path = d / "report.md"
    path.write_text("\n".join(md), encoding="utf-8")
    return path
