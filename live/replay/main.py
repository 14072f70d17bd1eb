"""``teleop replay RUN``: a recorded session played back through the estimator and the Rerun view.

A joint instrument's run (``slave_joints.csv``) is replayed joint by joint by
:mod:`live.replay.joints`; the rest of this docstring is the single tendon's.

RUN is a run directory (``runs/<id>/`` with ``slave.csv``, ``config.yaml`` and
``calibration/<instrument>.yaml`` or ``calibration.json``) or a ``slave.csv``. The proximal signals
(``time``, ``T_in``, ``x_in``) are re-estimated with the run's own config and calibration, or with
the given ones (``--config``, ``--calibration``), by the profile-memory estimator the slave runs
(:func:`estimator.online.distal.estimate_batch`, the same maths as its :class:`DistalEstimator`) or by the
paper's phase formulas (:func:`estimator.capstan.phase_formula_batch`, Phee et al. 2009). The new
estimate is compared with the recorded one (``T_out_hat``, ``elongation_hat``) and with the truth
(``T_out``, ``elongation`` or ``x_in - x_out``) when the recording has them: max and mean absolute
errors as fractions of the full scale (range) of the reference, over the whole run and per
experiment (``marker``), as ``teleop demo`` reports them.

The comparison with the recorded estimate is made on the recording's own samples, at its own rate (a
``slave.csv`` every ``recording.csv_every`` cycles, the MCAP estimate channel at its own rate): the
re-estimate runs on those samples only, so a decimated stream gives a different figure from the
live 1 kHz estimate's; the table prints each figure's sample count and the recording's rate.

The Rerun view is written with :class:`teleop.rerun.logger.RerunLogger` (the live view's helpers: route
in 3D, profile, series, phase) into ``RUN/replay.rrd`` by default, never over an existing file
without ``--force`` (nor ``--json``'s); ``--speed realtime`` (or a factor) paces that logging with the wall
clock, ``max`` runs as fast as possible.
"""
from __future__ import annotations

import argparse
import json
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from estimator.capstan import phase_formula_batch
from estimator.data import MeasuredData
from estimator.errors import CalibrationError, DataError
from estimator.online.distal import DistalEstimator, estimate_batch
from estimator.phase import Phase
from estimator.sheath import SheathModel
from live.demo.run import full_scale_errors
from live.kinds import kind_of
from live.replay.joints import find_joint_csv, joint_table_lines, new_output, rate_hz, replay_joints, samples_at
from teleop.config.load import load_config
from teleop.config.schema import Config
from teleop.errors import ConfigError
from teleop.recording.measured_csv import read_measured_csv

__all__ = ["ReplayInput", "load_run", "load_model", "tension_noise", "parse_speed", "reestimate", "compare", "replay",
           "add_arguments", "main_replay"]

EXPERIMENTS = {1: "paper", 2: "minor"}  # marker codes of the operator protocols (live.demo.main)
ESTIMATORS = ("profile", "paper")


@dataclass(frozen=True)
class ReplayInput:
    """A recording to replay: the slave CSV, the run directory (None for a bare CSV), the data."""

    csv: Path
    run_dir: Path | None
    data: MeasuredData


def load_run(run: str | Path) -> ReplayInput:
    """Find and read the recording of ``run`` (a run directory, a ``slave.csv``, or the recorder's ``.mcap``
    file; a run directory without ``slave.csv`` is read from its ``recorder/session.mcap``).

    Raises
    ------
    DataError
        No such directory or file, a directory without ``slave.csv``, or an unreadable CSV (file:line,
        column). A joint instrument's run (``slave_joints.csv``) is :func:`replay`'s other branch.
    """
    path = Path(run)
    if path.suffix == ".mcap" or (path.is_dir() and not (path / "slave.csv").is_file()):
        from live.record.mcap_read import estimate_data, find_mcap, read_session
        mcap = find_mcap(path)
        if mcap is not None:   # the recorder's MCAP file: its estimate channel (live.record.mcap_read)
            run_dir = mcap.parent.parent if mcap.parent.name == "recorder" else mcap.parent
            own = any((run_dir / f).exists() for f in ("config.yaml", "calibration.json", "calibration"))
            return ReplayInput(mcap, run_dir if own else None, estimate_data(read_session(mcap), str(mcap)))
    if path.is_dir():
        csv = path / "slave.csv"
        if not csv.is_file():
            raise DataError(f"{path}: no slave.csv (single tendon), slave_joints.csv (joints) or "
                            f"recorder/session.mcap in it")
        return ReplayInput(csv, path, read_measured_csv(csv))
    if not path.exists():
        raise DataError(f"{path}: no such run directory or file")
    parent = path.parent   # a slave.csv inside its run directory keeps the run's config and calibration
    own = any((parent / f).exists() for f in ("config.yaml", "calibration.json", "calibration"))
    return ReplayInput(path, parent if own else None, read_measured_csv(path))


