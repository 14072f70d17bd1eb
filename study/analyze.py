"""``teleop analyze``: what the model gets wrong on a measured recording, why, and what fixes it.

Over 400 lines: the three modes of one command share its argument checks, output paths and messages.

Two modes:

* ``teleop analyze FILE.csv`` (measured-data format, one tendon, docs/reference/formats.md; T_out and x_out
  optional, at least one): the diagnosis of :func:`estimator.offline.diagnosis.selection.diagnose` - the base model
  (profile memory, K and L/EA) fitted on the first part of the recording, every catalogue extension
  fitted on the same block, all scored on the held-out rest; prints the cause, the held-out errors
  and the gain (:func:`study.report.format_summary`) and the fitted parameters. A progress bar goes
  to stderr on long recordings. Where the friction sits along the sheath is fitted; ``--route CONFIG``
  holds the route of CONFIG's ``sheath`` instead (an instrument whose route is known from its design).
* ``teleop analyze --kaist [DIR]`` or ``teleop analyze .../sine_config_N.txt`` (or any FILE with
  ``--bend DEG``; other layouts with ``--columns MAP``, :mod:`recorded.columns`): every configuration under DIR
  (``sine_config_<N>.txt``, or ``optimization/selected/<N>.txt`` of a clone given by its root or that folder,
  :mod:`recorded.kaist_files`; ``--configs`` picks some; default DIR in ``TSM_TELEOP_DATA``; read in place),
  calibrated on command cycle 1 and tested on the later cycles, the model choice on cycle 1 only:
  the pair diagnosis (:mod:`estimator.offline.pair.diagnosis`: the seed pair model against the
  capstan-joint model and the pair-level effects; causes, extended model, gain), one parameter set
  for all configurations with K growing with the bend, its structure chosen by leave-one-
  configuration-out on the training cycles, its leave-one-out predictions and its bootstrap
  uncertainty, saved under ``shared.params`` (:mod:`estimator.offline.pair.shared`,
  :mod:`estimator.offline.pair.general`), and the Finding 1 baselines (force path, linear map, linear map
  through a play operator, model-free reversal dead zones). A few minutes.
* ``teleop analyze --kaist DIR2 --shared-params OUT``: every configuration of DIR2 predicted with the
  set saved by ``--json OUT``, nothing refitted (``shared_prediction.<N>.rmse_deg``).

``--json OUT`` writes the result (summary numbers, never per-sample data); ``--report DIR`` a
Markdown report with PNG figures (:func:`study.report.write_report`,
:func:`study.kaist.report.write_kaist_report`); ``--figures DIR`` the KAIST plots ``kaist_*.png``;
``--model-out OUTDIR`` the chosen model of each configuration as a model file the live estimator runs
(:mod:`study.kaist.model_file`; ``--mrd``: :mod:`study.mrd.model_file`; FILE.csv: the one file OUT.yaml
with ``--instrument ID``, :mod:`study.tendon_model`).
Bad input raises DataError / ConfigError (one line, exit 2).
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from estimator.data import MeasuredData
from estimator.errors import DataError
from estimator.offline.diagnosis.result import Diagnosis, as_diagnosis
from estimator.offline.diagnosis.selection import diagnose_recording
from estimator.offline.pair.diagnosis import diagnose_pair
from estimator.offline.pair.fit import fit_force_path, fit_linear, fit_pair, fit_play_map, reversal_dead_zones, rmse
from estimator.offline.pair.general import shared_analysis
from recorded.kaist import KaistRecording, split
from recorded.kaist_files import is_kaist_file
from study.kaist.inputs import format_prediction, load_kaist_input, predict_kaist
from study.kaist.report import write_kaist_figures, write_kaist_report
from study.kaist.summary import format_kaist
from study.report import format_summary, split_text, write_report
from teleop.errors import ConfigError
from teleop.recording.measured_csv import MAX_MAGNITUDE, read_measured_csv, values_error
from teleop.recording.text_files import check_text_head, require_file

__all__ = [
    "add_arguments", "main_analyze", "diagnose_file", "configured_route", "format_diagnosis", "analyze_kaist",
    "PROGRESS_SAMPLES",
]

#: Recordings of at least this many samples get a progress bar on stderr (100 s at 1 kHz).
PROGRESS_SAMPLES = 100_000


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the ``analyze`` options to ``parser``."""
    parser.add_argument("file", nargs="?", metavar="FILE",
                        help="measured-data CSV (one tendon), or a KAIST sine_config_N.txt")
    parser.add_argument("--kaist", nargs="?", const="", default=None, metavar="DIR",
                        help="analyse every KAIST configuration in DIR: sine_config_<N>.txt, or a clone of the source "
                             "repository (its root or optimization/selected/) (default DIR: kaist-tsm or "
                             "hysteresis_compensation_ROS in $TSM_TELEOP_DATA, docs/how-to/get-the-data.md)")
    parser.add_argument("--configs", metavar="N[,N...]",
                        help="KAIST mode: only these configurations (bend N [deg]), e.g. 0,60,120,180,240")
    parser.add_argument("--mrd", nargs="?", const="", default=None, metavar="DIR",
                        help="jaw torque and angle of a da Vinci tool from its spindle: every *.TXT run of a folder, "
                             "a Tool_ folder or a clone of the source repository (its root or data/: "
                             "Tool_4_Maryland_L_2) (default DIR: the MRD data in $TSM_TELEOP_DATA)")
    parser.add_argument("--calibration", metavar="RUN[,RUN]|mid|kinematic:RUN|segment:SECONDS|gain=G:RUN",
                        help="MRD mode: calibrate on one run (default: the slowest, lightest; mid: the run whose "
                             "spindle band centre is nearest the folder's middle), on several runs together, "
                             "or on the first SECONDS of every run; gain=G:RUN gives the one-run calibration a "
                             "design load gain G (jaw torque per N m of spindle band-centre shift, about "
                             "1 / (r cosh K)) in place of the encoders' 1 / n_k; G may be the JSON of "
                             "`teleop analyze --mrd OTHER --json OUT` (OTHER's centre_map.load_gain: another tool "
                             "of the same model, fitted across its loads)")
    parser.add_argument("--runs", metavar="GLOB",
                        help="MRD mode: only the runs whose file name (without .TXT) matches GLOB, e.g. '1*': one "
                             "jaw stopping position of a folder that holds several")
    parser.add_argument("--json", metavar="OUT", help="write the result (summary numbers) as JSON to OUT")
    parser.add_argument("--report", metavar="DIR", help="write a Markdown report with PNG figures to DIR")
    parser.add_argument("--model-out", metavar="OUT",
                        help="write the chosen model as a model file the live estimator runs (estimator.model, "
                             "--model): FILE.csv: the file OUT (.yaml); --kaist: OUT/<recording stem>.model.yaml per "
                             "configuration; --mrd: OUT/<folder name>.model.yaml (docs/reference/formats.md, "
                             "\"Model file\")")
    parser.add_argument("--instrument", metavar="ID",
                        help="CSV mode with --model-out: the instrument id the model file is for (default: the "
                             "default config's instrument.id)")
    parser.add_argument("--figures", metavar="DIR",
                        help="write the plots to DIR (kaist_*.png with --kaist, mrd_*.png with --mrd)")
    parser.add_argument("--bend", type=float, metavar="DEG",
                        help="KAIST mode: bend angle N [deg] of a FILE not named sine_config_<N>.txt")
    parser.add_argument("--columns", metavar="MAP",
                        help="KAIST mode: column map, e.g. time=0,command=1,angle=3,T_a=4,T_b=5[,units=rad] "
                             "(default: the 8-column KAIST layout)")
    parser.add_argument("--shared-params", metavar="JSON",
                        help="KAIST mode: predict every configuration with the shared parameter set saved by "
                             "--json (its shared.params); nothing is refitted")
    parser.add_argument("--bootstrap", type=int, default=20, metavar="B",
                        help="KAIST mode: bootstrap draws for the uncertainty of the shared parameters and of "
                             "every reported held-out figure (0: none; default 20)")
    parser.add_argument("--route", metavar="CONFIG",
                        help="CSV mode: hold the route of CONFIG's sheath (its runs: where the friction sits) "
                             "instead of fitting it; for an instrument whose route is known from its design")
    parser.add_argument("--train-fraction", type=float, default=0.6, metavar="F",
                        help="CSV mode: nominal share of the duration used for fitting, in [0.3, 0.9]; the "
                             "split moves to a rest within 8%% of it (default 0.6)")


