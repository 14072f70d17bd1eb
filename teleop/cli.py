"""The ``teleop`` command: ``teleop demo|master|slave|calibrate|analyze|devices``.

:func:`main` takes an argument list and returns an exit code; argument parsing is separate
(:func:`build_parser`) and every subcommand is a function of the parsed arguments. Exit codes:

* 0   done;
* 1   the run finished but failed its checks (``demo``: accuracy or process failure);
* 2   bad input: unknown option, config typo, missing file, bad CSV... one line
      ``teleop: error: <message>`` on stderr, no traceback;
* 130 interrupted by Ctrl-C, 143 stopped by SIGTERM; recordings are closed and flushed either way.

Shared flags: ``--config FILE`` (YAML over the defaults), ``--listen EP`` / ``--connect EP``
(repeatable Zenoh endpoints such as ``tcp/127.0.0.1:7447``; given either, they replace both
configured lists), ``--run-dir DIR`` (where recordings and stats go; default
``<recording.dir>/<timestamp>``).
"""
from __future__ import annotations

import argparse
import contextlib
import logging
import sys
import time
from pathlib import Path

from teleop.errors import DeviceError, TeleopError

__all__ = ["build_parser", "main", "run_slave", "run_master", "default_run_dir", "prepare_run_dir", "endpoints",
           "open_session", "slave_links", "master_links"]

PROG = "teleop"


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
    from teleop.errors import TransportError
    from teleop.transport import Session, zenoh_config

    listen, connect = endpoints(args)
    zcfg = zenoh_config(cfg.transport, listen=listen, connect=connect)
    try:
        return Session(zcfg, clock=clock)
    except TransportError as e:
        lst = cfg.transport.listen if listen is None else listen
        con = cfg.transport.connect if connect is None else connect
        raise TransportError(f"{e} (listen: {', '.join(lst) or 'none'}; connect: {', '.join(con) or 'none'})") from None