def _config(run_dir: Path | None, config: str | Path | None) -> Config:
    if config is not None:
        if not Path(config).is_file():
            raise ConfigError(f"{config}: config file not found")
        return load_config(config)
    own = run_dir / "config.yaml" if run_dir is not None else None
    return load_config(own if own is not None and own.is_file() else None)


def load_model(cfg: Config, inp: ReplayInput, calibration: str | Path | None = None) -> tuple[SheathModel, str]:
    """The sheath model to estimate with, and where it came from.

    ``calibration`` is a calibration file (``.yaml``, :func:`slave.calibration_file.load_calibration`)
    or a run's ``calibration.json`` (``K``, ``compliance_m_per_N``, ``use_route``); None takes the
    run's ``calibration/<instrument.id>.yaml``, else its ``calibration.json``.

    Raises
    ------
    CalibrationError
        No calibration found, or a file that is unreadable or wrong (named with the key).
    """
    from slave.calibrate import route_wrap_shape
    from slave.calibration_file import load_calibration, tendon_model

    if kind_of(cfg).replay != "tendon":
        raise ConfigError(f"instrument {cfg.instrument.id} has joints: replay handles single-tendon runs")
    if calibration is None:
        if inp.run_dir is None:
            raise CalibrationError(f"{inp.csv}: a bare CSV has no calibration: give --calibration FILE")
        cands = [inp.run_dir / "calibration" / f"{cfg.instrument.id}.yaml", inp.run_dir / "calibration.json"]
        found = next((c for c in cands if c.is_file()), None)
        if found is None:
            raise CalibrationError(f"{inp.run_dir}: no calibration ({cands[0].name} in calibration/ or "
                                   f"calibration.json): give --calibration FILE")
        calibration = found
    path = Path(calibration)
    if path.suffix != ".json":
        return tendon_model(load_calibration(path, cfg), cfg), str(path)
    try:
        d = json.loads(path.read_text(encoding="utf-8"))
        K, c = float(d["K"]), float(d["compliance_m_per_N"])
    except FileNotFoundError:
        raise CalibrationError(f"{path}: calibration file not found") from None
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise CalibrationError(f"{path}: not a calibration.json with K and compliance_m_per_N ({e!r})") from None
    if not (math.isfinite(K) and K >= 0 and math.isfinite(c) and c > 0):
        raise CalibrationError(f"{path}: K must be >= 0 and compliance_m_per_N > 0, got {K!r}, {c!r}")
    shape = route_wrap_shape(cfg) if d.get("use_route", True) else None
    return SheathModel(K=K, compliance=c, wrap_shape=shape), str(path)


def tension_noise(cfg: Config, source: str) -> float:
    """The noise sigma of T_in [N] for the estimator's noise band: ``cfg.estimator.tension_noise`` when set, else
    the calibration's at ``source`` (a ``.yaml`` calibration file or a run's ``calibration.json``; 0 when it has
    none: the estimator without a band)."""
    if cfg.estimator.tension_noise is not None:
        return float(cfg.estimator.tension_noise)
    from slave.calibration_file import load_calibration

    path = Path(source)
    if path.suffix != ".json":
        tendon = load_calibration(path, cfg).tendon
        return 0.0 if tendon is None else float(tendon.tension_noise)
    v = json.loads(path.read_text(encoding="utf-8")).get("tension_noise_N", 0.0)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v >= 0):
        raise CalibrationError(f"{path}: tension_noise_N must be a number >= 0 [N], got {v!r}")
    return float(v)


