"""``teleop replay RUN`` for a joint instrument: ``slave_joints.csv`` re-estimated joint by joint.

Each joint's two tendons (``<joint>.<a|b>.T_in`` [N], ``.x_in`` [m]) go through a new
:class:`estimator.online.pair.PairEstimator` (the maths the slave's :class:`slave.pair_axis.PairAxis`
runs live, with the run's ``estimator`` settings and the joint's pretension) built from the run's
calibration (``calibration/<instrument>.yaml``) or another one (``--calibration FILE``). The live
estimator's memory started at the calibration routine, before the first recorded row; the replay starts
at rest on the first row, and its angle zero is the recorded ``angle_hat`` of that row (the pose the live
estimate had reached), so that angles from two calibrations stay comparable.

Scores per joint, as :func:`live.demo.joints.evaluate_joints` does for the demo: the distal joint
torque's max and mean error as fractions of the reference's range (full scale) and the angle's max and
RMS error [rad], against the recorded estimate (``torque_hat``, ``angle_hat``) and against the truth
(``torque``, ``angle``) when the recording has it, over the whole run and per experiment (the joint's
4-bit tag in ``marker``: ``paper_a`` pulls tendon a, ``paper_b`` tendon b).
"""
from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from estimator.errors import CalibrationError, DataError
from estimator.online.pair import PairEstimator
from live.demo.run import full_scale_errors
from live.kinds import kind_of
from teleop.config.schema import Config

__all__ = ["JOINT_CSV", "find_joint_csv", "reestimate_joints", "compare_joints", "replay_joints", "joint_table_lines",
           "rate_hz", "new_output"]

JOINT_CSV = "slave_joints.csv"
#: the joint's 4-bit marker tags of the joint protocols (master.protocols.MARKER_PAPER_A / _B)
JOINT_EXPERIMENTS = {1: "paper_a", 2: "paper_b"}


def find_joint_csv(run: str | Path) -> Path | None:
    """``RUN/slave_joints.csv`` or RUN itself when it is such a file; None for anything else."""
    p = Path(run)
    if p.is_dir() and (p / JOINT_CSV).is_file():
        return p / JOINT_CSV
    if p.is_file() and p.name.endswith("joints.csv"):
        return p
    return None


def rate_hz(time_s: np.ndarray) -> float:
    """The recording's sample rate [Hz]: 1 / the median interval of ``time_s`` [s]; NaN with fewer than two rows."""
    d = np.diff(np.asarray(time_s, dtype=float))
    d = d[d > 0]
    return float(1.0 / np.median(d)) if d.size else math.nan


def new_output(path: Path, given: bool, force: bool) -> Path:
    """``path``, which the replay will write; ``given``: named by ``--rrd`` (else the default ``RUN/replay.rrd``).

    Raises
    ------
    DataError
        ``path`` exists and not ``force`` (one line: the file, and the way out).
    """
    if path.exists() and not force:
        what = f"--rrd {path}" if given else f"{path} (the default --rrd, RUN/replay.rrd)"
        raise DataError(f"{what}: already exists; give --rrd with a new path, or --force to overwrite it")
    return path


def _column(cols: dict[str, np.ndarray], csv: Path, name: str) -> np.ndarray:
    if name not in cols:
        raise DataError(f"{csv}: no column {name!r} (a joint recording has <joint>.<a|b>.T_in and .x_in per tendon)")
    v = cols[name]
    if not np.all(np.isfinite(v)):
        raise DataError(f"{csv}: column {name!r} has a non-finite value at row {int(np.argmin(np.isfinite(v)))}")
    return v


def _calibration_file(run_dir: Path, cfg: Config, calibration: str | Path | None) -> Path:
    if calibration is not None:
        return Path(calibration)
    found = run_dir / "calibration" / f"{cfg.instrument.id}.yaml"
    if not found.is_file():
        raise CalibrationError(f"{run_dir}: no calibration/{found.name}: give --calibration FILE (teleop calibrate)")
    return found


