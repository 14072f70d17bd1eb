"""The evaluation of ``teleop demo --rig recording --recording FILE``: the live estimate against the measured one.

A KAIST recording on the pair axis (:func:`evaluate_kaist`) is scored on the distal angle of its test cycles, a
tendon's CSV on the single-tendon axis (:func:`evaluate_tendon`) on the distal tension after its calibration part.

The demo's flow is every instrument's (:func:`live.demo.main.main_demo`); the recording rig (slave/recording/rig.py)
plays an MRD run as the spindle axis's hardware and the slave fits its calibration on one run of the folder at
power-up (slave/recording/spindle.py). :class:`RecordingDemo` reads ``slave_joints.csv`` (a row per cycle: the rig's
time is the recording's) and scores, over the cycles the slave ran from the run's scored start (its first
spindle reversal after 0.5 s; with the centre map once its band reading holds both edges, as ``teleop analyze
--mrd``):

* the live jaw torque against the measured jaw torque: RMSE and max |error| over the full scale (the tool
  file's measured output-torque range, else the run's own);
* the same run's offline estimate, the batch model of the same calibration (:mod:`live.demo.recording_score`), on
  the same cycles, and the difference of the two RMSEs (the same model: it must stay within
  :data:`AGREEMENT_FS`);
* the live jaw angle against the measured one (RMSE [deg]).

The scripted operator runs its protocol on the jaw and the master renders the estimated jaw torque; the rig
ignores the commands (the recorded motion is the one that happened), so the haptic loop's chatter and
transparency are not scored here.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from estimator.errors import DataError
from live.demo.joints import read_joint_csv
from live.kinds import kind_of
from teleop.config.schema import Config

__all__ = ["AGREEMENT_FS", "TORQUE_RMSE_BOUND", "AGREEMENT_DEG", "ANGLE_RMSE_BOUND_DEG", "MODEL_ANGLE_BOUND_DEG",
           "MODEL_AGREEMENT_DEG", "RecordingDemo",
           "evaluate_recording", "recording_checks", "evaluate_kaist", "evaluate_tendon", "with_recording"]

#: Acceptance: |live - offline| jaw torque RMSE on the same cycles [FS].
AGREEMENT_FS = 0.005
#: Acceptance: live jaw torque RMSE against the measured one [FS] (the folder's median is 0.024).
TORQUE_RMSE_BOUND = 0.05


def evaluate_recording(run_dir: Path, cfg: Config) -> dict:
    """The scores of the module docstring from ``run_dir/slave_joints.csv`` and the run's calibration files.

    Raises
    ------
    DataError
        No cycle of the slave reached the run's scored start, or a missing or malformed CSV.
    """
    from estimator.offline.spindle.centre_fit import predict_held
    from estimator.online.spindle import make_batch, predict_torque
    from live.demo.recording_score import scored_from
    from recorded.detect import check_recording, read_recording_run
    from slave.recording.routine import recorded_model_path
    from slave.recording.spindle import CENTRE, full_scale, load_model
    fmt = check_recording(cfg)[1]
    if fmt == "kaist":
        return evaluate_kaist(run_dir, cfg)
    if fmt == "csv":
        return evaluate_tendon(run_dir, cfg)
    run = read_recording_run(cfg)
    model = load_model(recorded_model_path(cfg))
    name = cfg.instrument.joints[0].name
    cols = read_joint_csv(run_dir / "slave_joints.csv")
    idx = np.rint(cols["time"] / run.dt).astype(int)
    k0 = scored_from(model, run)
    keep = (idx >= k0) & (idx < len(run))
    if not keep.any():
        raise DataError(f"{run_dir / 'slave_joints.csv'}: no cycle reached the scored start of {run.source} "
                        f"({run.time[min(k0, len(run) - 1)]:.1f} s of the recording)")
    if model.chosen == CENTRE and model.centre_map is not None:
        offline = predict_held(model.centre_map, run.tau_p, run.theta_p, run.dt)
    else:
        offline = predict_torque(model.pair, make_batch([(run.tau_p, run.theta_p)], model.band_centre,
                                                        model.theta_ref, run.dt))
    fs = full_scale(cfg, run.tau_d)
    i = idx[keep]
    truth, live = run.tau_d[i], cols[f"{name}.torque_hat"][keep]
    e, eo = live - truth, offline[i] - truth
    ea = cols[f"{name}.angle_hat"][keep] - run.theta_d[i]
    rmse, rmse_off = float(np.sqrt(np.mean(e ** 2)) / fs), float(np.sqrt(np.mean(eo ** 2)) / fs)
    return {"recording": run.source, "calibration_run": model.run, "model": model.chosen, "tool": model.tool,
            "full_scale_Nm": fs, "cycles_scored": int(keep.sum()), "scored_from_s": float(run.time[k0]),
            "scored_to_s": float(run.time[i.max()]), "torque_rmse_fs": rmse,
            "torque_max_fs": float(np.max(np.abs(e)) / fs), "offline_torque_rmse_fs": rmse_off,
            "live_minus_offline_fs": rmse - rmse_off, "angle_rmse_deg": float(math.degrees(np.sqrt(np.mean(ea ** 2)))),
            "recording_finished": bool(idx.max() >= len(run) - 1)}


def with_recording(cfg: Config, args: Any) -> Config:
    """``cfg`` with ``--rig`` / ``--recording PATH`` applied (``--recording`` alone means ``--rig recording``;
    without ``--config`` the instrument is the shipped one of the format the file's content shows:
    configs/recording-mrd.yaml's jaw, recording-kaist.yaml's joint or sim.yaml's tendon), the recording checked
    against the instrument before any process starts (:func:`recorded.detect.check_recording`: one line naming
    the file and the problem)."""
    import dataclasses

    from recorded.detect import read_recording
    from teleop.config.files import shipped_config
    from teleop.config.load import load_config
    rig, path = getattr(args, "rig", None), getattr(args, "recording", None)
    if path is not None and rig in (None, "recording"):
        if getattr(args, "config", None) is None:
            from recorded.detect import recording_format
            fmt = recording_format(Path(path).expanduser())
            name = {"kaist": "recording-kaist.yaml", "csv": "sim.yaml"}.get(fmt, "recording-mrd.yaml")
            cfg = load_config(shipped_config(name))
        rec = dataclasses.replace(cfg.rig.recording, path=str(Path(path).expanduser().resolve()), format="auto")
        cfg = dataclasses.replace(cfg, rig=dataclasses.replace(cfg.rig, type="recording", recording=rec))
    elif rig is not None:
        cfg = dataclasses.replace(cfg, rig=dataclasses.replace(cfg.rig, type=rig))
    if cfg.rig.type == "recording":
        if cfg.rig.recording.path:      # the sides run from the run's config: an absolute path reads the same
            rec = dataclasses.replace(cfg.rig.recording, path=str(Path(cfg.rig.recording.path).expanduser().resolve()))
            cfg = dataclasses.replace(cfg, rig=dataclasses.replace(cfg.rig, recording=rec))
        read_recording(cfg)
    return cfg


def evaluate_kaist(run_dir: Path, cfg: Config) -> dict:
    """The pair axis on a KAIST recording: the live distal angle on the test cycles (cycle 2 on, as ``teleop
    analyze --kaist``) against the measured one, beside the same model run offline over the recording (the base
    estimator's, :func:`estimator.online.pair_batch.predict_pair_angle`; with a model file, its model,
    :func:`estimator.offline.pair.models.predict_model`) and the offline seed pair model on the same
    samples. Raises DataError when no row of the slave falls on a test sample."""
    import json

    from estimator.offline.pair.fit import PairParams, fit_pair
    from estimator.offline.pair.models import predict_model
    from estimator.online.pair_batch import predict_pair_angle
    from recorded.detect import check_recording
    from recorded.kaist import read_kaist_recording, split
    from slave.estimator_model import configured_model
    from slave.recording.pair import N_NODES
    from slave.recording.routine import recorded_model_path
    rec = read_kaist_recording(check_recording(cfg)[0])
    model = json.loads(recorded_model_path(cfg).read_text(encoding="utf-8"))
    name = cfg.instrument.joints[0].name
    cols = read_joint_csv(run_dir / "slave_joints.csv")
    c1, c2, how = split(rec)
    t = cols["time"]
    j, near = _rows_at(t, rec.time)
    keep = near & (np.arange(len(rec)) >= c2.start) & (np.arange(len(rec)) < c2.stop)
    if not keep.any():
        raise DataError(f"{run_dir / 'slave_joints.csv'}: no cycle of the slave on the test cycles of {rec.source}")
    live = cols[f"{name}.angle_hat"][j[keep]]
    truth = rec.angle[keep]
    mf = configured_model(cfg)          # the model file the slave ran (estimator.model), or None: the base estimator
    if mf is None:
        batch = predict_pair_angle(PairParams(**model["params"]), rec.command, rec.T_a, rec.T_b, N_NODES)[keep]
    else:
        batch = predict_model(mf.structure, tuple(e.id for e in mf.extensions), mf.values(), rec)[0][keep]
    seed = fit_pair(rec.command, rec.T_a, rec.T_b, rec.angle, c1.stop, N_NODES).prediction[keep]

    def deg(e: np.ndarray) -> float:
        return float(math.degrees(np.sqrt(np.mean(e ** 2))))
    return {"recording": rec.source, "format": "kaist", "calibration_run": model["run"], "split": how,
            "samples_scored": int(keep.sum()), "angle_rmse_deg": deg(live - truth),
            "angle_max_deg": float(math.degrees(np.max(np.abs(live - truth)))),
            "offline_same_model_rmse_deg": deg(batch - truth),
            "live_minus_offline_deg": deg(live - truth) - deg(batch - truth),
            "offline_seed_rmse_deg": deg(seed - truth),
            "model": None if mf is None else {"id": mf.model_id, "sha256": mf.sha256, "path": mf.path,
                                              "held_out_deg": mf.gain["extended"], "base_deg": mf.gain["base"]}}


def _bounds(r: dict) -> tuple[float, float]:
    """A KAIST evaluation's bounds [deg]: (live vs measured, |live - offline|), the model file's when it ran one."""
    return (MODEL_ANGLE_BOUND_DEG, MODEL_AGREEMENT_DEG) if r.get("model") else (ANGLE_RMSE_BOUND_DEG, AGREEMENT_DEG)


def _model_lines(m: dict | None, ran: dict | None) -> list[str]:
    """The summary's line on the estimator's model: the model file's id, hash and held-out figures and, from the
    slave's stats, its cycles and fallbacks; none without a model file."""
    if not m:
        return []
    runs = "" if not ran else f"; {ran['cycles']} cycles, {ran['fallbacks']} fell back to the base estimator"
    return [f"  model {m['id']} (sha256 {m['sha256'][:12]}..., {Path(m['path']).name}): held-out "
            f"{m['held_out_deg']:.2f} deg where it was fitted (base {m['base_deg']:.2f}){runs}"]


def _rows_at(t_rows: np.ndarray, t_rec: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(row index at each recorded sample time, whether a row lies within 0.6 ms of it)."""
    j = np.clip(np.searchsorted(t_rows, t_rec - 6e-4), 0, t_rows.size - 1)
    return j, np.abs(t_rows[j] - t_rec) <= 6e-4


def evaluate_tendon(run_dir: Path, cfg: Config) -> dict:
    """A tendon's CSV on the single-tendon axis: the live distal tension on the held-out part (after the calibration
    fit's 60 %) against the measured one, over the measured range (FS), beside the same estimator run offline
    (:func:`estimator.online.distal.estimate_batch`) on the same samples. Raises DataError when the recording has no
    T_out or no slave row falls on a held-out sample."""
    import json

    from estimator.online.distal import estimate_batch
    from estimator.sheath import SheathModel
    from recorded.detect import check_recording, read_tendon_csv
    from slave.calibration_file import calibration_path
    d = read_tendon_csv(check_recording(cfg)[0])
    if d.T_out is None:
        raise DataError(f"{d.source}: no T_out column: the summary scores the distal tension")
    model = json.loads(calibration_path(cfg).with_suffix(".recording.json").read_text(encoding="utf-8"))
    rows = read_joint_csv(run_dir / "slave.csv")
    j, near = _rows_at(rows["time"], d.time)
    keep = near & (d.time >= d.time[0] + model["split_time_s"])
    if not keep.any():
        raise DataError(f"{run_dir / 'slave.csv'}: no cycle of the slave on the held-out part of {d.source}")
    e = cfg.estimator
    off = estimate_batch(d.T_in, d.x_in, SheathModel(K=model["K"], compliance=model["compliance"]), time=d.time,
                         n_nodes=e.n_nodes, pretension=cfg.sheath.pretension, hold_rate=e.hold_rate,
                         rate_time_constant=e.rate_time_constant).T_out[keep]
    truth, live = d.T_out[keep], rows["T_out_hat"][j[keep]]
    fs = float(np.ptp(truth)) or 1.0
    rmse, rmse_off = (float(np.sqrt(np.mean((v - truth) ** 2)) / fs) for v in (live, off))
    return {"recording": d.source, "format": "csv", "calibration_run": model["run"], "full_scale_N": fs,
            "samples_scored": int(keep.sum()), "T_out_rmse_fs": rmse, "offline_T_out_rmse_fs": rmse_off,
            "live_minus_offline_fs": rmse - rmse_off}


#: Acceptance (KAIST): |live - offline| distal angle RMSE of the same model on the same samples [deg].
AGREEMENT_DEG = 0.05
#: Acceptance (KAIST): live distal angle RMSE [deg] (the seed pair model's is 3.0-3.6 on the shipped files).
ANGLE_RMSE_BOUND_DEG = 5.0
#: Acceptance (KAIST with a model file): live distal angle RMSE [deg] (the study's extended models: 0.83-1.17).
MODEL_ANGLE_BOUND_DEG = 1.2
#: Acceptance (KAIST with a model file): |live - offline| of the model file's model on the same samples [deg].
MODEL_AGREEMENT_DEG = 0.1


def recording_checks(r: dict) -> dict[str, bool]:
    """The acceptance checks of an evaluation ``r`` (:func:`evaluate_recording`), each named by a sentence with its
    figure and bound: the live estimate against the measured one, and live against offline (the same model)."""
    if r.get("format") == "csv":
        d = r["live_minus_offline_fs"]
        return {f"distal tension live vs offline (same estimator, same samples): |live - offline| {abs(d):.4f} FS, "
                f"bound {AGREEMENT_FS} FS": abs(d) <= AGREEMENT_FS}
    if r.get("format") == "kaist":
        a, d = r["angle_rmse_deg"], r["live_minus_offline_deg"]
        bound, agree = _bounds(r)
        return {f"distal angle live vs measured: RMSE {a:.2f} deg, bound {bound} deg": a <= bound,
                f"distal angle live vs offline (same model, same samples): |live - offline| {abs(d):.3f} deg, "
                f"bound {agree} deg": abs(d) <= agree}
    t, d = r["torque_rmse_fs"], r["live_minus_offline_fs"]
    return {f"jaw torque live vs measured: RMSE {t:.4f} FS, bound {TORQUE_RMSE_BOUND} FS": t <= TORQUE_RMSE_BOUND,
            f"jaw torque live vs offline (same model, same cycles): |live - offline| {abs(d):.4f} FS, "
            f"bound {AGREEMENT_FS} FS": abs(d) <= AGREEMENT_FS}


class RecordingDemo:
    """The recording rig's part of ``teleop demo`` (module docstring)."""

    files = ("slave_joints.csv",)

    @staticmethod
    def evaluate(summary: dict, run_dir: Path, cfg: Config, problems: list[str]) -> dict[str, bool]:
        """Fill ``summary["recording"]``; the checks of :func:`recording_checks`."""
        summary["kind"] = "recording"
        summary["slave_file"] = kind_of(cfg).slave_file
        try:
            r = summary["recording"] = evaluate_recording(run_dir, cfg)
        except (DataError, OSError, KeyError) as e:
            problems.append(f"evaluation: {e}")
            return {"recording evaluated (see the problems)": False}
        return recording_checks(r)

    @staticmethod
    def lines(s: dict) -> list[str]:
        """The summary table's rows."""
        r: Any = s.get("recording")
        if not r:
            return ["recording: not evaluated (see problems)"]
        if r.get("format") == "csv":
            return [f"recording {r['recording']} (single tendon, calibrated on {Path(r['calibration_run']).name})",
                    f"  scored {r['samples_scored']} recorded samples after the calibration fit's 60 %",
                    f"  distal tension live vs measured: RMSE {r['T_out_rmse_fs']:.4f} FS "
                    f"(FS {r['full_scale_N']:.2f} N)",
                    f"  offline (same estimator and calibration, same samples): "
                    f"RMSE {r['offline_T_out_rmse_fs']:.4f} FS; "
                    f"live - offline {r['live_minus_offline_fs']:+.4f} FS (bound {AGREEMENT_FS})"]
        if r.get("format") == "kaist":
            return [f"recording {r['recording']} (pair axis, calibrated on {r['split'].split(';')[0]})",
                    *_model_lines(r.get("model"), s.get("slave", {}).get("model")),
                    f"  scored {r['samples_scored']} recorded samples of the test cycles",
                    f"  distal angle live vs measured: RMSE {r['angle_rmse_deg']:.2f} deg (bound {_bounds(r)[0]}), "
                    f"max {r['angle_max_deg']:.2f} deg",
                    f"  offline (same model and calibration, same samples): "
                    f"RMSE {r['offline_same_model_rmse_deg']:.2f} "
                    f"deg; live - offline {r['live_minus_offline_deg']:+.3f} deg (bound {_bounds(r)[1]})",
                    f"  offline seed pair model (teleop analyze --kaist's seed): "
                    f"RMSE {r['offline_seed_rmse_deg']:.2f} deg"]
        m = s.get("model")
        return [f"recording {r['recording']} (calibrated on {Path(r['calibration_run']).name}, tool "
                f"{r['tool'] or 'none'}): jaw torque from the {r['model']}, "
                f"full scale {r['full_scale_Nm'] * 1e3:.1f} mN m",
                *([f"  model {m['id']} (sha256 {m['sha256'][:12]}..., {Path(m['path']).name}): the model file's, not "
                   "fitted at power-up"] if m else []),
                f"  scored {r['cycles_scored']} cycles, {r['scored_from_s']:.2f}-{r['scored_to_s']:.2f} s "
                f"of the recording",
                f"  jaw torque live vs measured: RMSE {r['torque_rmse_fs']:.4f} FS (bound {TORQUE_RMSE_BOUND}), max "
                f"{r['torque_max_fs']:.3f} FS",
                f"  offline (same model and calibration, same cycles): RMSE {r['offline_torque_rmse_fs']:.4f} FS; "
                f"live - offline {r['live_minus_offline_fs']:+.4f} FS (bound {AGREEMENT_FS})",
                f"  jaw angle live vs measured: RMSE {r['angle_rmse_deg']:.2f} deg"]