def main_analyze(args: argparse.Namespace) -> int:
    """Run the subcommand; returns the exit code (0). Raises DataError / ConfigError on bad input."""
    if getattr(args, "mrd", None) is not None:
        from study.mrd.report import main_mrd  # lazy: the MRD analysis and its figures
        try:
            return main_mrd(args)
        except (ArithmeticError, ValueError) as e:   # not one of ours: a fit the runs' values spoiled
            if isinstance(e, (DataError, ConfigError)):
                raise
            from recorded.mrd import load_mrd_dir, values_error
            raise values_error(load_mrd_dir(args.mrd or None, getattr(args, "runs", None))[0], e) from None
    if args.file is None and args.kaist is None:
        raise ConfigError("analyze needs FILE or --kaist [DIR]")
    if getattr(args, "tool", None) is not None:
        raise ConfigError(f"--tool {args.tool}: a tool's constants are for the spindle analysis (--mrd DIR)")
    if args.json is not None and not Path(args.json).resolve().parent.is_dir():
        raise ConfigError(f"--json {args.json}: directory {Path(args.json).resolve().parent} does not exist")
    kaist = (args.kaist is not None or is_kaist_file(args.file) or args.bend is not None or args.columns is not None
             or args.shared_params is not None or getattr(args, "configs", None) is not None)
    for opt, d in (("--report", args.report), ("--figures", args.figures),
                   ("--model-out", getattr(args, "model_out", None) if kaist else None)):
        if d is not None and Path(d).exists() and not Path(d).is_dir():
            raise ConfigError(f"{opt} {d}: exists and is not a directory")
    if args.file is not None:
        require_file(args.file)
    if getattr(args, "model_out", None) is not None and kaist and args.shared_params is not None:
        raise ConfigError(f"--model-out {args.model_out}: model files are written by a diagnosis (FILE.csv, --kaist) "
                          "and the MRD analysis (--mrd DIR --tool T), not by --shared-params")
    if getattr(args, "instrument", None) is not None and (kaist or getattr(args, "model_out", None) is None):
        raise ConfigError(f"--instrument {args.instrument}: names the instrument of a single-tendon model file "
                          "(FILE.csv --model-out OUT.yaml)")
    if kaist:
        if args.route is not None:
            raise ConfigError("--route is for a single-tendon CSV; the KAIST pair models have no sheath route")
        recs = load_kaist_input(args)
        if args.shared_params is not None:
            summary = predict_kaist(recs, args.shared_params)
            print(format_prediction(summary))
        else:
            if not 0 <= args.bootstrap <= 1000 or 0 < args.bootstrap < 5:
                raise ConfigError(f"--bootstrap must be 0 or in [5, 1000], got {args.bootstrap}")
            summary, fits = analyze_kaist(recs, progress=sys.stderr.isatty(), n_bootstrap=args.bootstrap)
            print(format_kaist(summary))
            if args.figures:
                for p in write_kaist_figures(recs, fits, summary, args.figures):
                    print(f"wrote {p}")
            if args.report is not None:
                print(f"wrote {write_kaist_report(recs, fits, summary, args.report)}")
            if getattr(args, "model_out", None) is not None:
                from study.kaist.model_file import write_kaist_models
                for p in write_kaist_models(recs, summary, fits, args.model_out):
                    print(f"wrote {p}")
    else:
        if args.figures:
            raise ConfigError("--figures is for the KAIST analysis (--kaist); use --report DIR")
        if getattr(args, "model_out", None) is not None:
            from study.tendon_model import check_model_out
            check_model_out(args.model_out, args.instrument, args.route)
        shape, how = (None, None) if args.route is None else configured_route(args.route)
        result, data = diagnose_file(args.file, train_fraction=args.train_fraction, wrap_shape=shape)
        if how is not None:
            result.extra["route"] = how
        print(format_diagnosis(result))
        if args.report is not None:
            print(f"wrote {write_report(result, data, args.report)}")
        if getattr(args, "model_out", None) is not None:
            from study.tendon_model import write_model_out
            print(f"wrote {write_model_out(result, data, args.file, args.model_out, args.instrument, args.route)}")
        summary = result.to_json()
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

