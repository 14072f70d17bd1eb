"""``teleop calibrate``: the joint-limit calibration of any instrument, saved as its calibration data.

One life cycle for every instrument (:mod:`slave.calibration_file`): ``teleop calibrate`` (or the
slave's power-up routine when ``<calibration.dir>/<instrument.id>.yaml`` is missing, or on
``teleop slave --recalibrate``) pulls every tendon into its joint limit - both directions for each
antagonistic pair (:class:`slave.pair_calibrate.PairCalibration`), the one tendon of a single-tendon
instrument once (:class:`slave.calibrate.JointLimitCalibration`) - fits K and M_e (Phee et al. 2009,
Sec. IV; K from M_e by Newton, eq. 13) and writes the file the slave reloads.
"""
from __future__ import annotations

import argparse
from typing import Any

from teleop.config import Config
from teleop.errors import ConfigError

__all__ = ["add_calibrate_arguments", "run_calibrate", "calibration_report"]

#: Simulated time the routine may take before it is declared stuck [s].
MAX_CALIBRATION_TIME = 120.0


def add_calibrate_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", metavar="FILE", required=True, help="YAML config of the instrument")
    p.add_argument("--out", metavar="FILE", help="calibration file (default <calibration.dir>/<instrument.id>.yaml; "
                                                  "calibration.dir null: $XDG_DATA_HOME/tsm-teleop/calibration)")
    p.add_argument("-v", "--verbose", action="store_true", help="log details")


def calibration_report(cal, instrument=None) -> str:
    """A table of the fitted values per axis and tendon, against the simulator's when ``instrument``
    (a simulated rig or instrument) has them."""
    head = (f"{'axis':10s} {'tendon':6s} {'K':>8s} {'M_e [m/N]':>11s} {'knee T_in [N]':>14s} {'residual [m]':>13s}"
            f" {'samples':>8s}" + ("   K vs sim   M_e vs sim" if instrument is not None else ""))
    lines = [f"calibration of {cal.instrument} ({cal.date}): {cal.method}", head]
    if cal.tendon is not None:
        rows = [("tendon", "-", cal.tendon, None if instrument is None else (instrument.K, instrument.M_e))]
    else:
        rows = [(name, t, tend[t], None if instrument is None else (instrument.K[i, k], instrument.M_e[i, k]))
                for i, (name, tend) in enumerate(cal.joints) for k, t in enumerate("ab")]
    for name, t, c, true in rows:
        row = (f"{name:10s} {t:6s} {c.K:8.4f} {c.M_e:11.4e} {c.knee_T_in:14.2f} {c.residual_rms:13.2e} "
               f"{c.n_samples:8d}")
        if true is not None:
            row += f"   {100 * (c.K / true[0] - 1):+7.2f} %  {100 * (c.M_e / true[1] - 1):+7.2f} %"
        lines.append(row)
    return "\n".join(lines)


def _simulate(cfg: Config, source: str) -> tuple[Any, Any]:
    """Run the calibration routine of the configured instrument on its simulator as fast as it computes;
    returns (calibration data, the simulator).

    Raises
    ------
    ConfigError
        The routine did not finish within :data:`MAX_CALIBRATION_TIME` of simulated time.
    """
    from slave.node import axis_kind
    from slave.rigs import RIG_TYPES

    dt = 1.0 / cfg.rig.rate_hz
    steps = int(MAX_CALIBRATION_TIME / dt)
    kind = axis_kind(cfg)                       # the slave's own routine for this kind of instrument
    sim = RIG_TYPES["simulated"](cfg, None)     # whatever rig.type says: the simulator of this instrument
    routine = kind.routine(cfg, sim)
    st = sim.state
    for _ in range(steps):
        if routine.done:
            return kind.calibration_of(cfg, routine), sim
        st = kind.routine_step(routine, sim, st, dt)
    raise ConfigError(f"{source}: calibration did not finish within {MAX_CALIBRATION_TIME:g} s of simulated time")


def run_calibrate(args: argparse.Namespace) -> int:
    """``teleop calibrate --config FILE``: the joint-limit calibration of every tendon of the simulated
    instrument (module docstring), saved as calibration data. The simulation runs as fast as it
    computes (it has no real time to keep); on hardware the same routine is paced by the slave's loop
    (``teleop slave --recalibrate``)."""
    from slave.calibration_file import calibration_path, save_calibration
    from teleop.config import load_config

    cfg = load_config(args.config)
    cal, sim = _simulate(cfg, args.config)
    path = save_calibration(cal, args.out or calibration_path(cfg))
    print(calibration_report(cal, sim))
    print(f"wrote {path}")
    return 0
