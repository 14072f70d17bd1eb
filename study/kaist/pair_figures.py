"""The KAIST figures of the pair diagnosis and the shared fit (docs/results/kaist.md).

* ``kaist_pair_loops.png``      distal angle against the command on the test cycle, per
  configuration: measured, seed model, extended model, shared fit;
* ``kaist_pair_residuals.png``  residual (predicted - measured) against the phase of the test
  cycle, seed and extended model, per configuration;
* ``kaist_pair_tensions.png``   measured proximal tensions beside the extended model's prediction;
* ``kaist_shared.png``          K against the bend angle (shared fit, per-configuration fits,
  model-free band) and the held-out RMSE of every model per configuration.

Each function takes what :func:`study.analyze.analyze_kaist` read and returned (``recs``, ``details``,
``summary``), the output directory ``d`` and pyplot, and returns the path it wrote.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from teleop.recording.figures import save_figure

__all__ = ["pair_loops_figure", "pair_residuals_figure", "pair_tensions_figure", "shared_figure"]


def _std(row: dict) -> float:
    """Bootstrap std [deg] of a reported figure (``rmse_test_bootstrap``), nan when there is none."""
    b = row.get("rmse_test_bootstrap")
    return float(b["std_deg"]) if b else math.nan


def _style(ax) -> None:
    ax.grid(alpha=0.3)


def pair_loops_figure(recs, details, summary, d: Path, plt) -> Path:
    """kaist_pair_loops.png: distal angle against the command on the test cycle: measured, seed,
    extended and shared model."""
    deg = np.degrees
    confs = summary["configurations"]
    n = len(recs)
    fig, axes = plt.subplots(1, n, figsize=(3.6 * n, 4.4), squeeze=False)
    for ax, rec, det, c in zip(axes[0], recs, details, confs, strict=False):
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
    return save_figure(fig, d / "kaist_pair_loops.png", 100, rect=(0, 0.07, 1, 1))


def pair_residuals_figure(recs, details, summary, d: Path, plt) -> Path:
    """kaist_pair_residuals.png: residual of the seed and extended model against the test cycle's phase."""
    deg = np.degrees
    n = len(recs)
    fig, axes = plt.subplots(1, n, figsize=(3.6 * n, 3.6), squeeze=False, sharey=True)
    for ax, rec, det in zip(axes[0], recs, details, strict=False):
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
    return save_figure(fig, d / "kaist_pair_residuals.png", 100)


def pair_tensions_figure(recs, details, summary, d: Path, plt) -> Path:
    """kaist_pair_tensions.png: measured proximal tensions beside the extended model's prediction."""
    deg = np.degrees
    confs = summary["configurations"]
    n = len(recs)
    fig, axes = plt.subplots(1, n, figsize=(3.6 * n, 3.8), squeeze=False, sharey=True)
    for ax, rec, det, c in zip(axes[0], recs, details, confs, strict=False):
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
    return save_figure(fig, d / "kaist_pair_tensions.png", 100)


def shared_figure(recs, details, summary, d: Path, plt) -> Path | None:
    """kaist_shared.png: K against the bend angle (shared fit, per-configuration fits, model-free band) and
    the held-out RMSE of every model per configuration; None when the analysis ran no shared fit."""
    if "shared" not in summary:
        return None
    confs = summary["configurations"]
    sh = summary["shared"]
    Ns = np.array([c["config_deg"] for c in confs], dtype=float)
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(15, 5.0), gridspec_kw={"width_ratios": [1, 1.6]})
    _K_panel(ax1, sh, confs, Ns)
    _rmse_panel(ax2, sh, confs, Ns)
    return save_figure(fig, d / "kaist_shared.png", 100)


def _K_panel(ax, sh: dict, confs: list[dict], Ns: np.ndarray) -> None:
    """The friction exponents against the configuration's bend: shared fit, per configuration, model-free."""
    p = {k: v["value"] for k, v in sh["models"]["capstan"]["params"].items()}
    nn = np.linspace(0, Ns.max() if Ns.size else 1.0, 50)
    for j, col in (("a", "tab:blue"), ("b", "tab:orange")):
        ax.plot(nn, p[f"K0_{j}"] + p["mu"] * np.radians(nn), color=col, lw=2,
                 label=f"shared fit: K_{j} = {p[f'K0_{j}']:.2f} + {p['mu']:.3f} N")
        ext = [c["diagnosis"]["extended"]["params"].get(f"K_{j}", {}).get("value") for c in confs]
        ax.plot([N for N, k in zip(Ns, ext, strict=False) if k is not None], [k for k in ext if k is not None], "o",
                 color=col, mfc="none", ms=8, label=f"K_{j} fitted per configuration")
    kr = [np.mean([z["K_release"] for z in c["dead_zones"] if z["K_release"] is not None] or [np.nan])
          for c in confs]
    ax.plot(Ns, kr, "ks", ms=6, label="model-free K_release (tension ratios)")
    ax.set(xlabel="configuration: accumulated bend N [deg]", ylabel="friction exponent K [-]",
            title=f"K grows with the bend (mu = {p['mu']:.3f} per rad)")
    ax.legend(fontsize=8, loc="upper left")
    _style(ax)


def _rmse_panel(ax, sh: dict, confs: list[dict], Ns: np.ndarray) -> None:
    """The held-out distal-angle RMSE of every model per configuration, with bootstrap error bars."""
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
        b = ax.bar(x + (i - (len(bars) - 1) / 2) * w, vals, w, label=lab, color=col,
                    yerr=e if e and len(e) == len(vals) and not np.all(np.isnan(e)) else None, capsize=2,
                    error_kw={"lw": 0.8})
        ax.bar_label(b, fmt="%.1f", fontsize=6.5)
    mu0 = sh["models"]["capstan, mu = 0"]["rmse_test_deg"]
    ax.set(xticks=x, xticklabels=[f"{int(N)}" for N in Ns], xlabel="configuration N [deg]",
            ylabel="distal angle RMSE on the test cycle [deg]",
            title=f"Held-out error (shared without K growth, mu = 0: {mu0:.1f} deg overall"
                  + ("; error bars: bootstrap std)" if any(np.isfinite(v).any() for v in errs.values() if v) else ")"))
    ax.legend(fontsize=8, ncol=3, loc="upper left")
    ax.set_ylim(0, 1.35 * max(max(v) for _, v, _ in bars))
    _style(ax)