def configured_route(path: str | Path) -> tuple[np.ndarray, str]:
    """The route shape of the ``sheath`` of a config file, for ``diagnose(..., wrap_shape=...)``.

    Returns (normalised cumulative wrap angle, shape (257,); a one-line description naming the file).

    Raises
    ------
    ConfigError
        The file is missing, a directory, not UTF-8 text or not a valid config, or its route has no bend (no
        shape to hold).
    """
    from slave.calibrate import wrap_shape
    from teleop.config.load import load_config
    try:
        check_text_head(require_file(path))
    except DataError as e:
        raise ConfigError(f"--route {e}") from None
    geo = load_config(path).sheath.geometry()
    shape = wrap_shape(geo)
    if shape is None:
        raise ConfigError(f"--route {path}: the sheath's route ({len(geo.runs)} runs) has no bend, so there is no "
                          "route shape to hold")
    bends = sum(1 for r in geo.runs if math.isfinite(r.radius))
    return shape, (f"route held from {path}: {len(geo.runs)} runs ({bends} bent), {geo.length:.3g} m, "
                   f"{math.degrees(geo.total_angle):.0f} deg of bend")


def diagnose_file(path: str | Path, train_fraction: float = 0.6,
                  progress: bool | None = None,
                  wrap_shape: np.ndarray | None = None) -> tuple[Diagnosis, MeasuredData]:
    """Diagnose one measured-data CSV (:func:`estimator.offline.diagnosis.selection.diagnose_recording`).

    Parameters
    ----------
    path : the CSV (docs/reference/formats.md): time [s], x_in [m], T_in [N], and T_out [N] and/or x_out [m]
    train_fraction : nominal share of the duration used for fitting, in [0.3, 0.9]
    progress : stderr progress bar; default: on for recordings of at least
        :data:`PROGRESS_SAMPLES` samples
    wrap_shape : the route shape to hold (:func:`configured_route`), shape (n,); None: fitted

    Returns
    -------
    result : Diagnosis
        The diagnosis (cause, causes, base and extended {rmse_T_out_N, rmse_x_out_m}, gain,
        parameters, candidates, ...; ``.to_json()`` for the JSON) with ``file``, ``n_samples`` and
        ``duration_s`` in its ``extra``.
    data : MeasuredData, the recording (for :func:`study.report.write_report`)

    Raises
    ------
    DataError
        Missing or malformed file, neither T_out nor x_out, a recording too short to diagnose, a value beyond
        :data:`teleop.recording.measured_csv.MAX_MAGNITUDE` (its line and column), values that make the diagnosis'
        arithmetic fail (the line and column of the value farthest out of its column).
    ConfigError
        ``train_fraction`` outside [0.3, 0.9].
    """
    if not 0.3 <= train_fraction <= 0.9:
        raise ConfigError(f"--train-fraction must be in [0.3, 0.9], got {train_fraction!r}")
    data = read_measured_csv(path, limits=MAX_MAGNITUDE).require_distal()
    try:
        result = diagnose_recording(data, train_fraction=train_fraction, wrap_shape=wrap_shape,
                                    progress=len(data) >= PROGRESS_SAMPLES if progress is None else progress)
    except ArithmeticError as e:                     # a division by zero, an overflow: values far out of range
        raise values_error(data, e) from None
    except ValueError as e:
        if "infs or NaNs" in str(e):                 # an overflow that reached a linear-algebra routine as inf
            raise values_error(data, e) from None
        raise DataError(str(e) if str(e).startswith(data.source) else f"{data.source}: {e}") from None
    result.extra.update({"file": str(path), "n_samples": len(data), "duration_s": data.duration})
    return result, data


