"""The two side processes of ``teleop``: ``slave`` and ``master`` of any instrument, and what they share.

One Zenoh session per process (:func:`open_session`), the streams of :mod:`teleop.wire.keys` wired to a
node (:func:`slave_links`, :func:`master_links`; ``--inject`` wraps the publishers in a
:class:`live.faults.FaultInjector`), a run directory for recordings and stats
(:func:`prepare_run_dir`), and the node run until it is done, stopped or out of time (``_serve``).
:mod:`live.cli` parses the arguments and calls :func:`run_slave` / :func:`run_master`; the single
tendon and the joint instrument share everything here, the nodes included (they iterate over axes).
"""
from __future__ import annotations

import argparse
import contextlib
import faulthandler
import logging
import sys
import time
from pathlib import Path

from live.kinds import kind_of
from live.side_files import SideFiles
from teleop.config.bounds import announce_waivers
from teleop.config.kinds import instrument_kind
from teleop.config.schema import Config
from teleop.rerun.layout import joint_views
from teleop.rerun.serve import serve_spec

__all__ = ["run_slave", "run_master", "load_or_recalibrate", "default_run_dir",
           "prepare_run_dir", "endpoints", "open_session", "slave_links", "master_links"]


#: [s] after the loop ends, a side still shutting down this long dumps its threads' stacks to its log
SHUTDOWN_DUMP_S = 15.0


def _arm_shutdown_dump() -> None:
    """Arm the stack dump of a slow shutdown on the process's own stderr (fd 2; not a captured stream)."""
    stream = sys.__stderr__
    if stream is None:
        return
    try:
        faulthandler.dump_traceback_later(SHUTDOWN_DUMP_S, exit=False, file=stream)
    except (OSError, ValueError):      # stderr without a file descriptor: no dump, nothing else changes
        pass


def default_run_dir(base: str | Path) -> Path:
    """A fresh ``<base>/<YYYYmmdd-HHMMSS>[-n]`` directory path (not created)."""
    stamp = time.strftime("%Y%m%d-%H%M%S")
    path = Path(base) / stamp
    n = 1
    while path.exists():
        path = Path(base) / f"{stamp}-{n}"
        n += 1
    return path


def endpoints(args: argparse.Namespace) -> tuple[tuple[str, ...] | None, tuple[str, ...] | None]:
    """(listen, connect) overrides from the flags: both None when neither flag is given."""
    if args.listen is None and args.connect is None:
        return None, None
    return tuple(args.listen or ()), tuple(args.connect or ())


def open_session(cfg, args: argparse.Namespace, clock):
    """The Zenoh session of one side; a failure to open names the endpoints tried.

    Raises
    ------
    ConfigError
        An endpoint zenoh rejects in the configuration.
    TransportError
        The session cannot be opened (port in use, address not resolvable).
    """
    from live.discovery import side_session  # bare start: listen, or connect when taken
    return side_session(cfg, args, clock)


def side_run_dir(args: argparse.Namespace, cfg, role: str | None = None) -> Path:
    """A side's run directory: the session opened now, the run id agreed with the peers, ``role`` claimed
    (a second slave or master of the instrument is refused; live/discovery.py)."""
    from live.discovery import side_run_dir as agreed
    return agreed(args, cfg, role)


def _injector(args: argparse.Namespace, clock):
    """The fault injector of ``--inject`` (SIGUSR1 trigger installed), or None."""
    if not getattr(args, "inject", None):
        return None
    from live.faults import FaultInjector
    inj = FaultInjector(args.inject, clock)
    inj.install_signal()
    logging.getLogger("live.faults").warning("fault injection on: %s", args.inject)
    return inj


def _publisher(session, key: str, stream: str, injector):
    pub = session.publisher(key)
    return pub if injector is None else injector.wrap(pub, stream)


def _write_fault_stats(injector, path: Path) -> None:
    if injector is not None:
        import json
        path.write_text(json.dumps(injector.stats(), indent=2) + "\n", encoding="utf-8")