def parse_speed(text: str) -> float:
    """``realtime`` -> 1.0, ``max`` -> inf, a number > 0 -> that factor of real time.

    Raises
    ------
    ConfigError
        Anything else.
    """
    if text == "realtime":
        return 1.0
    if text == "max":
        return math.inf
    try:
        v = float(text)
    except ValueError:
        v = math.nan
    if not (v > 0):
        raise ConfigError(f"--speed: expected realtime, max or a factor > 0, got {text!r}")
    return v


def reestimate(data: MeasuredData, model: SheathModel, cfg: Config, estimator: str = "profile",
               noise: float = 0.0) -> dict[str, np.ndarray]:
    """New estimates over the recording: ``T_out`` [N], ``elongation`` [m], ``phase`` (int8), shape (n,).

    ``profile``: :func:`estimate_batch` with the slave's settings (``cfg.estimator``, pretension, the noise band of
    T_in's noise sigma ``noise`` [N], :func:`tension_noise`);
    ``paper``: :func:`phase_formula_batch` with the demo's deadband (10 x load-cell noise, >= 0.1 N).
    """
    if estimator == "profile":
        e = cfg.estimator
        b = estimate_batch(data.T_in, data.x_in, model, time=data.time, n_nodes=e.n_nodes,
                           pretension=cfg.sheath.pretension, hold_rate=e.hold_rate,
                           rate_time_constant=e.rate_time_constant, tension_noise=noise)
        return {"T_out": b.T_out, "elongation": b.elongation, "phase": b.phase}
    if estimator == "paper":
        from live.demo.main import baseline_deadband
        T, el, ph = phase_formula_batch(data.T_in, model.K, model.compliance, deadband=baseline_deadband(cfg),
                                        T0=cfg.sheath.pretension)
        return {"T_out": T, "elongation": el, "phase": ph}
    raise ConfigError(f"--estimator: expected one of {', '.join(ESTIMATORS)}, got {estimator!r}")


def _errors(T: np.ndarray, e: np.ndarray, T_ref: np.ndarray, e_ref: np.ndarray) -> dict[str, float]:
    fmax, fmean = full_scale_errors(T, T_ref)
    emax, emean = full_scale_errors(e, e_ref)
    return {"force_error_max_fs": fmax, "force_error_mean_fs": fmean, "elongation_error_max_fs": emax,
            "elongation_error_mean_fs": emean, "force_full_scale_N": float(np.ptp(T_ref)),
            "elongation_full_scale_m": float(np.ptp(e_ref)), "samples": int(T.size)}


def compare(data: MeasuredData, new: dict[str, np.ndarray]) -> dict[str, dict[str, dict[str, float]]]:
    """Full-scale errors of the new estimate: ``{block: {"vs_recorded"|"vs_truth": {...}}}``.

    Blocks: ``all`` and, with a ``marker`` column, each experiment run (``paper``, ``minor``). A
    reference the recording lacks is left out. Errors are NaN when the reference has no range.
    """
    refs: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    x = data.extra
    if "T_out_hat" in x and "elongation_hat" in x:
        refs["vs_recorded"] = (x["T_out_hat"], x["elongation_hat"])
    if data.T_out is not None and ("elongation" in x or data.x_out is not None):
        refs["vs_truth"] = (data.T_out, x["elongation"] if "elongation" in x else data.x_in - data.x_out)
    blocks = {"all": np.ones(data.time.size, dtype=bool)}
    if "marker" in x:
        for m, name in EXPERIMENTS.items():
            sel = x["marker"].astype(int) == m
            if sel.any():
                blocks[name] = sel
    return {b: {k: _errors(new["T_out"][sel], new["elongation"][sel], T[sel], e[sel]) for k, (T, e) in refs.items()}
            for b, sel in blocks.items()}


