"""``teleop calibrate --diagnose``: calibrate a single tendon, excite it, diagnose it and write the model it runs.

On the connected instrument (``rig.type simulated``: as fast as it computes; ``rig.type zenoh``: a motor controller
or ``teleop bridge``, paced at ``rig.rate_hz`` on the real clock) an in-process :class:`slave.node.SlaveNode` runs:

1. the power-up joint-limit calibration (:class:`slave.calibrate.JointLimitCalibration`), saved where
   :func:`live.calibrate.destination` says (the file the slave reloads, or ``--out``);
2. the excitation motion of :mod:`live.excitation`, every command judged by the node's checks (range, step, speed,
   tension limit, watchdog); the proximal readings and the bench's distal ones (:mod:`slave.bench`: the diagnosis
   needs a distal reading an instrument does not have) go to a measured-data CSV, flushed as it grows and closed on
   every exit path; Ctrl-C or an error stops the commands and leaves the instrument SAFE and relaxed;
3. the diagnosis of that CSV (:func:`study.analyze.diagnose_file`, ``teleop analyze``'s), printed;
4. the model file of the diagnosis (:func:`study.tendon_model.write_model_out`) and the command that starts the slave
   with it.

Files: the calibration ``C`` (``--out`` or ``<calibration.dir>/<instrument.id>.yaml``), the model file ``--model-out``
(default ``C``'s folder, ``<stem>.model.yaml``) and beside it the excitation's recording ``<stem>.excitation.csv``
(the model's provenance names it). Only a single tendon is diagnosed; another instrument is refused in one line.
"""
from __future__ import annotations

import argparse
import contextlib
import math
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from teleop.config.kinds import KINDS, instrument_kind
from teleop.config.schema import Config
from teleop.errors import ConfigError

__all__ = ["check_diagnose", "diagnose_paths", "run_diagnose", "MIN_DURATION", "MAX_DURATION", "DEFAULT_DURATION",
           "LEAVE_SAFE_S",
           "DIAGNOSE_RIGS"]

#: the excitation's length bounds and default [s]
MIN_DURATION, MAX_DURATION, DEFAULT_DURATION = 10.0, 600.0, 60.0
#: the longest the instrument is run after the excitation to come to rest SAFE [s]
LEAVE_SAFE_S = 10.0
#: the rigs --diagnose moves
DIAGNOSE_RIGS = ("simulated", "zenoh")
#: the recording's columns (measured-data format)
COLUMNS = ("time", "x_in", "T_in", "x_out", "T_out")


def check_diagnose(cfg: Config, source: str, duration: float) -> None:
    """Refuse what ``--diagnose`` cannot do, in one line naming what it supports.

    Raises
    ------
    ConfigError
        Not a single tendon; a rig that is not an instrument to move; ``duration`` out of its bounds.
    """
    kind = instrument_kind(cfg)
    if kind != "tendon":
        what = KINDS[kind]
        raise ConfigError(f"--diagnose: {source} is {'an' if what[0] in 'aeiou' else 'a'} {what} instrument; "
                          "--diagnose supports the single tendon (instrument.joints empty)")
    if cfg.rig.type not in DIAGNOSE_RIGS:
        raise ConfigError(f"--diagnose: rig.type {cfg.rig.type} of {source} is not an instrument to move; "
                          f"--diagnose runs on rig.type {' or '.join(DIAGNOSE_RIGS)}")
    if not (math.isfinite(duration) and MIN_DURATION <= duration <= MAX_DURATION):
        raise ConfigError(f"--duration {duration!r}: expected the excitation's length in [{MIN_DURATION:g}, "
                          f"{MAX_DURATION:g}] s")


def diagnose_paths(cfg: Config, out: str | None, model_out: str | None) -> tuple[Path, Path, Path]:
    """(calibration file, model file, excitation recording) of a diagnosis (module docstring).

    Raises
    ------
    ConfigError
        A destination inside the project's configs, a model file that is a folder or whose folder is missing.
    """
    from live.calibrate import destination
    from teleop.config.files import configs_dir
    cal = destination(cfg, out)
    model = Path(model_out) if model_out else cal.with_name(f"{cal.stem}.model.yaml")
    if model.resolve().is_relative_to(configs_dir().resolve()):
        raise ConfigError(f"--model-out {model}: inside the project's configs, whose files are read-only examples")
    if model.is_dir() or (model_out and not model.resolve().parent.is_dir()):
        raise ConfigError(f"--model-out {model}: the model is one file (OUT.yaml) in an existing folder")
    stem = model.name.removesuffix(".yaml").removesuffix(".model")
    return cal, model, model.with_name(f"{stem}.excitation.csv")


@contextlib.contextmanager
def _connected(cfg: Config, args: argparse.Namespace) -> Iterator[tuple[Any, Any, Callable[[], float]]]:
    """The rig (closed on leaving), its clock and the cycle tick: the simulated rig on a clock that moves as fast as
    it computes, a rig over Zenoh on the real clock through the slave's session."""
    from slave.rigs import make_rig
    from teleop.timing.clock import FakeClock, MonotonicClock, Pacer
    with contextlib.ExitStack() as stack:
        if cfg.rig.type == "simulated":
            clock: Any = FakeClock()
            rig = make_rig(cfg, None)
        else:
            from live.sides import open_session
            clock = MonotonicClock()
            session = stack.enter_context(open_session(cfg, args, clock))
            rig = make_rig(cfg, session)
        stack.callback(rig.close)
        pacer = Pacer(clock, cfg.rig.rate_hz)
        yield rig, clock, lambda: pacer.wait(None)


