"""The ``teleop`` subcommands for joint instruments (config ``instrument.joints``): ``calibrate``, and
the joint version of ``slave`` that :mod:`teleop.cli` hands over to (``master`` is one path for every
instrument).

One Zenoh session per process, as for one tendon; the key expressions are the same
(``teleop/<instrument>/<side>/<stream>``), the payloads are JointCommand / JointEstimate.
"""
from __future__ import annotations

import argparse
import logging

from teleop.config import Config
from teleop.errors import ConfigError

__all__ = ["add_calibrate_arguments", "run_calibrate", "calibration_report", "run_joint_slave", "joint_protocols"]


def add_calibrate_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", metavar="FILE", required=True, help="YAML config of a joint instrument")
    p.add_argument("--out", metavar="FILE", help="calibration file (default <calibration.dir>/<instrument.id>.yaml)")
    p.add_argument("-v", "--verbose", action="store_true", help="log details")


def calibration_report(cal, instrument=None) -> str:
    """A table of the fitted values per joint and tendon, against the simulator's when ``instrument`` has them."""
    lines = [f"calibration of {cal.instrument} ({cal.date}): joint-limit knee each way, K by Newton (eq. 13)",
             f"{'joint':10s} {'tendon':6s} {'K':>8s} {'M_e [m/N]':>11s} {'knee T_in [N]':>14s} {'residual [m]':>13s}"
             f" {'samples':>8s}" + ("   K vs sim   M_e vs sim" if instrument is not None else "")]
    for i, (name, tend) in enumerate(cal.joints):
        for k, t in enumerate("ab"):
            c = tend[t]
            row = (f"{name:10s} {t:6s} {c.K:8.4f} {c.M_e:11.4e} {c.knee_T_in:14.2f} {c.residual_rms:13.2e} "
                   f"{c.n_samples:8d}")
            if instrument is not None:
                row += f"   {100 * (c.K / instrument.K[i, k] - 1):+7.2f} %  {100 * (c.M_e / instrument.M_e[i, k] - 1):+7.2f} %"
            lines.append(row)
    return "\n".join(lines)


def _joint_config(args) -> Config:
    from teleop.config import load_config
    cfg = load_config(args.config)
    if not cfg.instrument.joints:
        raise ConfigError(f"{args.config}: `teleop calibrate` is for joint instruments (instrument.joints); a "
                          f"single-tendon rig calibrates at power-up in `teleop slave`")
    return cfg


def run_calibrate(args: argparse.Namespace) -> int:
    """``teleop calibrate --config FILE``: both-direction joint-limit calibration of every tendon of the
    simulated instrument, saved as calibration data. The simulation runs as fast as it computes (it
    has no real time to keep); on hardware the same routine is paced by the slave's loop."""
    from slave.calibration_file import calibration_path, from_results, save_calibration
    from slave.joint_rig import SimulatedInstrument
    from slave.pair_calibrate import PairCalibration

    cfg = _joint_config(args)
    inst = SimulatedInstrument.from_config(cfg)
    routine = PairCalibration(cfg, inst)
    dt = 1.0 / cfg.rig.rate_hz
    st = inst.state
    for _ in range(int(120.0 / dt)):
        if routine.done:
            break
        st = inst.step(routine.command(st, dt), dt)
    if not routine.done:
        raise ConfigError(f"{args.config}: calibration did not finish within 120 s of simulated time")
    cal = from_results(cfg, routine.results)
    path = save_calibration(cal, args.out or calibration_path(cfg))
    print(calibration_report(cal, inst))
    print(f"wrote {path}")
    return 0


def _load_or_none(cfg: Config):
    from slave.calibration_file import calibration_path, load_calibration
    path = calibration_path(cfg)
    return (load_calibration(path, cfg) if path.is_file() else None), path


def run_joint_slave(args: argparse.Namespace, cfg: Config) -> int:
    """``teleop slave`` for a joint instrument: reload ``<calibration.dir>/<id>.yaml`` (or calibrate at
    power-up and save it there), then serve JointCommands until stopped."""
    from estimator.joint import JointEstimator
    from estimator.sheath import SheathModel
    from slave.joint_node import JointSlaveNode, joint_csv_columns
    from slave.joint_rig import SimulatedInstrument
    from teleop.cli import _injector, _serve, open_session, prepare_run_dir, slave_links
    from teleop.clock import MonotonicClock
    from teleop.messages import JointCommand
    from teleop.recording import CsvRecorder, raise_on_sigterm
    from teleop.rerun_log import RerunLogger

    log = logging.getLogger("teleop.slave")
    calibration, cal_path = _load_or_none(cfg)
    log.info("calibration %s", f"loaded from {cal_path}" if calibration else f"missing: calibrating, then {cal_path}")
    run_dir = prepare_run_dir(args, cfg)
    inst = SimulatedInstrument.from_config(cfg)
    # compile the numba kernels now, not in the first real-time cycles
    SimulatedInstrument(cfg.instrument.joints[:1], cfg.rig).step([[1e-4, 1e-4]], 1e-3)
    m = SheathModel(K=0.5, compliance=1e-4)
    JointEstimator(m, m, 0.004, n_nodes=4).step(1.0, 0.0, 0.5, 0.0, 0.0)
    names = [j.name for j in cfg.instrument.joints]
    meta = {"source": "teleop slave", "instrument": cfg.instrument.id, "joints": " ".join(names),
            "truth": "torque, angle, T_out, elongation are simulator ground truth (evaluation only)"}
    ident = cfg.instrument.id
    clock = MonotonicClock()
    injector = _injector(args, clock)
    with raise_on_sigterm(), open_session(cfg, args, clock) as session, \
            CsvRecorder(run_dir / "slave_joints.csv", joint_csv_columns(names, True), meta, flush_every=500) as rec, \
            RerunLogger("teleop", run_dir.name, args.rerun or cfg.recording.rerun, run_dir / "slave.rrd") as rr:
        links = slave_links(session, ident, injector, JointCommand)
        node = JointSlaveNode(cfg, inst, links, recorder=rec, rerun=rr, calibration=calibration,
                              calibration_file=cal_path, run_dir=run_dir, stop_on_master_stop=args.exit_on_master_stop)
        _serve(node, clock, args, run_dir, "slave", injector)
    log.info("slave done: %s", run_dir)
    return 0


def joint_protocols(cfg: Config, names: str):
    """One axis protocol per joint: ``paper`` (the seed paper's experiment on tendon a, then b) or
    ``short`` (6 N, 2 N each way).

    Raises
    ------
    ConfigError
        Another protocol name.
    """
    from master.joint_operator import paper_protocol
    from slave.pair_calibrate import set_tension
    targets = {"paper": (20.0, 5.0, 20.0), "short": (6.0, 2.0)}.get(names.strip())
    if targets is None:
        raise ConfigError(f"protocol: {names!r} is not a joint-instrument protocol (expected 'paper' or 'short')")
    return [paper_protocol(set_tension(cfg, j), targets) for j in cfg.instrument.joints]