def _shared(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", metavar="FILE", help="YAML config over the defaults (configs/default.yaml)")
    p.add_argument("--listen", metavar="EP", action="append",
                   help="Zenoh endpoint to listen on, e.g. tcp/127.0.0.1:7447 (repeatable)")
    p.add_argument("--connect", metavar="EP", action="append",
                   help="Zenoh endpoint to connect to (repeatable)")
    p.add_argument("--run-dir", metavar="DIR", help="directory for recordings and stats (default runs/<timestamp>)")
    p.add_argument("-v", "--verbose", action="store_true", help="log state changes and details")


def _inject_flag(p: argparse.ArgumentParser) -> None:
    p.add_argument("--inject", metavar="SPEC", default=None,
                   help="fault injection on this side's outgoing messages (tests), e.g. "
                        "delay=30ms,drop=0.1,dup=0.05,reorder=0.05,seed=1 or corrupt=nan,stream=command,on=usr1 "
                        "(teleop/faults.py)")


def _injector(args: argparse.Namespace, clock):
    """The fault injector of ``--inject`` (SIGUSR1 trigger installed), or None."""
    if not getattr(args, "inject", None):
        return None
    from teleop.faults import FaultInjector
    inj = FaultInjector(args.inject, clock)
    inj.install_signal()
    logging.getLogger("teleop.faults").warning("fault injection on: %s", args.inject)
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
    from teleop.keys import heartbeat_key, liveliness_key
    from teleop.messages import Heartbeat

    watcher = session.liveliness_watcher(liveliness_key(ident, peer))
    streams = (_publisher(session, out[0], out[1], injector),
               _publisher(session, heartbeat_key(ident, me), "heartbeat", injector),
               session.subscriber(incoming[0], incoming[1]),
               session.subscriber(heartbeat_key(ident, peer), Heartbeat),
               lambda: watcher.alive)
    session.liveliness_token(liveliness_key(ident, me))
    return streams


def slave_links(session, ident: str, injector, command_type):
    """The slave's links on ``session`` (:func:`_side_streams`): estimates out, commands of
    ``command_type`` (Command or JointCommand) in."""
    from slave.node_base import SlaveLinks
    from teleop.keys import command_key, estimate_key

    # SlaveLinks' fields in order: estimate, heartbeat, command, master_heartbeat, master_alive
    return SlaveLinks(*_side_streams(session, ident, injector, "slave", "master", (estimate_key(ident), "estimate"),
                                     (command_key(ident), command_type)))


def master_links(session, ident: str, injector, estimate_type):
    """The master's links on ``session`` (:func:`_side_streams`): commands out, estimates of
    ``estimate_type`` (Estimate or JointEstimate) in."""
    from master.node_base import MasterLinks
    from teleop.keys import command_key, estimate_key

    # MasterLinks' fields in order: command, heartbeat, estimate, slave_heartbeat, slave_alive
    return MasterLinks(*_side_streams(session, ident, injector, "master", "slave", (command_key(ident), "command"),
                                      (estimate_key(ident), estimate_type)))


def _serve(node, clock, args: argparse.Namespace, run_dir: Path, side: str, injector, *, close_first=None) -> None:
    """Run ``node`` until done (or ``--max-duration``); however it ends, ``close_first()`` (e.g. the
    device), then ``<side>_stats.json`` and ``<side>_faults.json`` in ``run_dir``."""
    try:
        node.run(clock, max_duration=args.max_duration)
    finally:
        if close_first is not None:
            close_first()
        node.write_stats(run_dir / f"{side}_stats.json")
        _write_fault_stats(injector, run_dir / f"{side}_faults.json")


def _log_master_done(node) -> None:
    lat = node.latency_stats()
    logging.getLogger("teleop.master").info("master done: %s commands, rtt p50 %s ms, p99 %s ms",
                                            node.commands_sent, lat["p50_ms"], lat["p99_ms"])


def build_parser(argv: list[str] | None = None) -> argparse.ArgumentParser:
    """The argument parser. ``argv`` decides whether ``teleop.analyze`` is imported (only for analyze)."""
    parser = argparse.ArgumentParser(prog=PROG, description="Haptic teleoperation of tendon-sheath instruments.")
    sub = parser.add_subparsers(dest="command", metavar="{demo,master,slave,calibrate,analyze,devices}", required=True)

    p = sub.add_parser("demo", help="both sides as two processes over Zenoh on 127.0.0.1, then a summary")
    _shared(p)
    p.add_argument("--protocol", default="paper,minor", help="operator protocol(s) (default paper,minor)")
    p.add_argument("--timeout", type=float, default=50.0, help="give up on the processes after this [s]")
    p.set_defaults(func=_cmd_demo)

    p = sub.add_parser("slave", help="instrument side: calibrate, then follow commands and estimate")
    _shared(p)
    p.add_argument("--exit-on-master-stop", action="store_true", help="finish when the master announces STOPPING")
    p.add_argument("--max-duration", type=float, default=None, metavar="S", help="stop after this long [s]")
    p.add_argument("--rerun", choices=("save", "spawn", "off"), default=None, help="override recording.rerun")
    _inject_flag(p)
    p.set_defaults(func=_cmd_slave)

    p = sub.add_parser("master", help="operator side: device -> commands, estimate -> force")
    _shared(p)
    p.add_argument("--protocol", default="paper,minor",
                   help="scripted operator protocol(s), comma separated: paper, minor, short")
    _inject_flag(p)
    p.add_argument("--max-duration", type=float, default=None, metavar="S", help="stop after this long [s]")
    p.set_defaults(func=_cmd_master)

    p = sub.add_parser("calibrate", help="joint instruments: joint-limit calibration of every tendon, both "
                                         "directions, saved as configs/calibration/<instrument>.yaml")
    from teleop.cli_joints import add_calibrate_arguments, run_calibrate
    add_calibrate_arguments(p)
    p.set_defaults(func=run_calibrate)

    p = sub.add_parser("devices", help="list HID devices (vendor/product id, usage page, usage, path)")
    if "devices" in (sys.argv[1:] if argv is None else argv)[:1]:
        from master import devices_list  # lazy: only `teleop devices` imports hidapi
        devices_list.add_arguments(p)
        p.set_defaults(func=devices_list.main_devices)
    else:
        p.set_defaults(func=None)

    args = sys.argv[1:] if argv is None else argv
    if "analyze" in args[:1]:
        from teleop import analyze  # lazy: only `teleop analyze` pays for it
        p = sub.add_parser("analyze", help="run the model against a recording")
        analyze.add_arguments(p)
        p.set_defaults(func=analyze.main_analyze)
    else:
        p = sub.add_parser("analyze", help="run the model against a recording (see `teleop analyze -h`)",
                           add_help=False)
        p.set_defaults(func=None)
    return parser


# ---- subcommands ---------------------------------------------------------------------------------

def _cmd_demo(args: argparse.Namespace) -> int:
    from teleop.demo import main_demo
    return main_demo(args)


def _cmd_slave(args: argparse.Namespace) -> int:
    return run_slave(args)


def _cmd_master(args: argparse.Namespace) -> int:
    return run_master(args)


def run_slave(args: argparse.Namespace) -> int:
    """``teleop slave``: calibrate the rig, then serve commands until stopped."""
    from slave.node import SlaveNode, csv_columns, warm_up
    from slave.simulated import SimulatedRig
    from teleop.clock import MonotonicClock
    from teleop.config import load_config
    from teleop.messages import Command
    from teleop.recording import CsvRecorder, raise_on_sigterm
    from teleop.rerun_log import RerunLogger

    cfg = load_config(args.config)
    if cfg.instrument.joints:           # a joint instrument: its own node, same transport and flags
        from teleop.cli_joints import run_joint_slave
        return run_joint_slave(args, cfg)
    run_dir = prepare_run_dir(args, cfg)
    warm_up(cfg)  # compile the numba kernels now, not in the first real-time cycles
    rig = SimulatedRig.from_config(cfg)
    has_truth = rig.state.truth is not None
    meta = {"source": "teleop slave", "instrument": cfg.instrument.id, "rig": cfg.rig.type,
            "truth": "x_out, T_out, elongation are simulator ground truth (evaluation only)" if has_truth else "none"}
    ident = cfg.instrument.id
    clock = MonotonicClock()
    injector = _injector(args, clock)
    node = None
    with raise_on_sigterm(), \
            open_session(cfg, args, clock) as session, \
            CsvRecorder(run_dir / "slave.csv", csv_columns(has_truth), meta, flush_every=500) as rec, \
            RerunLogger("teleop", run_dir.name, args.rerun or cfg.recording.rerun, run_dir / "slave.rrd") as rr:
        links = slave_links(session, ident, injector, Command)
        node = SlaveNode(cfg, rig, links, recorder=rec, rerun=rr, run_dir=run_dir,
                         stop_on_master_stop=args.exit_on_master_stop)
        _serve(node, clock, args, run_dir, "slave", injector)
    logging.getLogger("teleop.slave").info("slave done: %s", run_dir)
    return 0


def open_device(cfg, protocol: str):
    """The configured haptic device (``master.device.type``) for the configured instrument.

    Raises
    ------
    DeviceError
        A HID device for a joint instrument (one report map per axis is not there yet), or a HID
        device that cannot be opened (named).
    """
    from master.simulated import ScriptedOperator, build_protocol
    if cfg.master.device.type == "hid":
        if cfg.instrument.joints:
            raise DeviceError("master.device.type: a HID device drives a single tendon so far; joint instruments "
                              "have the simulated multi-axis operator")
        from master.hid import HidDevice
        # opens, resets and enables the actuators; raises DeviceError naming the device when absent
        return HidDevice.from_file(cfg.master.device.file)
    if cfg.instrument.joints:
        from master.joint_operator import MultiAxisOperator
        from teleop.cli_joints import joint_protocols
        return MultiAxisOperator(joint_protocols(cfg, "paper" if protocol in ("paper,minor", "paper") else protocol),
                                 clutch_bit=cfg.master.mapping.clutch_button)
    return ScriptedOperator(build_protocol(protocol), clutch_bit=cfg.master.mapping.clutch_button)


def run_master(args: argparse.Namespace) -> int:
    """``teleop master``: run the operator side of any instrument until the device's protocol is finished."""
    from master.node import MasterNode, csv_columns, csv_units
    from teleop.clock import MonotonicClock
    from teleop.config import load_config
    from teleop.messages import Estimate, JointEstimate
    from teleop.recording import CsvRecorder, raise_on_sigterm

    cfg = load_config(args.config)
    device = open_device(cfg, args.protocol)
    # from here on the device is closed on every exit path (HID: zero force, stop all effects,
    # disable actuators), whatever fails: session, recording, the loop, Ctrl-C or SIGTERM
    with _closing(device):
        run_dir = prepare_run_dir(args, cfg)
        ident = cfg.instrument.id
        clock = MonotonicClock()
        injector = _injector(args, clock)
        meta = {"source": "teleop master", "instrument": ident, "device": cfg.master.device.type,
                "columns": "x_in = command sent, T_in = slave's latest proximal tension, force = rendered"
                if not cfg.instrument.joints else "per joint: cmd, slave angle [rad], device position [m], "
                "rendered tension torque_hat / r [N], forces [N], passivity energy [J]"}
        with raise_on_sigterm(), open_session(cfg, args, clock) as session, \
                CsvRecorder(run_dir / "master.csv", csv_columns(cfg), meta, units=csv_units(cfg), flush_every=100) as rec:
            links = master_links(session, ident, injector, JointEstimate if cfg.instrument.joints else Estimate)
            node = MasterNode(cfg, device, links, recorder=rec)
            _serve(node, clock, args, run_dir, "master", injector, close_first=device.close)
    _log_master_done(node)
    return 0 if getattr(device, "finished", True) else 1


@contextlib.contextmanager
def _closing(device):
    """``device.close()`` on leaving the block, however it is left."""
    try:
        yield device
    finally:
        device.close()


# ---- entry point ---------------------------------------------------------------------------------

def main(argv: list[str] | None = None) -> int:
    """Run ``teleop`` with ``argv`` (default ``sys.argv[1:]``); returns the exit code."""
    argv = sys.argv[1:] if argv is None else list(argv)
    try:
        parser = build_parser(argv)
    except ImportError as e:
        print(f"{PROG}: error: analyze is not available ({e})", file=sys.stderr)
        return 2
    args = parser.parse_args(argv)
    if args.func is None:
        print(f"{PROG}: error: {args.command} is not available in this build", file=sys.stderr)
        return 2
    logging.basicConfig(level=logging.INFO if getattr(args, "verbose", False) or args.command in ("slave", "master")
                        else logging.WARNING,
                        format=f"[{args.command}] %(levelname)s %(message)s", stream=sys.stderr)
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt as e:   # Ctrl-C, or SIGTERM inside raise_on_sigterm (Terminated)
        from teleop.recording import Terminated
        stopped = isinstance(e, Terminated)
        print(f"{PROG}: {'terminated' if stopped else 'interrupted'}", file=sys.stderr)
        return 143 if stopped else 130
    except (TeleopError, ValueError, FileNotFoundError) as e:
        msg = " ".join(str(e).split()) or type(e).__name__
        print(f"{PROG}: error: {msg}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # python -m teleop.cli
    sys.exit(main())