def format_diagnosis(result: Diagnosis | dict) -> str:
    """The lines printed for one CSV: :func:`study.report.format_summary`, then the split and the
    fitted parameters of the extended model (SI units). ``result`` carries ``file``, ``n_samples`` and
    ``duration_s`` (:func:`diagnose_file`), and ``route`` when the route was held."""
    r = as_diagnosis(result)
    pars = ", ".join(f"{k} = {p['value']:.4g}" + ("" if p["unit"] in ("", "-") else f" {p['unit']}")
                     for k, p in r.parameters.items())
    held = r.settings.get("distal_end_held")
    note = [] if not held else [
        f"x_out set aside: it moves {1e6 * held['range_m']:.3g} um, "
        f"{100 * held['range_m'] / held['travel_m']:.2g} % of "
        f"x_in's {1e3 * held['travel_m']:.3g} mm travel - the distal end pressed on a stop, whose deflection the base "
        "model reads as elongation: with x_out structure was left that no effect explains, without it none"
        if held.get("pressed") else
        f"x_out set aside: it stays within {1e6 * held['range_m']:.3g} um over the recording (resolution "
        f"{1e6 * held['step_m']:.3g} um, x_in travel {1e3 * held['travel_m']:.3g} mm) - the distal end was held "
        "(a stop, or a load the tension never moved), so x_out shows nothing of the tendon"]
    at_end = r.settings.get("distal_at_end")
    if at_end and at_end["hides"]:
        note.append(f"x_out sits within {1e6 * at_end['band_m']:.2g} um of an end of its "
                    f"{1e3 * at_end['range_m']:.3g} mm "
                    f"range for {100 * at_end['share']:.0f} % of the proximal travel (a distal end held on a stop, or "
                    "a load not lifted): " + ", ".join(at_end["hides"])
                    + " cannot show in this recording, whatever the answer")
    if r.extra.get("route"):
        note.append(r.extra["route"])
    return "\n".join([f"{r.extra['file']}: {r.extra['n_samples']} samples, {r.extra['duration_s']:.1f} s "
                      f"(diagnosed in {r.elapsed_s:.1f} s)", split_text(r), *note,
                      format_summary(r), f"parameters: {pars}"])