def reestimate_joints(cols: dict[str, np.ndarray], csv: Path, cfg: Config,
                      calibration: Path) -> dict[str, dict[str, np.ndarray]]:
    """New estimates per joint: ``{joint: {"torque" [N m], "angle" [rad], "T_out_a", "T_out_b" [N]}}``,
    each shape (n_rows,), from (J1)-(J4) of :mod:`estimator.online.pair` on the recorded proximal signals,
    and ``profile_a``, ``profile_b``: the tendons' tension profiles [N] every :func:`_snapshot_every` rows,
    shape (n_rows // that + 1, n_nodes + 1).

    Raises
    ------
    DataError
        A missing or non-finite proximal column (named with the file).
    CalibrationError
        An unreadable calibration or one of another instrument (from :func:`load_calibration`).
    """
    from slave.calibration_file import load_calibration, sheath_models

    cal = load_calibration(calibration, cfg)
    e, out = cfg.estimator, {}
    for joint, (ma, mb), (_, tend) in zip(cfg.instrument.joints, sheath_models(cal, cfg), cal.joints, strict=False):
        n = joint.name
        Ta, xa = _column(cols, csv, f"{n}.a.T_in"), _column(cols, csv, f"{n}.a.x_in")
        Tb, xb = _column(cols, csv, f"{n}.b.T_in"), _column(cols, csv, f"{n}.b.x_in")
        noise = ((tend["a"].tension_noise, tend["b"].tension_noise) if e.tension_noise is None
                 else (e.tension_noise, e.tension_noise))
        est = PairEstimator(ma, mb, float(joint.pulley_radius), n_nodes=e.n_nodes, pretension=joint.pretension,
                             hold_rate=e.hold_rate, rate_time_constant=e.rate_time_constant, tension_noise=noise)
        m, snap = Ta.size, _snapshot_every(cfg)
        torque, angle, Toa, Tob = np.empty(m), np.empty(m), np.empty(m), np.empty(m)
        prof_a, prof_b = np.empty((m // snap + 1, e.n_nodes + 1)), np.empty((m // snap + 1, e.n_nodes + 1))
        t = cols["time"]
        for k in range(m):
            s = est.step(float(Ta[k]), float(xa[k]), float(Tb[k]), float(xb[k]), float(t[k]))
            torque[k], angle[k], Toa[k], Tob[k] = s.torque, s.angle, s.T_out[0], s.T_out[1]
            if k % snap == 0:
                prof_a[k // snap], prof_b[k // snap] = est.tendons[0].profile, est.tendons[1].profile
        rec = cols.get(f"{n}.angle_hat")
        if rec is not None and math.isfinite(rec[0]):
            angle += rec[0] - angle[0]     # the live estimate's pose at the first recorded row
        out[n] = {"torque": torque, "angle": angle, "T_out_a": Toa, "T_out_b": Tob, "profile_a": prof_a,
                  "profile_b": prof_b}
    return out


def _snapshot_every(cfg: Config) -> int:
    """Rows between two tension profiles in the view: ``recording.log_every * recording.profile_every``."""
    return max(1, cfg.recording.log_every) * max(1, cfg.recording.profile_every)


def _errors(tq: np.ndarray, ang: np.ndarray, tq_ref: np.ndarray, ang_ref: np.ndarray) -> dict[str, float]:
    fmax, fmean = full_scale_errors(tq, tq_ref)
    d = ang - ang_ref
    return {"torque_error_max_fs": fmax, "torque_error_mean_fs": fmean, "torque_full_scale_Nm": float(np.ptp(tq_ref)),
            "angle_error_max_rad": float(np.abs(d).max()), "angle_error_rms_rad": float(np.sqrt(np.mean(d ** 2))),
            "samples": int(tq.size)}


def compare_joints(cols: dict[str, np.ndarray], new: dict[str, dict[str, np.ndarray]],
                   cfg: Config) -> dict[str, dict[str, dict[str, dict[str, float]]]]:
    """``{joint: {block: {"vs_recorded"|"vs_truth": errors}}}``; blocks ``all`` and each experiment the
    joint ran (:data:`JOINT_EXPERIMENTS`). A reference the recording lacks is left out."""
    from master.protocols import joint_marker

    out: dict = {}
    for j, joint in enumerate(cfg.instrument.joints):
        n, est = joint.name, new[joint.name]
        refs = {k: (cols[f"{n}.{a}"], cols[f"{n}.{b}"]) for k, a, b in
                (("vs_recorded", "torque_hat", "angle_hat"), ("vs_truth", "torque", "angle"))
                if f"{n}.{a}" in cols and f"{n}.{b}" in cols}
        blocks = {"all": np.ones(est["torque"].size, dtype=bool)}
        if "marker" in cols:
            tags = np.array([joint_marker(int(m), j) for m in cols["marker"]])
            blocks.update({name: tags == tag for tag, name in JOINT_EXPERIMENTS.items() if (tags == tag).sum() >= 2})
        out[n] = {b: {k: _errors(est["torque"][sel], est["angle"][sel], tq[sel], ang[sel])
                      for k, (tq, ang) in refs.items()}
                  for b, sel in blocks.items()}
    return out


def _log(cols: dict[str, np.ndarray], new: dict[str, dict[str, np.ndarray]], cfg: Config, run_id: str,
         speed: float, rrd: Path) -> None:
    """Per joint the re-estimated and true torque and angle and the tendons in 3D (the live joint view,
    :meth:`teleop.rerun.logger.RerunLogger.log_joint`), the recorded estimate under ``signals/``, every
    ``recording.log_every`` rows, paced with the wall clock at ``speed`` x real time (inf: no pacing)."""
    from teleop.rerun.layout import joint_views
    from teleop.rerun.logger import RerunLogger

    t_all = cols["time"]
    every, wall0, t0 = max(1, cfg.recording.log_every), time.monotonic(), float(t_all[0])
    snap = _snapshot_every(cfg)

    def val(name: str, k: int) -> float | None:
        return float(cols[name][k]) if name in cols else None

    with RerunLogger("teleop-replay", f"{run_id}-replay", "save", rrd, joints=joint_views(cfg),
                     wall_clock=True) as rr:   # the recording's time on both timelines
        for k in range(0, t_all.size, every):
            t = float(t_all[k])
            if math.isfinite(speed):
                wait = wall0 + (t - t0) / speed - time.monotonic()
                if wait > 0:
                    time.sleep(wait)
            for n, est in new.items():
                rr.log_joint(t, n, torque_hat=float(est["torque"][k]), torque_true=val(f"{n}.torque", k),
                             angle_hat=float(est["angle"][k]), angle_true=val(f"{n}.angle", k),
                             profiles=(est["profile_a"][k // snap], est["profile_b"][k // snap])
                             if k % snap == 0 else None)
                rr.log_scalars(t, **{f"{n}/torque_recorded": val(f"{n}.torque_hat", k),
                                     f"{n}/angle_recorded": val(f"{n}.angle_hat", k)})


def replay_joints(csv: Path, cfg: Config, *, calibration: str | Path | None = None, speed: float = math.inf,
                  rrd: str | Path | None = None, force: bool = False) -> dict[str, Any]:
    """Re-estimate a joint recording, log it to Rerun and compare (module docstring).

    Returns
    -------
    dict
        ``kind`` ("joints"), ``run``, ``csv``, ``calibration``, ``estimator`` ("joint"), ``joints`` (names),
        ``samples``, ``rate_hz`` (the recording's, :func:`rate_hz`), ``duration_s``, ``estimate_s``,
        ``samples_per_s``, ``log_s``, ``rrd``, ``comparison`` (:func:`compare_joints`).

    Raises
    ------
    DataError, CalibrationError
        Unreadable CSV or missing column; no or a wrong calibration; the Rerun file exists and not ``force``
        (:func:`new_output`, checked first).
    """
    from live.demo.joints import read_joint_csv

    out = new_output(Path(rrd) if rrd is not None else csv.parent / "replay.rrd", rrd is not None, force)
    kind = kind_of(cfg)
    if kind.replay != "joints":
        raise DataError(f"{csv}: a joint recording, but the config's instrument {cfg.instrument.id} has no joints")
    if kind.replay_refusal:  # its per-cable T_in columns are estimates, not load-cell readings: a replay would be wrong
        raise DataError(f"{csv}: joint(s) {', '.join(j.name for j in cfg.instrument.joints)} are "
                        f"{kind.replay_refusal}")
    cols = read_joint_csv(csv)
    _column(cols, csv, "time")
    cal = _calibration_file(csv.parent, cfg, calibration)
    t_start = time.perf_counter()
    new = reestimate_joints(cols, csv, cfg, cal)
    t_est = time.perf_counter() - t_start
    t_start = time.perf_counter()
    _log(cols, new, cfg, csv.parent.name, speed, out)
    n = int(cols["time"].size)
    return {"kind": "joints", "run": str(csv.parent), "csv": str(csv), "calibration": str(cal), "estimator": "joint",
            "joints": list(new), "samples": n, "rate_hz": rate_hz(cols["time"]),
            "duration_s": float(cols["time"][-1] - cols["time"][0]),
            "estimate_s": t_est, "samples_per_s": n / t_est if t_est > 0 else math.inf,
            "log_s": time.perf_counter() - t_start, "rrd": str(out), "comparison": compare_joints(cols, new, cfg)}


def samples_at(res: dict[str, Any]) -> str:
    """The recording's rate as printed next to each figure, e.g. ``100 Hz`` (``? Hz`` when unknown)."""
    r = res.get("rate_hz", math.nan)
    return f"{r:.4g} Hz" if math.isfinite(r) else "? Hz"


def joint_table_lines(res: dict[str, Any]) -> list[str]:
    """The joint comparison as printed: one line per joint, block and reference."""
    rate = samples_at(res)
    lines = [f"replay {res['csv']} ({res['samples']} samples at {rate}, {res['duration_s']:.1f} s) with the joint "
             f"estimator, calibration {res['calibration']}",
             f"{'joint':<9} {'block':<8} {'against':<9} {'torque max':>10} {'mean':>7} {'angle max':>10} "
             f"{'rms':>8} {'samples':>8}  (torque of full scale, angle in rad)"]
    for joint, blocks in res["comparison"].items():
        for block, refs in blocks.items():
            for ref, e in refs.items():
                lines.append(f"{joint:<9} {block:<8} {ref[3:]:<9} {e['torque_error_max_fs']:10.4f} "
                             f"{e['torque_error_mean_fs']:7.4f} {e['angle_error_max_rad']:10.4f} "
                             f"{e['angle_error_rms_rad']:8.4f} {e['samples']:8d} at {rate}")
    lines.append(f"re-estimated at {res['samples_per_s']:.3g} samples/s; Rerun view in {res['rrd']} "
                 f"({res['log_s']:.2f} s)")
    return lines
