"""``teleop analyze``: what the model gets wrong on a measured recording, why, and what fixes it.

Two modes:

* ``teleop analyze FILE.csv`` (measured-data format, one tendon, docs/formats.md; T_out and x_out
  optional, at least one): the diagnosis of :func:`estimator.diagnosis.diagnose` - the base model
  (profile memory, K and L/EA) fitted on the first part of the recording, every catalogue extension
  fitted on the same block, all scored on the held-out rest; prints the cause, the held-out errors
  and the gain (:func:`teleop.report.format_summary`) and the fitted parameters. A progress bar goes
  to stderr on long recordings.
* ``teleop analyze --kaist [DIR]`` or ``teleop analyze .../sine_config_N.txt``: every KAIST
  configuration (:mod:`teleop.kaist`; unlicensed data read in place): the seed pair model
  (:mod:`estimator.pair`) calibrated on command cycle 1 and tested on cycle 2, beside the
  force-path variant, the linear map and the linear map through a play operator, plus the
  model-free reversal dead zones.

``--json OUT`` writes the result (summary numbers, never per-sample data); ``--report DIR`` a
Markdown report with PNG figures (CSV mode: :func:`teleop.report.write_report`); ``--figures DIR``
the KAIST summary plots ``kaist_*.png``. Bad input raises DataError / ConfigError (one line, exit 2).
"""
from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np

from estimator.diagnosis import diagnose
from estimator.pair import fit_force_path, fit_linear, fit_pair, fit_play_map, reversal_dead_zones, rmse
from teleop.errors import ConfigError, DataError
from teleop.kaist import KaistRecording, cycles, is_kaist_file, load_all
from teleop.recording import MeasuredData, read_measured_csv
from teleop.report import format_summary, write_report

__all__ = ["add_arguments", "main_analyze", "diagnose_file", "format_diagnosis", "analyze_kaist", "format_kaist",
           "write_kaist_figures", "PROGRESS_SAMPLES"]