# ---- KAIST antagonistic pair ------------------------------------------------------------------

def _kaist_one(rec: KaistRecording) -> tuple[dict, dict]:
    c1, c2, how = split(rec)
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
               "import_notes": list(rec.notes), "split": how, "pretension": list(rec.pretension),
               "cycle1": [float(rec.time[c1.start]), float(rec.time[min(c1.stop, len(rec) - 1)])],
               "cycle2": [float(rec.time[c2.start]), float(rec.time[min(c2.stop, len(rec) - 1)])],
               "angle_range_deg": [math.degrees(float(rec.angle.min())), math.degrees(float(rec.angle.max()))],
               "models": models,
               "dead_zones": [{"time": float(rec.time[z.index]), "command_deg": math.degrees(rec.command[z.index]),
                               "command_travel_deg": _finite(math.degrees(z.command_travel)),
                               "K_release": _finite(z.K_release), "K_pull": _finite(z.K_pull)} for z in zones]}
    return summary, {"fits": fits, "cycles": (c1, c2)}


def _labelled(tick: Callable[[str], None], prefix: str) -> Callable[[str], None]:
    """A progress callback that prefixes each label (one per recording)."""
    return lambda label: tick(prefix + label)


def analyze_kaist(recs: list[KaistRecording], progress: bool = False,
                  n_bootstrap: int = 20) -> tuple[dict, list[dict]]:
    """Every KAIST configuration: the pair diagnosis, the shared fit and the Finding 1 baselines.

    Per configuration (train on command cycle 1, test on cycle 2): the seed pair model beside the
    force path, the linear map and the linear map + play, the model-free reversal dead zones, and
    the pair diagnosis (:func:`estimator.offline.pair.diagnosis.diagnose_pair`: the seed model against the
    capstan-joint model and the pair-level effects). Across configurations: one set of physical
    parameters with K growing with the bend angle (:func:`estimator.offline.pair.general.shared_analysis`).

    Parameters
    ----------
    recs : recordings, one per configuration
    progress : a status line on stderr (the analysis takes a few minutes)
    n_bootstrap : bootstrap draws of the shared set's uncertainty and of every reported held-out figure
        (per configuration and leave-one-out; 0: none)

    Returns
    -------
    summary : dict, JSON-ready
        ``mode`` ("kaist"), ``configurations`` (one dict per recording: config_deg, cycle times,
        models {name: {params, rmse_train_deg, rmse_test_deg, max_abs_test_deg}}, dead_zones,
        ``diagnosis`` (the pair diagnosis: seed, extended, cause, causes, gain, candidates) and
        ``shared`` {model, rmse_test_deg, leave_one_out_rmse_test_deg, K_a, K_b} of the chosen shared
        structure), ``shared`` (every shared model, the choice, leave-one-out, the E6 test, mu, the
        exported set ``params`` with its uncertainty) and ``trend``: least-squares line of the mean
        release-side band exponent K_release against the configuration angle [rad]
        (``K_release_per_rad``, ``K_release_at_0``), when >= 2 configurations.
    details : list of dict
        Per recording: ``fits`` (name -> PairFit), ``cycles``, ``pair_fits`` (model id -> FitResult),
        ``extended`` (its id), ``shared_angle``, ``loco_angle`` [rad]; for the figures.

    Raises
    ------
    DataError
        A recording without two complete command cycles.
    """
    tick = _Status(progress)
    summaries, details = zip(*(_kaist_one(r) for r in recs), strict=False) if recs else ((), ())
    out: dict[str, Any] = {"mode": "kaist", "train": "command cycle 1 (from the first sample)",
                           "test": "the later command cycles", "configurations": list(summaries)}
    train = [d["cycles"][0] for d in details]
    test = [d["cycles"][1] for d in details]
    for rec, s, d, tr, te in zip(recs, summaries, details, train, test, strict=False):
        diag, fits = diagnose_pair(rec, tr, te, progress=_labelled(tick, f"N = {rec.config_deg}: "),
                                   n_bootstrap=n_bootstrap)
        s["diagnosis"], d["pair_fits"], d["extended"] = diag, fits, diag["extended"]["model"]
    Ns = [math.radians(s["config_deg"]) for s in summaries]
    if len(recs) >= 3:
        shared, sdet = shared_analysis(list(recs), Ns, train, test, progress=tick, n_bootstrap=n_bootstrap)
        out["shared"] = shared
        ch = shared["chosen"]
        for i, (s, d) in enumerate(zip(summaries, details, strict=False)):
            row = shared["models"][ch]["configurations"][i]
            s["shared"] = {"model": ch, "rmse_test_deg": row["rmse_test_deg"], "K_a": row["K_a"], "K_b": row["K_b"],
                           "leave_one_out_rmse_test_deg": shared["leave_one_out"][ch][i]["rmse_test_deg"]}
            d["shared_angle"] = sdet["models"][ch][i]
            d["loco_angle"] = sdet["leave_one_out"][ch][i]
    tick.done()
    Kr = [np.nanmean([z["K_release"] if z["K_release"] is not None else np.nan for z in s["dead_zones"]])
          for s in summaries]
    ok = [i for i, k in enumerate(Kr) if math.isfinite(k)]
    if len(ok) >= 2:
        slope, icpt = np.polyfit([Ns[i] for i in ok], [Kr[i] for i in ok], 1)
        out["trend"] = {"K_release_per_rad": float(slope), "K_release_at_0": float(icpt)}
    return out, list(details)


class _Status:
    """A one-line status on stderr (when enabled), overwritten in place."""

    def __init__(self, enabled: bool):
        self.enabled, self.n = enabled, 0

    def __call__(self, label: str) -> None:
        self.n += 1
        if self.enabled:
            sys.stderr.write(f"\ranalyze --kaist: {self.n:3d} models fitted, {label:<60.60}")
            sys.stderr.flush()

    def done(self) -> None:
        if self.enabled and self.n:
            sys.stderr.write("\n")