def _calibrate(node, tick: Callable[[], float], source: str) -> None:
    """The node's power-up routine, until it is done (the node saves the calibration file).

    Raises
    ------
    ConfigError
        Not done within :data:`live.calibrate.MAX_CALIBRATION_TIME`.
    """
    from live.calibrate import MAX_CALIBRATION_TIME
    from teleop.wire.messages import SideState
    t_end = tick() + MAX_CALIBRATION_TIME
    while node.state == SideState.CALIBRATING:
        now = tick()
        if now > t_end:
            raise ConfigError(f"{source}: calibration did not finish within {MAX_CALIBRATION_TIME:g} s")
        node.step(now)


class _Rows:
    """The excitation's rows, positions zeroed at the first one (the rest before the first move)."""

    def __init__(self, recorder, bench) -> None:
        self.recorder, self.bench = recorder, bench
        self.zero: tuple[float, float, float] | None = None
        self.n = 0

    def __call__(self, state) -> None:
        from estimator.errors import CalibrationError
        T_out, x_out = self.bench.read(state)
        if not (math.isfinite(T_out) and math.isfinite(x_out)):
            raise CalibrationError(f"the rig's sample at {state.t:.3f} s has no distal reading (T_out, x_out)")
        if self.zero is None:
            self.zero = (float(state.t), float(state.x_in), x_out)
        t0, x0, y0 = self.zero
        self.recorder.write((float(state.t) - t0, float(state.x_in) - x0, float(state.T_in), x_out - y0, T_out))
        self.n += 1


def _excite(node, rig, cfg: Config, args: argparse.Namespace, csv: Path, tick: Callable[[], float]) -> int:
    """The excitation through ``node`` recorded to ``csv`` (closed on every exit path); the instrument left SAFE
    whatever happens. Returns the rows written.

    Raises
    ------
    ConfigError
        The rig gives no distal reading (no bench).
    """
    from live.excitation import ExcitationMotion, leave_safe, run_excitation
    from slave.bench import distal_bench
    from teleop.recording.measured import CsvRecorder
    bench = distal_bench(rig, args.seed)
    if bench is None:
        raise ConfigError(f"--diagnose: the rig of {args.config} (rig.type {cfg.rig.type}) gives no distal reading; "
                          "the diagnosis needs a calibration bench's distal load cell or position sensor in the rig's "
                          "samples (T_out, x_out; docs/how-to/analyse-recording.md)")
    meta = {"source": "teleop calibrate --diagnose", "instrument": cfg.instrument.id, "rig": cfg.rig.type,
            "distal": bench.name}
    motion = ExcitationMotion(cfg, float(node.rig_state.x_in), args.duration, args.seed)
    try:
        with CsvRecorder(csv, COLUMNS, meta, flush_every=1000, overwrite=True) as rec:
            rows = _Rows(rec, bench)
            run_excitation(node, motion, tick, rows)
    finally:
        leave_safe(node, tick, LEAVE_SAFE_S)
    return rows.n


def run_diagnose(args: argparse.Namespace) -> int:
    """``teleop calibrate --diagnose --config FILE`` (module docstring); 0 when the model file is written."""
    from live.calibrate import calibration_report
    from slave.calibration_file import calibration_path
    from slave.node import SlaveNode
    from slave.node_base import SlaveLinks
    from study.analyze import diagnose_file, format_diagnosis
    from study.tendon_model import write_model_out
    from teleop.config.load import load_config
    from teleop.recording.measured import raise_on_sigterm

    cfg = load_config(args.config)
    args.duration = DEFAULT_DURATION if args.duration is None else args.duration
    args.seed = 0 if args.seed is None else args.seed
    check_diagnose(cfg, args.config, args.duration)
    cal_path, model_path, csv = diagnose_paths(cfg, args.out, args.model_out)
    cal_path.parent.mkdir(parents=True, exist_ok=True)
    model_path.parent.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    with raise_on_sigterm(), _connected(cfg, args) as (rig, clock, tick):
        from live.excitation import Loopback
        links = SlaveLinks(estimate=Loopback(clock), heartbeat=Loopback(clock), command=Loopback(clock),
                           master_heartbeat=Loopback(clock))
        node = SlaveNode(cfg, rig, links, calibration_file=cal_path)
        print(f"calibrating {cfg.instrument.id} on rig.type {cfg.rig.type}: the tendon pulled into its joint limit ...",
              flush=True)
        _calibrate(node, tick, args.config)
        print(calibration_report(node.calibration, rig if cfg.rig.type == "simulated" else None), flush=True)
        print(f"wrote {cal_path}", flush=True)
        print(f"excitation: {args.duration:g} s through the slave's checks, recorded to {csv} ...", flush=True)
        t1 = time.perf_counter()
        n = _excite(node, rig, cfg, args, csv, tick)
    t2 = time.perf_counter()
    print(f"recorded {n} samples in {t2 - t1:.1f} s; diagnosing ...", flush=True)
    result, data = diagnose_file(csv)
    print(format_diagnosis(result))
    path = write_model_out(result, data, csv, model_path, cfg.instrument.id, None)
    effects = "+".join(result.model.effects) or "none (the base model)"
    print(f"wrote {path}: {effects}")
    reload = calibration_path(cfg)
    where = "" if cal_path.resolve() == reload.resolve() else \
        f" (it reloads {reload}: copy {cal_path} there, or set calibration.dir)"
    print(f"start the slave with it: teleop slave --config {args.config} --model {path}{where}")
    print(f"teleop calibrate --diagnose: {time.perf_counter() - t0:.1f} s")
    return 0