def prepare_run_dir(args: argparse.Namespace, cfg) -> Path:
    """``--run-dir``, else a fresh ``<recording.dir>/<timestamp>``; created."""
    run_dir = Path(args.run_dir) if args.run_dir else default_run_dir(cfg.recording.dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    return run_dir


def _side_streams(session, ident: str, injector, me: str, peer: str, out: tuple[str, str], incoming: tuple[str, type]):
    """Declare the streams of side ``me`` on ``session``: the peer's liveliness watched, the outgoing
    publisher ``out = (key, stream name)`` and the heartbeat (``--inject`` faults on both), the
    incoming subscriber ``incoming = (key, message type)`` and the peer's heartbeat; then the own
    liveliness token. Returns (outgoing, heartbeat, incoming, peer heartbeat, peer alive)."""
    from teleop.session.link_security import SourceLock  # slave: one master session only (transport.lock_master)
    from teleop.wire.keys import heartbeat_key, liveliness_key
    from teleop.wire.messages import Heartbeat
    lock = SourceLock() if me == "slave" and session.lock_master else None
    only = {} if lock is None else {"source_lock": lock}
    watcher = session.liveliness_watcher(liveliness_key(ident, peer), None if lock is None else lock.on_liveliness)
    streams = (_publisher(session, out[0], out[1], injector),
               _publisher(session, heartbeat_key(ident, me), "heartbeat", injector),
               session.subscriber(incoming[0], incoming[1], **only),
               session.subscriber(heartbeat_key(ident, peer), Heartbeat, **only),
               lambda: watcher.alive)
    session.liveliness_token(liveliness_key(ident, me))
    return streams


def slave_links(session, ident: str, injector):
    """The slave's links on ``session`` (:func:`_side_streams`): estimates out, commands in (any
    other message on the command key is dropped by the subscriber)."""
    from slave.node_base import SlaveLinks
    from teleop.wire.keys import command_key, estimate_key
    from teleop.wire.messages import Command

    # SlaveLinks' fields in order: estimate, heartbeat, command, master_heartbeat, master_alive
    links = SlaveLinks(*_side_streams(session, ident, injector, "slave", "master", (estimate_key(ident), "estimate"),
                                      (command_key(ident), Command)))
    watch = getattr(session, "refusal_watch", None)     # connections refused for their credentials (live/discovery.py)
    if watch is not None:
        links.refused_links = lambda: int(watch.refused)
    return links


def master_links(session, ident: str, injector):
    """The master's links on ``session`` (:func:`_side_streams`): commands out, estimates in (any
    other message on the estimate key is dropped by the subscriber)."""
    from master.node_base import MasterLinks
    from teleop.wire.keys import command_key, estimate_key
    from teleop.wire.messages import Estimate

    # MasterLinks' fields in order: command, heartbeat, estimate, slave_heartbeat, slave_alive
    return MasterLinks(*_side_streams(session, ident, injector, "master", "slave", (command_key(ident), "command"),
                                      (estimate_key(ident), Estimate)))


def _record_waivers(path: Path, waived: list[dict]) -> None:
    """Add the config's safety waivers (teleop/config/bounds.py) to the stats file at ``path``."""
    import json
    try:
        stats = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        stats = {}
    stats["safety_waivers"] = waived
    path.write_text(json.dumps(stats, indent=2) + "\n", encoding="utf-8")


def _live(node) -> dict:
    """The running loop's figures for ``<side>_live.json`` (live/side_files.py): cycles, overruns, messages
    sent, a master's round-trip histogram."""
    cs = getattr(node, "cycle_stats", None)
    out = {"cycles": sum(dict(getattr(cs, "cycles_by_state", {})).values()),
           "overruns": sum(dict(getattr(cs, "overruns_by_state", {})).values()), "sent": int(node.seq)}
    rtt = getattr(node, "rtt", None)
    if rtt is not None:
        out["rtt"] = rtt.snapshot()
    return out


def _serve(node, clock, args: argparse.Namespace, run_dir: Path, side: str, injector, *, close_first=None,
           waived: list[dict] | None = None, files=None) -> None:
    """Run ``node`` until done (or ``--max-duration``); however it ends, ``close_first()`` (e.g. the
    device), then ``<side>_stats.json`` (with the safety waivers ``waived`` and the disk use of ``files``, a
    :class:`live.side_files.SideFiles`) and ``<side>_faults.json`` in ``run_dir``. Every message the side
    publishes is journaled in ``run_dir`` first (teleop/recording/journal.py: the recorder recovers a SIGKILLed side's
    tail)."""
    from teleop.recording.journal import close_journal, open_journal
    open_journal(run_dir, side)
    if files is not None:
        files.live_source = lambda: _live(node)
    try:
        node.run(clock, max_duration=args.max_duration)
    finally:
        # a shutdown that takes longer than SHUTDOWN_DUMP_S leaves every thread's stack in the side's log
        _arm_shutdown_dump()
        close_journal()
        if close_first is not None:
            close_first()
        node.write_stats(run_dir / f"{side}_stats.json")
        _record_waivers(run_dir / f"{side}_stats.json", waived or [])
        if files is not None:
            from live.side_files import add_to_stats
            files.close()
            add_to_stats(run_dir / f"{side}_stats.json", "disk", files.summary())
        _write_fault_stats(injector, run_dir / f"{side}_faults.json")


def _log_master_done(node) -> None:
    lat = node.latency_stats()
    def ms(v) -> str:
        return "n/a" if v is None else f"{v:.3f}"
    logging.getLogger("teleop.master").info("master done: %s commands, rtt p50 %s ms, p99 %s ms",
                                            node.commands_sent, ms(lat["p50_ms"]), ms(lat["p99_ms"]))


def run_slave(args: argparse.Namespace) -> int:
    """``teleop slave`` for any instrument: reload ``<calibration.dir>/<id>.yaml`` (or calibrate at
    power-up and save it there: missing, or ``--recalibrate``), then serve commands until stopped. One
    path and one :class:`slave.node.SlaveNode` for every instrument (a single tendon is one axis)."""
    from slave.estimator_model import configured_model, with_model
    from slave.node import SlaveNode, recording, warm_up
    from slave.rigs import make_rig
    from teleop.config.load import load_config
    from teleop.recording.csv_proc import (
        ProcessCsvRecorder as CsvRecorder,  # the loop only queues rows; a child process writes
    )
    from teleop.recording.measured import raise_on_sigterm
    from teleop.rerun.process import RerunProcessLogger as RerunLogger  # the loop only queues; a child process logs
    from teleop.timing.clock import MonotonicClock

    cfg = with_model(load_config(args.config), getattr(args, "model", None))   # --model over estimator.model
    configured_model(cfg)       # the model file checked before anything starts (one line, exit 2)
    waived = announce_waivers(cfg, logging.getLogger("teleop.slave"))
    calibration, cal_path = load_or_recalibrate(cfg, getattr(args, "recalibrate", False))
    run_dir = side_run_dir(args, cfg, "slave")
    warm_up(cfg)  # compile the numba kernels now, not in the first real-time cycles
    ident = cfg.instrument.id
    clock = MonotonicClock()
    injector = _injector(args, clock)
    with raise_on_sigterm(), open_session(cfg, args, clock) as session:
        rig = make_rig(cfg, session)     # rig.type: simulated in process, zenoh (a drive or `teleop bridge`), ...
        try:
            name, columns, meta = recording(cfg, rig)
            files = SideFiles(run_dir, cfg, "slave", (name, "slave.rrd"))   # csv_every, max_bytes, min_free_bytes
            with CsvRecorder(run_dir / name, columns, meta, flush_every=500) as rec, \
                    RerunLogger("teleop", run_dir.name, args.rerun or cfg.recording.rerun, run_dir / "slave.rrd",
                                route=cfg.sheath.runs if kind_of(cfg).sheath_view else None,   # 3D sheath view
                                joints=joint_views(cfg), serve=serve_spec(cfg, "slave")) as rr:
                links = slave_links(session, ident, injector)
                if cfg.ros2.enabled:     # the CRTK topics on ROS 2 beside the loop, servo_jp in (teleop/ros2/side.py)
                    from teleop.ros2.side import attach_slave
                    attach_slave(session, cfg, links)
                node = SlaveNode(cfg, rig, links, recorder=files.csv(rec), rerun=files.rerun(rr), run_dir=run_dir,
                            stop_on_master_stop=args.exit_on_master_stop, calibration=calibration,
                            calibration_file=cal_path)
                _serve(node, clock, args, run_dir, "slave", injector, waived=waived, files=files)
        finally:
            rig.close()
    faulthandler.cancel_dump_traceback_later()
    logging.getLogger("teleop.slave").info("slave done: %s", run_dir)
    return 0


def run_master(args: argparse.Namespace) -> int:
    """``teleop master``: run the operator side of any instrument until the device's protocol is finished."""
    from master.devices import make_device
    from master.kinds import master_kind
    from master.node import MasterNode, csv_columns, csv_units
    from teleop.config.load import load_config
    from teleop.recording.csv_proc import (
        ProcessCsvRecorder as CsvRecorder,  # the loop only queues rows; a child process writes
    )
    from teleop.recording.measured import raise_on_sigterm
    from teleop.rerun.process import RerunProcessLogger as RerunLogger  # the loop only queues; a child process logs
    from teleop.timing.clock import MonotonicClock

    cfg = load_config(args.config)
    waived = announce_waivers(cfg, logging.getLogger("teleop.master"))
    if cfg.rig.type == "recording" and cfg.master.device.type == "simulated":
        from master.recording_operator import recorded_operator
        device = recorded_operator(cfg)    # the scripted hand retraces the recorded jaw angle
    else:
        device = make_device(cfg, args.protocol)     # master.device.type through the registry
    # from here on the device is closed on every exit path (HID: zero force, stop all effects,
    # disable actuators), whatever fails: session, recording, the loop, Ctrl-C or SIGTERM
    with _closing(device):
        run_dir = side_run_dir(args, cfg, "master")
        ident = cfg.instrument.id
        clock = MonotonicClock()
        injector = _injector(args, clock)
        meta = {"source": "teleop master", "instrument": ident, "device": cfg.master.device.type,
                "columns": master_kind(instrument_kind(cfg)).columns}
        with raise_on_sigterm(), open_session(cfg, args, clock) as session, \
                CsvRecorder(run_dir / "master.csv", csv_columns(cfg), meta, units=csv_units(cfg),
                            flush_every=100) as rec, \
                RerunLogger("teleop", run_dir.name, getattr(args, "rerun", None) or cfg.recording.rerun,
                            run_dir / "master.rrd",
                            wall_clock=True, joints=joint_views(cfg),
                            serve=serve_spec(cfg, "master")) as rr:   # master-side series; same recording id
            links = master_links(session, ident, injector)
            if cfg.ros2.enabled:         # the CRTK topics on ROS 2 beside the loop (teleop/ros2/side.py)
                from teleop.ros2.side import attach_master
                attach_master(session, cfg, links)
            files = SideFiles(run_dir, cfg, "master", ("master.csv", "master.rrd"))
            node = MasterNode(cfg, device, links, recorder=files.csv(rec), rerun=files.rerun(rr))
            _serve(node, clock, args, run_dir, "master", injector, close_first=device.close, waived=waived, files=files)
    faulthandler.cancel_dump_traceback_later()
    _log_master_done(node)
    return 0 if getattr(device, "finished", True) else 1


@contextlib.contextmanager
def _closing(device):
    """``device.close()`` on leaving the block, however it is left."""
    try:
        yield device
    finally:
        device.close()


def load_or_recalibrate(cfg: Config, recalibrate: bool = False):
    """The calibration life cycle of every instrument, as ``teleop slave`` starts it.

    Returns
    -------
    (InstrumentCalibration or None, Path)
        The data reloaded from ``<calibration.dir>/<instrument.id>.yaml``, or None when the file is
        missing or ``recalibrate`` (``--recalibrate``) is set: the slave then calibrates at power-up
        and saves the fit at that path.

    Raises
    ------
    CalibrationError
        The file does not fit the config (another instrument, another kind, bad values); the
        message names the file and the key.
    """
    from slave.calibration_file import calibration_path, load_calibration
    path = calibration_path(cfg)
    again = bool(recalibrate)
    calibration = load_calibration(path, cfg) if path.is_file() and not again else None
    logging.getLogger("teleop.slave").info(
        "calibration %s", f"loaded from {path}" if calibration else
        f"{'recalibrating on request' if again else 'missing'}: calibrating, then {path}")
    return calibration, path
