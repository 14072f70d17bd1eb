"""``teleop calibrate`` for joint instruments (config ``instrument.joints``): every tendon pulled into
its joint limit both ways, saved as calibration data (the slave side itself is :mod:`teleop.sides`).

One Zenoh session per process, as for one tendon; the key expressions are the same
(``teleop/<instrument>/<side>/<stream>``), the payloads are JointCommand / JointEstimate.
"""
from __future__ import annotations

import argparse

from teleop.config import Config
from teleop.errors import ConfigError

__all__ = ["add_calibrate_arguments", "run_calibrate", "calibration_report"]


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
