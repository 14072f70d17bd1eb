"""The evaluation of a joint instrument in ``teleop demo --config configs/instrument-3dof.yaml``.

The demo's flow is the one of every instrument (:func:`live.demo.main.main_demo`: calibration
file, slave and master processes, summary); what is a joint instrument's own is here
(:class:`JointDemo`): :func:`evaluate_joints` reads ``slave_joints.csv`` and computes, per joint and
per pulled tendon (the scripted operator runs the seed paper's protocol on tendon a then tendon b
of every joint, all joints together), the full-scale errors of the distal joint torque (max and
mean of |estimate - truth| over the range of the true torque in that experiment) and of the angle;
``summary.json`` has them under ``joints.<name>`` with the calibration against the simulator's K
and M_e. The haptic loop of every joint is measured as a single tendon's (:mod:`teleop.timing.loop_metrics`,
:func:`joint_loop_metrics`): chatter of the commanded tendon displacement ``r * cmd`` and of the
rendered force, transparency of the rendered force against the scaled true net distal tension
``torque / r``, per joint and pulled tendon, checked against the single tendon's chatter limits
(:data:`teleop.timing.loop_metrics.CHATTER_LIMITS`) and the transparency limit
(:data:`teleop.timing.loop_metrics.TRANSPARENCY_LIMIT_FS`); docs/stability.md says where each comes from.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from estimator.errors import DataError
from live.demo.run import full_scale_errors
from master.protocols import MARKER_PAPER_A, MARKER_PAPER_B, joint_marker
from teleop.config.schema import Config

__all__ = ["TORQUE_BOUND", "CALIBRATION_BOUND", "read_joint_csv", "evaluate_joints", "joint_checks",
           "joint_loop_metrics", "JointDemo"]

#: Acceptance: max full-scale error of the distal joint torque on the paper's protocol, each joint.
TORQUE_BOUND = 0.05
#: Acceptance: calibrated K and M_e within this relative error of the simulator's, each tendon.
CALIBRATION_BOUND = 0.05
_SIDES = {MARKER_PAPER_A: "a", MARKER_PAPER_B: "b"}


def read_joint_csv(path: str | Path) -> dict[str, np.ndarray]:
    """Columns of ``slave_joints.csv`` by name, each shape (n_rows,).

    Raises
    ------
    DataError
        Missing file, no header or fewer than two rows.
    """
    path = Path(path)
    if not path.is_file():
        raise DataError(f"{path}: no such file")
    with open(path, encoding="utf-8") as fh:
        skip, header = 0, None
        for line in fh:
            skip += 1
            if not line.startswith("#"):
                header = line.strip().split(",")
                break
    if header is None:
        raise DataError(f"{path}: no header line")
    data = np.loadtxt(path, delimiter=",", skiprows=skip, ndmin=2)
    if data.shape[0] < 2:
        raise DataError(f"{path}: {data.shape[0]} data row(s), need at least 2")
    return {name: data[:, k] for k, name in enumerate(header)}


def evaluate_joints(cols: dict[str, np.ndarray], cfg: Config) -> dict:
    """Per joint: per pulled tendon (``a``, ``b``) the torque and angle errors; the joint's worst.

    Returns
    -------
    dict
        ``{name: {"a": {...}, "b": {...}, "torque_error_max_fs": worst of a and b,
        "torque_error_mean_fs": ..., "angle_error_max_rad": ...}}``; per tendon ``samples``,
        ``duration_s``, ``torque_full_scale_Nm``, ``torque_error_max_fs``, ``torque_error_mean_fs``,
        ``angle_range_rad``, ``angle_error_max_rad``, ``angle_error_rms_rad``, ``T_in_max_N``.
    """
    out: dict = {}
    for j, joint in enumerate(cfg.instrument.joints):
        n = joint.name
        tags = np.array([joint_marker(int(m), j) for m in cols["marker"]])
        row: dict = {}
        for tag, side in _SIDES.items():
            sel = tags == tag
            if sel.sum() < 2:
                continue
            t = cols["time"][sel]
            tq, tq_hat = cols[f"{n}.torque"][sel], cols[f"{n}.torque_hat"][sel]
            ang, ang_hat = cols[f"{n}.angle"][sel], cols[f"{n}.angle_hat"][sel]
            fmax, fmean = full_scale_errors(tq_hat, tq)
            row[side] = {"samples": int(sel.sum()), "duration_s": float(t[-1] - t[0]),
                         "torque_full_scale_Nm": float(np.ptp(tq)), "torque_error_max_fs": fmax,
                         "torque_error_mean_fs": fmean, "angle_range_rad": float(np.ptp(ang)),
                         "angle_error_max_rad": float(np.abs(ang_hat - ang).max()),
                         "angle_error_rms_rad": float(np.sqrt(np.mean((ang_hat - ang) ** 2))),
                         "T_in_max_N": float(cols[f"{n}.{side}.T_in"][sel].max())}
        if row:
            per = [row[s] for s in ("a", "b") if s in row]
            row["torque_error_max_fs"] = max(r["torque_error_max_fs"] for r in per)
            row["torque_error_mean_fs"] = max(r["torque_error_mean_fs"] for r in per)
            row["angle_error_max_rad"] = max(r["angle_error_max_rad"] for r in per)
            out[n] = row
    return out


def _calibration_summary(cal_path: Path, cfg: Config) -> dict:
    from slave.calibration_file import load_calibration
    from slave.pair_rig import SimulatedInstrument
    cal = load_calibration(cal_path, cfg)
    inst = SimulatedInstrument.from_config(cfg)
    out: dict[str, Any] = {"file": str(cal_path), "date": cal.date}
    for i, (name, tend) in enumerate(cal.joints):
        out[name] = {t: {"K": c.K, "K_true": float(inst.K[i, k]), "K_error_rel": c.K / inst.K[i, k] - 1.0,
                         "M_e_m_per_N": c.M_e, "M_e_true_m_per_N": float(inst.M_e[i, k]),
                         "M_e_error_rel": c.M_e / inst.M_e[i, k] - 1.0, "residual_rms_m": c.residual_rms,
                         "n_samples": c.n_samples} for k, (t, c) in enumerate(tend.items())}
    return out


def joint_checks(joints: dict, calibration: dict, cfg: Config) -> dict[str, bool]:
    """Acceptance: each joint's torque within :data:`TORQUE_BOUND` of full scale, both directions run;
    each tendon's K and M_e within :data:`CALIBRATION_BOUND` of the simulator's."""
    res: dict[str, bool] = {}
    for joint in cfg.instrument.joints:
        r = joints.get(joint.name, {})
        both = "a" in r and "b" in r
        res[f"{joint.name}: torque error max <= {TORQUE_BOUND} FS, both directions"] = bool(
            both and r["torque_error_max_fs"] <= TORQUE_BOUND)
        c = calibration.get(joint.name)
        res[f"{joint.name}: calibrated K and M_e within {100 * CALIBRATION_BOUND:.0f} % (a and b)"] = bool(
            c and all(abs(c[t][k]) <= CALIBRATION_BOUND for t in "ab" for k in ("K_error_rel", "M_e_error_rel")))
    return res


def joint_loop_metrics(run_dir: Path, cfg: Config) -> dict:
    """Chatter and transparency of each joint's haptic loop, per pulled tendon, from ``master.csv`` and
    ``slave_joints.csv`` (:func:`teleop.timing.loop_metrics.loop_metrics` on the joint's columns: ``x_in`` =
    r * the commanded angle [m], ``force`` = the joint's rendered force [N], ``force_cmd`` its mapped force
    before the passivity controller [N], ``T_out`` = the true torque / r [N], ``T_out_hat`` = the estimated
    torque / r [N]); keys ``"<joint> (pull a)"``, ``"<joint> (pull b)"``.

    Raises
    ------
    DataError
        A recording is missing or lacks a column.
    """
    from teleop.timing.loop_metrics import loop_metrics, read_columns
    m, s = read_columns(run_dir / "master.csv"), read_columns(run_dir / "slave_joints.csv")
    out: dict = {}
    for j, joint in enumerate(cfg.instrument.joints):
        n, r = joint.name, joint.pulley_radius
        try:
            master = {"time": m["time"], "x_in": r * m[f"{n}.cmd"], "force": m[f"{n}.force"], "cmd_seq": m["cmd_seq"],
                      "state": m["state"], "force_cmd": m[f"{n}.force_cmd"]}
            slave = {"t_node": s["t_node"], "T_out": s[f"{n}.torque"] / r, "cmd_seq": s["cmd_seq"],
                     "T_out_hat": s[f"{n}.torque_hat"] / r,
                     "marker": np.array([joint_marker(int(v), j) for v in s["marker"]])}
        except KeyError as e:
            raise DataError(f"{run_dir}: the recordings lack column {e} of joint {n}") from None
        out.update(loop_metrics(master, slave, cfg.master.mapping.force_scale,
                                {MARKER_PAPER_A: f"{n} (pull a)", MARKER_PAPER_B: f"{n} (pull b)"}))
    return out


class JointDemo:
    """What the demo evaluates and prints for a joint instrument (module docstring)."""

    files = ("slave_joints.csv (per joint: command, mode, torque and angle estimates and truth; per tendon "
             "x_in, T_in, estimates, truth)", "master.csv")

    @staticmethod
    def evaluate(summary: dict, run_dir: Path, cfg: Config, problems: list[str]) -> dict[str, bool]:
        """Fill ``summary`` (calibration, joints, torque bound); the checks."""
        from slave.calibration_file import calibration_path
        summary["torque_bound_fs"] = TORQUE_BOUND
        summary["protocol"] = "paper (tendon a, then b; all joints together)"
        try:
            summary["calibration"] = _calibration_summary(calibration_path(cfg), cfg)
        except (OSError, ValueError) as e:
            problems.append(f"calibration: {e}")
            summary["calibration"] = {}
        try:
            summary["joints"] = evaluate_joints(read_joint_csv(run_dir / "slave_joints.csv"), cfg)
        except DataError as e:
            problems.append(str(e))
            summary["joints"] = {}
        try:            # chatter and transparency of every joint's haptic loop, per pulled tendon
            summary["haptic_loop"] = joint_loop_metrics(run_dir, cfg)
        except DataError as e:
            problems.append(str(e))
            summary["haptic_loop"] = {}
        from teleop.timing.loop_metrics import chatter_checks, transparency_checks
        loop = summary["haptic_loop"]
        loop_ok = {f"{j.name}: haptic loop measured (pull a and b)": all(f"{j.name} (pull {t})" in loop for t in "ab")
                   for j in cfg.instrument.joints}
        return {**joint_checks(summary["joints"], summary["calibration"], cfg), **loop_ok, **chatter_checks(loop),
                **transparency_checks(loop)}

    @staticmethod
    def lines(s: dict) -> list[str]:
        """The evaluation's lines of the printed table."""
        L = []
        cal = s.get("calibration", {})
        if cal:
            L.append("calibration (both directions)   K   (vs simulator)      M_e [m/N] (vs simulator)")
            for name, tend in cal.items():
                if not isinstance(tend, dict) or "a" not in tend:
                    continue
                for t in "ab":
                    c = tend[t]
                    L.append(f"  {name:10s} tendon {t}          {c['K']:.4f} ({100 * c['K_error_rel']:+6.2f} %)   "
                             f"{c['M_e_m_per_N']:.4e} ({100 * c['M_e_error_rel']:+6.2f} %)")
            L.append("")
        L.append("paper protocol, per joint and pulled tendon: torque error (full scale)   angle error")
        L.append(f"  {'joint':10s} {'pulled':6s} {'FS [N m]':>9s} {'max':>7s} {'mean':>7s}   {'max [deg]':>9s} "
                 f"{'rms [deg]':>9s}")
        for name, row in s.get("joints", {}).items():
            for t in "ab":
                r = row.get(t)
                if r:
                    L.append(f"  {name:10s} {t:6s} {r['torque_full_scale_Nm']:9.4f} {r['torque_error_max_fs']:7.3f} "
                             f"{r['torque_error_mean_fs']:7.3f}   {math.degrees(r['angle_error_max_rad']):9.2f} "
                             f"{math.degrees(r['angle_error_rms_rad']):9.2f}")
            L.append(f"  {name:10s} {'worst':6s} {'':9s} {row['torque_error_max_fs']:7.3f} "
                     f"{row['torque_error_mean_fs']:7.3f}   (bound {TORQUE_BOUND})")
        if s.get("haptic_loop"):
            from teleop.timing.loop_metrics import loop_metric_lines
            L.append("")
            L += loop_metric_lines(s["haptic_loop"])
            L.append("(per joint: x_in_cmd = r * commanded angle, T_out = true torque / r)")
        return L
