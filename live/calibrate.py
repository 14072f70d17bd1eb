"""``teleop calibrate``: the power-up calibration of any instrument, saved as its calibration data.

One life cycle for every instrument (:mod:`slave.calibration_file`): ``teleop calibrate`` (or the
slave's power-up routine when ``<calibration.dir>/<instrument.id>.yaml`` is missing, or on
``teleop slave --recalibrate``) runs the instrument's routine: every tendon pulled into its joint limit -
both directions for each antagonistic pair (:class:`slave.pair_calibrate.PairCalibration`), the one tendon
of a single-tendon instrument once (:class:`slave.calibrate.JointLimitCalibration`), fitting K and M_e
(Phee et al. 2009, Sec. IV; K from M_e by Newton, eq. 13) - or every spindle stroked over the open side of
its jaw (:class:`slave.spindle_calibrate.SpindleCalibration`, K from the spindle torque band); then it
writes the file the slave reloads: ``<calibration.dir>/<instrument.id>.yaml``, by default in the per-user
data directory (``$XDG_DATA_HOME/tsm-teleop/calibration``), or ``--out FILE``. The project's ``configs/``
(``configs/calibration/`` holds a read-only example) is never a destination.
"""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from teleop.config.schema import Config
from teleop.errors import ConfigError

__all__ = ["add_calibrate_arguments", "destination", "run_calibrate", "calibration_report"]

#: Simulated time the routine may take before it is declared stuck [s].
MAX_CALIBRATION_TIME = 120.0


def add_calibrate_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", metavar="FILE", required=True, help="YAML config of the instrument")
    p.add_argument("--out", metavar="FILE", help="calibration file (default <calibration.dir>/<instrument.id>.yaml; "
                                                  "calibration.dir null: $XDG_DATA_HOME/tsm-teleop/calibration)")
    p.add_argument("--diagnose", action="store_true",
                   help="single tendon: after the calibration, an excitation motion through the slave's checks, the "
                        "diagnosis of its recording and the model file the slave runs (live/diagnose.py)")
    p.add_argument("--model-out", metavar="FILE", default=None,
                   help="--diagnose: the model file (default beside the calibration: <stem>.model.yaml)")
    p.add_argument("--duration", type=float, default=None, metavar="S",
                   help="--diagnose: the excitation's length [s] (default 60)")
    p.add_argument("--seed", type=int, default=None, help="--diagnose: seeds the excitation's motion (default 0)")
    p.add_argument("--listen", metavar="EP", action="append",
                   help="--diagnose on rig.type zenoh: Zenoh endpoint to listen on (repeatable)")
    p.add_argument("--connect", metavar="EP", action="append",
                   help="--diagnose on rig.type zenoh: Zenoh endpoint to connect to (repeatable)")
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
    from slave.spindle_calibrate import METHOD_SPINDLE
    stroke = cal.method == METHOD_SPINDLE       # a spindle's stroke: no knee, no knee fit
    for name, t, c, true in rows:
        knee, resid = (f"{'-':>14s}", f"{'-':>13s}") if stroke else (f"{c.knee_T_in:14.2f}", f"{c.residual_rms:13.2e}")
        row = f"{name:10s} {t:6s} {c.K:8.4f} {c.M_e:11.4e} {knee} {resid} {c.n_samples:8d}"
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
    from slave.kinds import axis_kind
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


def destination(cfg: Config, out: str | None) -> Path:
    """Where ``teleop calibrate`` writes: ``out``, else the file the slave reloads
    (:func:`slave.calibration_file.calibration_path`).

    Raises
    ------
    ConfigError
        The destination is inside the project's configs (:func:`teleop.config.files.configs_dir`): its files
        are read-only examples.
    """
    from slave.calibration_file import calibration_path, user_calibration_dir
    from teleop.config.files import configs_dir
    path = Path(out) if out else calibration_path(cfg)
    shipped = configs_dir().resolve()
    if path.resolve().is_relative_to(shipped):
        what = f"--out {out}" if out else f"calibration.dir {cfg.calibration.dir}"
        raise ConfigError(f"{what}: {path} is inside the project's configs ({shipped}), whose files are read-only "
                          f"examples; expected a path elsewhere (default calibration.dir: {user_calibration_dir()})")
    return path


def run_calibrate(args: argparse.Namespace) -> int:
    """``teleop calibrate --config FILE``: the power-up routine of the simulated instrument (module docstring),
    saved as calibration data where :func:`destination` says, checked before it runs. The simulation runs as
    fast as it computes (it has no real time to keep); on hardware the same routine is paced by the slave's
    loop (``teleop slave --recalibrate``)."""
    from slave.calibration_file import calibration_path, save_calibration
    from teleop.config.load import load_config

    for flag, dest in (("--model-out", "model_out"), ("--duration", "duration"), ("--seed", "seed"),
                       ("--listen", "listen"), ("--connect", "connect")):
        if getattr(args, dest, None) is not None:
            raise ConfigError(f"{flag}: for --diagnose")
    cfg = load_config(args.config)
    out = destination(cfg, args.out)
    cal, sim = _simulate(cfg, args.config)
    path = save_calibration(cal, out)
    print(calibration_report(cal, sim))
    reload = calibration_path(cfg)
    print(f"wrote {path}" + ("" if path.resolve() == reload.resolve() else
                             f" (the slave of this config reloads {reload}, not this file)"))
    return 0