def _log(inp: ReplayInput, cfg: Config, model: SheathModel, new: dict[str, np.ndarray], estimator: str,
         speed: float, rrd: Path, noise: float = 0.0) -> None:
    """The live view's logging (every ``log_every`` samples, a profile every ``profile_every`` of those),
    paced with the wall clock at ``speed`` x real time (inf: no pacing)."""
    from teleop.rerun.logger import RerunLogger

    d, x = inp.data, inp.data.extra
    n, every = d.time.size, max(1, cfg.recording.log_every)
    rec_T, rec_e = x.get("T_out_hat"), x.get("elongation_hat")
    true_e = x["elongation"] if "elongation" in x else None if d.x_out is None else d.x_in - d.x_out
    s = np.linspace(0.0, cfg.sheath.geometry().length, cfg.estimator.profile_points)
    e = cfg.estimator
    est = DistalEstimator(model, n_nodes=e.n_nodes, pretension=cfg.sheath.pretension, hold_rate=e.hold_rate,
                          rate_time_constant=e.rate_time_constant, tension_noise=noise)
    u, done = est.positions, 0
    run_id = inp.run_dir.name if inp.run_dir is not None else inp.csv.stem
    wall0, t0 = time.monotonic(), float(d.time[0])
    with RerunLogger("teleop-replay", f"{run_id}-replay", "save", rrd, route=cfg.sheath.runs,
                     wall_clock=True) as rr:   # the recording's time on both timelines
        for k in range(0, n, every):
            t = float(d.time[k])
            if math.isfinite(speed):
                wait = wall0 + (t - t0) / speed - time.monotonic()
                if wait > 0:
                    time.sleep(wait)
            if estimator == "profile" and (k // every) % cfg.recording.profile_every == 0:
                est.replay(d.time[done:k + 1], d.x_in[done:k + 1], d.T_in[done:k + 1])
                done = k + 1   # the estimator's memory at sample k, from the same compiled update
                rr.log_profile(t, s, np.interp(np.linspace(0.0, 1.0, s.size), u, est.profile))
            rr.log_scalars(t, T_in=float(d.T_in[k]), T_out_hat=float(new["T_out"][k]),
                           elongation_hat=float(new["elongation"][k]),
                           T_out_recorded=None if rec_T is None else float(rec_T[k]),
                           elongation_recorded=None if rec_e is None else float(rec_e[k]),
                           T_out_true=None if d.T_out is None else float(d.T_out[k]),
                           elongation_true=None if true_e is None else float(true_e[k]))
            rr.log_phase(t, Phase(int(new["phase"][k])).label)


def replay(run: str | Path, *, config: str | Path | None = None, calibration: str | Path | None = None,
           estimator: str = "profile", speed: float = math.inf, rrd: str | Path | None = None,
           force: bool = False) -> dict[str, Any]:
    """Re-estimate a recording, log it to Rerun and compare (module docstring); a joint instrument's run
    (``slave_joints.csv``) goes to :func:`live.replay.joints.replay_joints` (``estimator`` ignored).

    Returns
    -------
    dict
        ``run``, ``csv``, ``calibration``, ``estimator``, ``K``, ``compliance_m_per_N``, ``samples``,
        ``rate_hz`` (the recording's), ``duration_s``, ``estimate_s`` (batch re-estimation time),
        ``samples_per_s`` (of it), ``log_s`` (Rerun logging, paced), ``rrd``, ``comparison`` (:func:`compare`).

    Raises
    ------
    DataError, ConfigError, CalibrationError
        Missing run or column, unreadable config or calibration, unknown estimator or speed; the Rerun file
        exists and not ``force`` (:func:`live.replay.joints.new_output`, before the re-estimation).
    """
    joint_csv = find_joint_csv(run)
    if joint_csv is not None:
        return replay_joints(joint_csv, _config(joint_csv.parent, config), calibration=calibration, speed=speed,
                             rrd=rrd, force=force)
    if estimator != "profile" and Path(run).is_dir() and not (Path(run) / "slave.csv").is_file():
        raise ConfigError(f"--estimator {estimator}: single-tendon runs only")
    inp = load_run(run)
    out = new_output(Path(rrd) if rrd is not None else (inp.run_dir or inp.csv.parent) / "replay.rrd", rrd is not None,
                     force)
    cfg = _config(inp.run_dir, config)
    model, source = load_model(cfg, inp, calibration)
    noise = tension_noise(cfg, source)
    t_start = time.perf_counter()
    new = reestimate(inp.data, model, cfg, estimator, noise)
    t_est = time.perf_counter() - t_start
    t_start = time.perf_counter()
    _log(inp, cfg, model, new, estimator, speed, out, noise)
    n = int(inp.data.time.size)
    return {"run": str(run), "csv": str(inp.csv), "calibration": source, "estimator": estimator,
            "K": model.K, "compliance_m_per_N": model.compliance, "samples": n, "rate_hz": rate_hz(inp.data.time),
            "duration_s": float(inp.data.time[-1] - inp.data.time[0]), "estimate_s": t_est,
            "samples_per_s": n / t_est if t_est > 0 else math.inf, "tension_noise_N": noise,
            "log_s": time.perf_counter() - t_start,
            "rrd": str(out), "comparison": compare(inp.data, new)}


def table_lines(res: dict[str, Any]) -> list[str]:
    """The comparison as printed: one line per block and reference (per joint for a joint run)."""
    if res.get("kind") == "joints":
        return joint_table_lines(res)
    rate = samples_at(res)
    lines = [f"replay {res['csv']} ({res['samples']} samples at {rate}, {res['duration_s']:.1f} s) with "
             f"{res['estimator']} estimator, K={res['K']:.4g}, L/EA={res['compliance_m_per_N']:.3g} m/N from "
             f"{res['calibration']}",
             f"{'block':<7} {'against':<9} {'force max':>9} {'mean':>7} {'elong max':>9} {'mean':>7} {'samples':>8}"
             f"  (of full scale)"]
    for block, refs in res["comparison"].items():
        for ref, e in refs.items():
            lines.append(f"{block:<7} {ref[3:]:<9} {e['force_error_max_fs']:9.4f} {e['force_error_mean_fs']:7.4f} "
                         f"{e['elongation_error_max_fs']:9.4f} {e['elongation_error_mean_fs']:7.4f} "
                         f"{e['samples']:8d} at {rate}")
    lines.append(f"re-estimated at {res['samples_per_s']:.3g} samples/s; Rerun view in {res['rrd']} "
                 f"({res['log_s']:.2f} s)")
    return lines


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The ``teleop replay`` arguments."""
    p.add_argument("run", metavar="RUN", help="run directory (runs/<id>), its slave.csv, or a recorder session.mcap")
    p.add_argument("--config", metavar="FILE", help="config instead of the run's config.yaml")
    p.add_argument("--calibration", metavar="FILE",
                   help="calibration (.yaml of teleop calibrate, or a run's calibration.json) instead of the run's")
    p.add_argument("--estimator", choices=ESTIMATORS, default="profile",
                   help="profile: the slave's profile-memory estimator (default); paper: the paper's phase formulas")
    p.add_argument("--speed", default="max", help="realtime, max (default) or a factor of real time")
    p.add_argument("--rrd", metavar="OUT", help="Rerun recording to write (default RUN/replay.rrd); an existing "
                                                "file is refused without --force")
    p.add_argument("--json", metavar="OUT", help="write the result and comparison as JSON (an existing file is "
                                                 "refused without --force)")
    p.add_argument("--force", action="store_true", help="overwrite an existing --rrd (or the default) and --json")


def main_replay(args: argparse.Namespace) -> int:
    """``teleop replay``: prints the comparison table; errors propagate to the CLI (exit 2)."""
    speed = parse_speed(args.speed)
    if args.json and Path(args.json).exists() and not args.force:
        raise DataError(f"--json {args.json}: already exists; give a new path, or --force to overwrite it")
    res = replay(args.run, config=args.config, calibration=args.calibration, estimator=args.estimator,
                 speed=speed, rrd=args.rrd, force=args.force)
    print("\n".join(table_lines(res)))
    if args.json:
        Path(args.json).write_text(json.dumps(res, indent=2, allow_nan=True) + "\n", encoding="utf-8")
    return 0