#: Recordings of at least this many samples get a progress bar on stderr (100 s at 1 kHz).
PROGRESS_SAMPLES = 100_000
_MODELS = ("seed pair model", "force path", "linear map", "linear map + play")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the ``analyze`` options to ``parser``."""
    parser.add_argument("file", nargs="?", metavar="FILE",
                        help="measured-data CSV (one tendon), or a KAIST sine_config_N.txt")
    parser.add_argument("--kaist", nargs="?", const="", default=None, metavar="DIR",
                        help="analyse every KAIST configuration (default DIR ../shared/data/kaist-tsm)")
    parser.add_argument("--json", metavar="OUT", help="write the result (summary numbers) as JSON to OUT")
    parser.add_argument("--report", metavar="DIR", help="write a Markdown report with PNG figures to DIR")
    parser.add_argument("--figures", metavar="DIR", help="KAIST mode: write the kaist_*.png plots to DIR")
    parser.add_argument("--train-fraction", type=float, default=0.6, metavar="F",
                        help="CSV mode: nominal share of the duration used for fitting, in [0.3, 0.9]; the "
                             "split moves to a rest within 8%% of it (default 0.6)")


def main_analyze(args: argparse.Namespace) -> int:
    """Run the subcommand; returns the exit code (0). Raises DataError / ConfigError on bad input."""
    if args.file is None and args.kaist is None:
        raise ConfigError("analyze needs FILE or --kaist [DIR]")
    if args.json is not None and not Path(args.json).resolve().parent.is_dir():
        raise ConfigError(f"--json {args.json}: directory {Path(args.json).resolve().parent} does not exist")
    for opt, d in (("--report", args.report), ("--figures", args.figures)):
        if d is not None and Path(d).exists() and not Path(d).is_dir():
            raise ConfigError(f"{opt} {d}: exists and is not a directory")
    if args.file is not None and not Path(args.file).is_file():
        raise DataError(f"{args.file}: no such file")
    if args.kaist is not None or is_kaist_file(args.file):
        directory = Path(args.file).parent if args.kaist is None else (args.kaist or None)
        recs = load_all(directory)
        summary, fits = analyze_kaist(recs)
        print(format_kaist(summary))
        if args.figures:
            for p in write_kaist_figures(recs, fits, summary, args.figures):
                print(f"wrote {p}")
    else:
        if args.figures:
            raise ConfigError("--figures is for the KAIST analysis (--kaist); use --report DIR")
        summary, data = diagnose_file(args.file, train_fraction=args.train_fraction)
        print(format_diagnosis(summary))
        if args.report is not None:
            print(f"wrote {write_report(summary, data, args.report)}")
    if args.json is not None:
        Path(args.json).write_text(json.dumps(summary, indent=2, allow_nan=False, default=_nan_none) + "\n")
        print(f"wrote {args.json}")
    return 0


def _nan_none(obj):
    if isinstance(obj, np.generic):
        return obj.item()
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


def _finite(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


# ---- one tendon, measured-data CSV ------------------------------------------------------------

def diagnose_file(path: str | Path, train_fraction: float = 0.6,
                  progress: bool | None = None) -> tuple[dict, MeasuredData]:
    """Diagnose one measured-data CSV (:func:`estimator.diagnosis.diagnose`).

    Parameters
    ----------
    path : the CSV (docs/formats.md): time [s], x_in [m], T_in [N], and T_out [N] and/or x_out [m]
    train_fraction : nominal share of the duration used for fitting, in [0.3, 0.9]
    progress : stderr progress bar; default: on for recordings of at least
        :data:`PROGRESS_SAMPLES` samples

    Returns
    -------
    result : dict
        The diagnosis (cause, causes, base and extended {rmse_T_out_N, rmse_x_out_m}, gain,
        parameters, candidates, ...; JSON-ready) plus ``file``, ``n_samples`` and ``duration_s``.
    data : MeasuredData, the recording (for :func:`teleop.report.write_report`)

    Raises
    ------
    DataError
        Missing or malformed file, neither T_out nor x_out, a recording too short to diagnose.
    ConfigError
        ``train_fraction`` outside [0.3, 0.9].
    """
    if not 0.3 <= train_fraction <= 0.9:
        raise ConfigError(f"--train-fraction must be in [0.3, 0.9], got {train_fraction!r}")
    data = read_measured_csv(path).require_distal()
    try:
        result = diagnose(data, train_fraction=train_fraction,
                          progress=len(data) >= PROGRESS_SAMPLES if progress is None else progress)
    except ValueError as e:
        raise DataError(str(e) if str(e).startswith(data.source) else f"{data.source}: {e}") from None
    result.update({"file": str(path), "n_samples": len(data), "duration_s": data.duration})
    return result, data


def format_diagnosis(result: dict) -> str:
    """The lines printed for one CSV: :func:`teleop.report.format_summary`, then the split and the
    fitted parameters of the extended model (SI units)."""
    sp = result["split"]
    pars = ", ".join(f"{k} = {p['value']:.4g}" + ("" if p["unit"] in ("", "-") else f" {p['unit']}")
                     for k, p in result["parameters"].items())
    return "\n".join([f"{result['file']}: {result['n_samples']} samples, {result['duration_s']:.1f} s; fitted on "
                      f"t < {sp['time_s']:.2f} s, held out: the {sp['n_heldout']} samples after it "
                      f"({result['elapsed_s']:.1f} s)",
                      format_summary(result), f"parameters: {pars}"])


# ---- KAIST antagonistic pair ------------------------------------------------------------------

def _kaist_one(rec: KaistRecording) -> tuple[dict, dict]:
    cs = cycles(rec)
    if len(cs) < 2:
        raise DataError(f"{rec.source}: found {len(cs)} complete command cycle(s), need 2 (train, test)")
    c1, c2 = cs[0], cs[1]
    n_train = c1.stop
    fits = {"seed pair model": fit_pair(rec.command, rec.T_a, rec.T_b, rec.angle, n_train),
            "force path": fit_force_path(rec.T_a, rec.T_b, rec.angle, n_train),
            "linear map": fit_linear(rec.command, rec.angle, n_train),
            "linear map + play": fit_play_map(rec.command, rec.angle, n_train)}
    models = {}
    for name, f in fits.items():
        err = f.prediction - rec.angle
        models[name] = {"params": f.params, "rmse_train_deg": math.degrees(rmse(err[c1])),
                        "rmse_test_deg": math.degrees(rmse(err[c2])),
                        "max_abs_test_deg": math.degrees(float(np.max(np.abs(err[c2]))))}
    zones = reversal_dead_zones(rec.command, rec.angle, rec.T_a, rec.T_b)
    summary = {"config_deg": rec.config_deg, "source": rec.source, "n_samples": len(rec),
               "pretension": list(rec.pretension),
               "cycle1": [float(rec.time[c1.start]), float(rec.time[c1.stop])],
               "cycle2": [float(rec.time[c2.start]), float(rec.time[c2.stop])],
               "angle_range_deg": [math.degrees(float(rec.angle.min())), math.degrees(float(rec.angle.max()))],
               "models": models,
               "dead_zones": [{"time": float(rec.time[z.index]), "command_deg": math.degrees(rec.command[z.index]),
                               "command_travel_deg": _finite(math.degrees(z.command_travel)),
                               "K_release": _finite(z.K_release), "K_pull": _finite(z.K_pull)} for z in zones]}
    return summary, {"fits": fits, "cycles": (c1, c2)}


def analyze_kaist(recs: list[KaistRecording]) -> tuple[dict, list[dict]]:
    """Seed pair model vs the linear maps on every configuration (train cycle 1, test cycle 2).

    Returns
    -------
    summary : dict
        ``mode`` ("kaist"), ``configurations`` (one dict per recording: config_deg, cycle times,
        models {name: {params, rmse_train_deg, rmse_test_deg, max_abs_test_deg}}, dead_zones) and
        ``trend``: least-squares line of the mean release-side band exponent K_release against the
        configuration angle [rad] (``K_release_per_rad``, ``K_release_at_0``), when >= 2 configurations.
    details : list of dict
        Per recording: ``fits`` (name -> PairFit with the predictions) and ``cycles``; for the figures.

    Raises
    ------
    DataError
        A recording without two complete command cycles.
    """
    summaries, details = zip(*(_kaist_one(r) for r in recs)) if recs else ((), ())
    out = {"mode": "kaist", "train": "command cycle 1", "test": "command cycle 2",
           "configurations": list(summaries)}
    Ns = [math.radians(s["config_deg"]) for s in summaries]
    Kr = [np.nanmean([z["K_release"] if z["K_release"] is not None else np.nan for z in s["dead_zones"]])
          for s in summaries]
    ok = [i for i, k in enumerate(Kr) if math.isfinite(k)]
    if len(ok) >= 2:
        slope, icpt = np.polyfit([Ns[i] for i in ok], [Kr[i] for i in ok], 1)
        out["trend"] = {"K_release_per_rad": float(slope), "K_release_at_0": float(icpt)}
    return out, list(details)


def format_kaist(s: dict) -> str:
    """The table printed for the KAIST analysis: cycle-2 RMSE [deg] per configuration."""
    lines = ["KAIST antagonistic pair: distal angle, calibrated on command cycle 1, tested on cycle 2",
             f"{'config [deg]':>12}{'seed pair':>11}{'force path':>12}{'linear':>9}{'lin+play':>10}"
             f"{'dead zone':>11}{'K_release':>11}{'K_force':>9}",
             ]
    for c in s["configurations"]:
        m = {k: v["rmse_test_deg"] for k, v in c["models"].items()}
        dz = [z["command_travel_deg"] for z in c["dead_zones"] if z["command_travel_deg"] is not None]
        kr = [z["K_release"] for z in c["dead_zones"] if z["K_release"] is not None]
        lines.append(f"{c['config_deg']:>12}{m['seed pair model']:>11.2f}{m['force path']:>12.2f}"
                     f"{m['linear map']:>9.2f}{m['linear map + play']:>10.2f}"
                     f"{np.mean(dz) if dz else math.nan:>11.1f}{np.mean(kr) if kr else math.nan:>11.2f}"
                     f"{c['models']['force path']['params']['K']:>9.2f}")
    lines.append("RMSE of the angle on cycle 2 [deg]; dead zone after a reversal [deg of command]; "
                 "K_release: capstan band from tension ratios; K_force: K of the force-path fit")
    if "trend" in s:
        lines.append(f"K_release = {s['trend']['K_release_at_0']:.2f} + {s['trend']['K_release_per_rad']:.3f} "
                     "* configuration angle [rad]")
    return "\n".join(lines)


def write_kaist_figures(recs: list[KaistRecording], details: list[dict], summary: dict,
                        directory: str | Path) -> list[Path]:
    """Write kaist_rmse.png, kaist_loops.png, kaist_residuals.png into ``directory`` (created).

    Raises
    ------
    ConfigError
        ``directory`` exists and is not a directory, or cannot be created.
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    d = Path(directory)
    try:
        d.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise ConfigError(f"--figures {d}: cannot create the directory ({e.strerror})") from None
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
