"""The calibration of a spindle-driven pair on recorded MRD runs (``teleop analyze --mrd``, the recording rig):
which runs calibrate (``--calibration``), a design load gain, the signals each run gives the fits, and the fit
of the calibration data (docs/results/mrd.md).

The model's *inputs* are always the spindle torque and angle; the calibration's jaw torque and angle are
the fit *targets*. Scored runs never contribute a distal sample.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from estimator.errors import DataError
from estimator.offline.spindle.fit import EXTENSIONS, band_centre, fit_baselines
from estimator.offline.spindle.shared import RunData, batch_of, kinematic_ratio, select_extensions, shared_fit
from estimator.online.spindle import SpindleParams, first_reversal, make_batch, predict_torque
from recorded.mrd import MrdRun
from recorded.mrd_centre import (
    CENTRE,
    centre_implied_gain,
    centre_one_run,
    implied_load_gain,
    mid_centre_run,
    model_choice,
)
from teleop.errors import ConfigError
from teleop.recording.text_files import read_text

__all__ = ["SCORE_FROM_S", "FIT_STEP", "LOAD_SCALING", "run_data", "split_design_gain", "design_gain",
           "parse_calibration", "calibrate", "CAL_INPUTS", "calibrate_on_runs"]

SCORE_FROM_S = 0.5         # the first reversal is searched after this [s] (the load motor ramps in first)
FIT_STEP = 10              # decimation of the calibration fits (1 kHz -> 100 Hz)
#: Extensions that scale with the load (band growth, torque ratio along the stroke): at one load level they
#: trade off against the fixed torque scale and extrapolate wildly (on run 00 K_b sent K_a to its bound), so the
#: ``kinematic:`` calibration does not offer them.
LOAD_SCALING = ("K_b", "rho_1", "rho_2")
#: The signals a calibration reads as the model's inputs and as its fit targets.
CAL_INPUTS = {"inputs": ["spindle torque", "spindle encoder"], "targets": ["jaw torque", "jaw encoder"]}

def run_data(r: MrdRun, stop: int | None = None) -> RunData:
    """The signals of run ``r`` (up to sample ``stop``) as the fits read them, scored from its first spindle
    reversal after :data:`SCORE_FROM_S` (the load motor ramps in first)."""
    n = len(r) if stop is None else stop
    return RunData(r.name, r.tau_p[:n], r.theta_p[:n], r.tau_d[:n], r.theta_d[:n],
                   min(first_reversal(r.theta_p, r.dt, SCORE_FROM_S), n - 2), r.dt)


def split_design_gain(spec: str | None) -> tuple[float | None, str | None]:
    """(design load gain, the rest of the spec) from ``--calibration gain=G:SPEC`` (G > 0: the tool's jaw torque
    per N m of spindle band-centre shift, about 1 / (r cosh K), from its design; the centre map uses it instead of
    1 / n_k or a fit; G may be another folder's JSON, :func:`_gain_from_json`); (None, spec) without the prefix.
    Raises ConfigError for a G that is not a positive number or such a JSON, or a segment calibration (the
    centre map has none)."""
    g, rest, _ = design_gain(spec)
    return g, rest


def design_gain(spec: str | None) -> tuple[float | None, str | None, str | None]:
    """:func:`split_design_gain` and the JSON the gain was read from (None for a number or no gain)."""
    if not spec or not spec.startswith("gain="):
        return None, spec, None
    head, _, rest = spec.partition(":")
    source = None
    try:
        g = float(head[len("gain="):])
    except ValueError:
        # a JSON path may hold ':' itself (C:\..., a:b/...): the split is after the longest prefix that is a file
        body = spec[len("gain="):]
        ends = [len(body)] + [i for i in range(len(body) - 1, -1, -1) if body[i] == ":"]
        at = next((i for i in ends if Path(body[:i]).is_file()), None)
        if at is not None:
            head, rest = "gain=" + body[:at], body[at + 1:]
        source = head[len("gain="):]
        g = _gain_from_json(spec, source)
    if not (math.isfinite(g) and g > 0.0):
        raise ConfigError(f"--calibration {spec}: the load gain G must be positive")
    if rest.startswith("segment:"):
        raise ConfigError(f"--calibration {spec}: a design gain applies to run calibrations, not to segment:")
    return g, rest, source


def _gain_from_json(spec: str, path: str) -> float:
    """``centre_map.load_gain.value`` of a JSON written by ``teleop analyze --mrd OTHER --json PATH`` (another
    folder's load gain fitted across its loads). Raises ConfigError naming what is missing."""
    import json
    f = Path(path)
    try:
        text = read_text(f)
    except DataError as e:
        raise ConfigError(f"--calibration {spec}: G in gain=G:RUN must be a number or the JSON of "
                          f"`teleop analyze --mrd OTHER --json OUT` ({e})") from None
    try:
        lg = json.loads(text)["centre_map"]["load_gain"]
    except (ValueError, KeyError, TypeError):
        raise ConfigError(f"--calibration {spec}: {f} has no centre_map.load_gain (write it with "
                          "`teleop analyze --mrd OTHER --json OUT`, folder fit on)") from None
    if not lg.get("several_loads", False):
        raise ConfigError(f"--calibration {spec}: {f} comes from a folder of one load level; its load gain "
                          "is not identified there")
    return float(lg["value"])


def parse_calibration(spec: str | None, runs: list[MrdRun]) -> tuple[str, Any]:
    """("run", names), ("kinematic", names) or ("segment", seconds) from ``--calibration``: ``RUN`` or
    ``RUN,RUN,...`` (calibrate on those runs together, score the others), ``kinematic:RUN[,RUN...]``
    (the same with rho = 1 / n_k from the calibration runs' encoders), ``mid`` (the run whose spindle band
    centre is nearest the middle of the folder's: a rule fixed before scoring), or ``segment:SECONDS``; default
    the slowest, lightest run. ``names`` is the comma-separated string.

    Raises ConfigError for an unknown run name, every run named, or a segment outside
    [1, half the shortest run] s; DataError for a run calibration of a single run (the folder's only usable
    run, or the one --runs picks): no run would be left to score, and the message names the segment calibration
    that analyses it.
    """
    names = [r.name for r in runs]
    if len(runs) == 1 and not (spec or "").startswith("segment:"):
        seconds = max(1, int(0.4 * float(runs[0].time[-1])))
        raise DataError(f"{Path(runs[0].source).parent}: one run to analyse ({names[0]}), and a run calibration "
                        "scores the other runs: give a folder of two runs or more, or calibrate on the run's first "
                        f"seconds and score the rest with --calibration segment:SECONDS (e.g. segment:{seconds})")
    if spec is None or spec == "":
        r = min(runs, key=lambda r: (round(r.frequency_hz, 3), r.load_level, r.name))
        return "run", r.name
    if spec.startswith("segment:"):
        try:
            s = float(spec.split(":", 1)[1])
        except ValueError:
            raise ConfigError(f"--calibration {spec}: SECONDS must be a number") from None
        shortest = min(float(r.time[-1]) for r in runs)
        if not 1.0 <= s <= 0.5 * shortest:
            raise ConfigError(f"--calibration {spec}: SECONDS must be in [1, {0.5 * shortest:.1f}]")
        return "segment", s
    mode = "run"
    if spec in ("mid", "kinematic:mid"):        # the run of the middle band centre (spindle torque only)
        spec = spec.replace("mid", mid_centre_run([run_data(r) for r in runs]))
    if spec.startswith("kinematic:"):
        mode, spec = "kinematic", spec.split(":", 1)[1]
    asked = [n.strip() for n in spec.split(",") if n.strip()]
    unknown = [n for n in asked if n not in names]
    if unknown or not asked:
        raise ConfigError(f"--calibration {spec}: no run named {', '.join(unknown) or spec!r} "
                          f"(runs: {', '.join(names)})")
    if len(set(asked)) == len(names):
        raise ConfigError(f"--calibration {spec}: every run is a calibration run, none is left to score")
    return mode, ",".join(dict.fromkeys(asked))


def calibrate(cal: list[RunData], tick, kinematic: bool = False) -> tuple[dict, dict, dict, float, float]:
    """Base and selected models plus the baselines on calibration data; (fits, baselines, selection, centre, ref).
    ``kinematic`` fixes rho = 1 / n_k (:func:`kinematic_ratio` of the calibration data)."""
    centre = float(np.mean([band_centre(c.tau_p) for c in cal]))
    ref = float(np.mean([np.mean(c.theta_p) for c in cal]))
    fixed: tuple[str, ...] = ("rho",) if kinematic else ()
    start = SpindleParams(rho=1.0 / kinematic_ratio(cal)) if kinematic else None
    cands = tuple(c for c in EXTENSIONS if not (kinematic and c in LOAD_SCALING))
    sel = select_extensions(cal, centre, ref, FIT_STEP, candidates=cands, progress=tick, fixed=fixed, start=start)
    fits = {"pair": shared_fit(cal, (), centre, ref, FIT_STEP, start=SpindleParams(**sel["base"]["params"]),
                               fixed=fixed)}
    if sel["chosen"]:
        fits["pair+" + "+".join(sel["chosen"])] = shared_fit(cal, tuple(sel["chosen"]), centre, ref, FIT_STEP,
                                                             start=SpindleParams(**sel["params"]), fixed=fixed)
    tick("calibrated")
    bt, yt, ya, w = batch_of(cal, centre, ref, FIT_STEP)
    base = fit_baselines(bt, yt, ya, mask=w > 0)
    tick("baselines")
    return fits, base, sel, centre, ref


def calibrate_on_runs(runs: list[MrdRun], mode: str, cal: str, calibration: str | None,
                       gain: tuple[float | None, str | None], fs: float, tick, out: dict) -> tuple[list, Any, list]:
    """Calibrate on the named runs (``mode`` "run" or "kinematic"), choose the headline model and record the
    calibration in ``out``; returns the plan of the scored runs, the centre map and the calibration RunData."""
    given, source = gain
    cal_names = str(cal).split(",")
    cal_runs = [run_data(r) for r in runs if r.name in cal_names]
    fits, base, sel, centre, ref = calibrate(cal_runs, tick, kinematic=mode == "kinematic")
    cmap, out["centre_calibration"] = centre_one_run(cal_runs, fs, given)
    sel_name = list(fits)[-1]               # the pair model with the selected extensions
    sel_p = fits[sel_name]
    pin = np.concatenate([predict_torque(sel_p, make_batch([(c.tau_p, c.theta_p)], centre, ref, c.dt))[
        c.k0:] - c.tau_d[c.k0:] for c in cal_runs])
    gains = {sel_name: implied_load_gain(lambda c, u: predict_torque(sel_p, make_batch(
                 [(c.tau_p + u, c.theta_p)], centre, ref, c.dt)), cal_runs),
             CENTRE: centre_implied_gain(cmap, cal_runs)}
    out["model_choice"] = model_choice(sel_name, float(sel["rmse_val"]) / fs, float(np.sqrt(np.mean(pin ** 2))) / fs,
                                       cal_runs, fs, out["centre_calibration"]["fit_rms_fs"], gains, given)
    out["calibration"] = {"mode": mode, "run": cal, "runs": cal_names, **CAL_INPUTS,
                          "scored": "every other run, from its spindle signals only"}
    if given is not None:
        dg: dict[str, Any] = {"value": given, "from": "--calibration gain=G: a design value from outside the "
                              "data (the centre map's load gain)"}
        if source is not None:
            dg.update({"from": f"centre_map.load_gain of {source} (another folder's map fitted across its loads; "
                               "--calibration gain=FILE)", "source": source})
        out["calibration"]["design_load_gain"] = dg
    if calibration and calibration.endswith("mid"):
        out["calibration"]["chosen_by"] = ("the run whose band centre (spindle torque only) is nearest the middle "
                                           "of the folder's band centres, a rule fixed before any score")
    if mode == "kinematic":
        n_k = kinematic_ratio(cal_runs)
        out["calibration"]["fixed"] = {"rho": {
            "value": 1.0 / n_k, "n_k": n_k,
            "from": "1 / n_k, n_k = slope of jaw encoder against spindle encoder in full motion (middle 60 % "
                    "of the stroke, an offset per direction) of the calibration run(s): the jaw encoder is a "
                    "distal reading of the calibration run; the pulley radii ratio r_d / r_p, equal to the "
                    "torque scale only if both torque sensors share one gain and no power is lost in the "
                    "band centre"}}
    plan = [(r, fits, base, centre, ref, run_data(r).k0) for r in runs if r.name not in cal_names]
    out["parameters"] = {n: p.as_dict() for n, p in fits.items()}
    out["baseline_parameters"] = {n: b.params for n, b in base.items()}
    out["selection"] = sel
    return plan, cmap, cal_runs
