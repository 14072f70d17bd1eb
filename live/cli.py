"""The ``teleop`` command: ``teleop demo|master|slave|view|bridge|calibrate|analyze|devices``, ``teleop --version``.

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
import importlib.metadata
import logging
import os
import signal
import sys
import threading
from typing import NoReturn

from live.sides import run_master, run_slave
from teleop.errors import TeleopError

__all__ = ["build_parser", "main", "version"]

PROG = "teleop"


def _shared(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", metavar="FILE", help="YAML config over the defaults (configs/default.yaml)")
    p.add_argument("--listen", metavar="EP", action="append",
                   help="Zenoh endpoint to listen on, e.g. tcp/127.0.0.1:7447 (repeatable)")
    p.add_argument("--connect", metavar="EP", action="append",
                   help="Zenoh endpoint to connect to (repeatable)")
    p.add_argument("--run-dir", metavar="DIR", help="directory for recordings and stats (default runs/<timestamp>)")
    p.add_argument("-v", "--verbose", action="store_true", help="log state changes and details")


def _rerun_flag(p: argparse.ArgumentParser) -> None:
    p.add_argument("--rerun", choices=("save", "spawn", "serve", "off"), default=None,
                   help="override recording.rerun (serve: the live view served to `teleop view` and browsers)")


def _model_flag(p: argparse.ArgumentParser) -> None:
    p.add_argument("--model", metavar="PATH", default=None,
                   help="run this model file in the live estimator (estimator.model; `teleop analyze --model-out` "
                        "writes one); checked against the instrument before anything starts")


def _inject_flag(p: argparse.ArgumentParser) -> None:
    p.add_argument("--inject", metavar="SPEC", default=None,
                   help="fault injection on this side's outgoing messages (tests), e.g. "
                        "delay=30ms,drop=0.1,dup=0.05,reorder=0.05,seed=1 or corrupt=nan,stream=command,on=usr1 "
                        "(live/faults.py)")


def version() -> str:
    """The installed version of the ``tsm-teleop`` distribution ("unknown" when it is not installed)."""
    try:
        return importlib.metadata.version("tsm-teleop")
    except importlib.metadata.PackageNotFoundError:
        return "unknown"


def build_parser(argv: list[str] | None = None) -> argparse.ArgumentParser:
    """The argument parser. ``argv`` (default ``sys.argv[1:]``) decides whether ``study.analyze``, the replay and the
    HID device list are imported (only for ``analyze``, ``replay`` and ``devices``)."""
    parser = argparse.ArgumentParser(prog=PROG, description="Haptic teleoperation of tendon-sheath instruments.")
    parser.add_argument("--version", action="version", version=f"%(prog)s {version()}")
    sub = parser.add_subparsers(dest="command",
                                metavar="{demo,master,slave,view,record,router,bridge,calibrate,replay,analyze,"
                                        "devices}",
                                required=True)
    args = sys.argv[1:] if argv is None else argv
    _add_sides(sub)
    _add_services(sub)
    _add_lazy(sub, args)
    return parser


def _add_sides(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The two sides and the demo that runs both."""
    p = sub.add_parser("demo", help="both sides as two processes over Zenoh on 127.0.0.1, then a summary")
    _shared(p)
    p.add_argument("--protocol", default="paper,minor",
                   help="scripted operator protocol(s), comma separated: paper, minor, short (a joint instrument: "
                        "paper or short); checked before anything starts (default paper,minor)")
    p.add_argument("--timeout", type=float, default=None,
                   help="give up on the processes after this [s] (default 50; with a recording its length + 120)")
    p.add_argument("--rig", choices=("simulated", "zenoh", "recording"), default=None, help="override rig.type")
    p.add_argument("--recording", metavar="PATH", default=None,
                   help="play this measured recording as the hardware (rig.type recording, rig.recording.path): an "
                        "MRD run, a KAIST recording or a measured-data CSV, told apart by its content; without "
                        "--config the instrument of configs/recording-mrd.yaml, recording-kaist.yaml or sim.yaml")
    p.add_argument("--keep-realtime", action="store_true",
                   help="run the sides at their configured SCHED_FIFO priorities even on a machine of fewer than 4 "
                        "CPUs, where the demo otherwise runs them with normal scheduling (docs/how-to/real-time.md)")
    _model_flag(p)
    _rerun_flag(p)
    p.set_defaults(func=_cmd_demo)

    p = sub.add_parser("slave", help="instrument side: reload or make the calibration, then follow commands and "
                                     "estimate")
    _shared(p)
    p.add_argument("--recalibrate", action="store_true",
                   help="calibrate at power-up even when <calibration.dir>/<instrument.id>.yaml exists "
                        "(and replace it)")
    p.add_argument("--exit-on-master-stop", action="store_true", help="finish when the master announces STOPPING")
    p.add_argument("--max-duration", type=float, default=None, metavar="S", help="stop after this long [s]")
    _model_flag(p)
    _rerun_flag(p)
    _inject_flag(p)
    p.set_defaults(func=_cmd_slave)

    p = sub.add_parser("master", help="operator side: device -> commands, estimate -> force")
    _shared(p)
    p.add_argument("--protocol", default="paper,minor",
                   help="scripted operator protocol(s), comma separated: paper, minor, short")
    _rerun_flag(p)
    _inject_flag(p)
    p.add_argument("--max-duration", type=float, default=None, metavar="S", help="stop after this long [s]")
    p.set_defaults(func=_cmd_master)


def _add_services(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The processes around the sides (recorder, router, bridge) and the offline commands on the rig."""
    p = sub.add_parser("record", help="record every stream of the instrument over Zenoh (live/record/recorder.py)")
    _shared(p)
    p.add_argument("--max-duration", type=float, default=None, metavar="S", help="stop after this long [s]")
    p.add_argument("--exit-when-done", action="store_true", help="finish once every side seen has gone")
    p.add_argument("--repair", metavar="RUN", help="rebuild RUN/recorder/session.mcap from messages.bin and the "
                                                   "sides' journals (after a SIGKILL of the recorder), then exit")
    p.add_argument("--journals", metavar="DIR", default=None,
                   help="where the sides' write-ahead journals are (default: the run directory); the records of this "
                        "instrument's keys complete the recording (a bimanual session: the session's run directory)")
    p.add_argument("--rerun", choices=("save", "spawn", "off"), default=None, help="override recording.rerun")
    p.set_defaults(func=lambda a: __import__("live.record.recorder", fromlist=["run_record"]).run_record(a))

    p = sub.add_parser("router", help="a Zenoh router the sides and the recorder connect to (live/router.py)")
    _shared(p)
    p.add_argument("--max-duration", type=float, default=None, metavar="S", help="stop after this long [s]")
    p.set_defaults(func=lambda a: __import__("live.router", fromlist=["run_router"]).run_router(a))

    p = sub.add_parser("bridge", help="the simulated rig of --config behind the Zenoh rig interface (rig.type "
                                      "zenoh on the slave), as its own process")
    _shared(p)
    p.add_argument("--max-duration", type=float, default=None, metavar="S", help="stop after this long [s]")
    p.set_defaults(func=_cmd_bridge)

    p = sub.add_parser("calibrate", help="the instrument's power-up calibration (tendons pulled into their joint "
                                         "limits, a pair both ways; spindles stroked over their open jaws) on its "
                                         "simulator, saved where the slave reloads it: <calibration.dir>/<instrument>"
                                         ".yaml (default ~/.local/share/tsm-teleop/calibration)")
    from live.calibrate import add_calibrate_arguments
    add_calibrate_arguments(p)
    p.set_defaults(func=_cmd_calibrate)

    p = sub.add_parser("keys", help="the installation's credentials every process authenticates with: where they "
                                    "are (made if missing), --renew, --export DIR (live/keys.py)")
    from live import keys
    keys.add_arguments(p)
    p.set_defaults(func=keys.main_keys)

    p = sub.add_parser("view", help="watch a session served with recording.rerun: serve (slave and master) from "
                                    "this or another machine: the desktop viewer, or --web for a browser's URL")
    p.add_argument("--config", metavar="FILE", help="the session's config: its recording.rerun_serve ports")
    p.add_argument("--slave", metavar="HOST", default=None,
                   help="address of the slave's machine (default recording.rerun_serve.bind)")
    p.add_argument("--master", metavar="HOST", default=None,
                   help="address of the master's machine (default recording.rerun_serve.bind)")
    p.add_argument("--web", action="store_true", help="print the web viewer's URL for a browser instead")
    p.add_argument("--screenshot-to", metavar="PNG", default=None,
                   help="save a picture of the view and quit (at 2 pixels per point of --window-size)")
    p.add_argument("--window-size", metavar="WxH", default=None, help="the viewer's window size in points")
    p.set_defaults(func=_cmd_view)


def _add_lazy(sub: argparse._SubParsersAction[argparse.ArgumentParser], args: list[str]) -> None:
    """The commands whose modules load only when ``args`` name them (hidapi, the estimator's kernels, the offline
    study)."""
    p = sub.add_parser("devices", help="list what each device backend finds (hid, evdev, forcedimension, touch)")
    if "devices" in args[:1]:
        from master import devices_list  # lazy: only `teleop devices` imports hidapi
        devices_list.add_arguments(p)
        p.set_defaults(func=devices_list.main_devices)
    else:
        p.set_defaults(func=None)
    replay = _lazy_parser(sub, args, "replay", "play a recorded run back through the estimator and the Rerun view, "
                          "compared with the recorded estimate and the truth (live/replay/main.py)")
    if replay is not None:
        from live.replay import main as replay_main  # lazy: the estimator's kernels load only for `teleop replay`
        replay_main.add_arguments(replay)
        replay.set_defaults(func=replay_main.main_replay)
    analysis = _lazy_parser(sub, args, "analyze", "run the model against a recording")
    if analysis is not None:
        from study import analyze  # lazy: only `teleop analyze` pays for it
        analyze.add_arguments(analysis)
        from study.mrd.tools import add_tool_argument
        add_tool_argument(analysis)
        analysis.set_defaults(func=analyze.main_analyze)


def _lazy_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser], args: list[str], name: str,
                 help_text: str) -> argparse.ArgumentParser | None:
    """The subcommand ``name``'s parser, for its caller to fill, when ``args`` name it; else a placeholder listed
    with its help (no arguments, no function) and None: its module is not imported."""
    if name in args[:1]:
        return sub.add_parser(name, help=help_text)
    sub.add_parser(name, help=f"{help_text} (see `teleop {name} -h`)", add_help=False).set_defaults(func=None)
    return None


# ---- subcommands ---------------------------------------------------------------------------------

def _cmd_demo(args: argparse.Namespace) -> int:
    from live.demo.main import main_demo
    return main_demo(args)


def _cmd_calibrate(args: argparse.Namespace) -> int:
    """``teleop calibrate``: the power-up calibration (live/calibrate.py), or with ``--diagnose`` the single tendon's
    calibration, excitation, diagnosis and model file (live/diagnose.py)."""
    if args.diagnose:
        from live.diagnose import run_diagnose
        return run_diagnose(args)
    from live.calibrate import run_calibrate
    return run_calibrate(args)


def _cmd_bridge(args: argparse.Namespace) -> int:
    from live.bridge import run_bridge
    return run_bridge(args)


def _cmd_view(args: argparse.Namespace) -> int:
    """``teleop view``: the desktop viewer on both sides' streams (its exit code), or with ``--web`` the URLs."""
    import subprocess

    from teleop.config.load import load_config
    from teleop.rerun.serve import session_streams, viewer_command, viewer_env, web_url
    cfg = load_config(args.config)
    streams = session_streams(cfg, args.slave, args.master)
    serve = cfg.recording.rerun_serve
    if args.web:
        if not (serve.slave_web_port or serve.master_web_port):
            raise ValueError("recording.rerun_serve: slave_web_port and master_web_port are 0: no web viewer")
        for side, host, port in (("slave", args.slave, serve.slave_web_port),
                                 ("master", args.master, serve.master_web_port)):
            if port:
                print(f"{side}'s web viewer, both sides: {web_url(host or serve.bind, port, streams)}")
        return 0
    cmd = viewer_command(streams, args.screenshot_to, args.window_size)
    try:
        return subprocess.run(cmd, env=viewer_env(), check=False).returncode
    except OSError as e:
        raise ValueError(f"the Rerun viewer {cmd[0]} cannot start ({e.strerror}): install rerun-sdk") from None


def _cmd_slave(args: argparse.Namespace) -> int:
    from teleop.arms import is_bimanual
    if is_bimanual(args.config):          # every arm's node in one loop (live/bimanual_sides.py)
        if getattr(args, "model", None):
            raise ValueError(f"--model {args.model}: {args.config} is bimanual; set estimator.model in an arm's config")
        from live.bimanual_sides import run_slave_group
        return run_slave_group(args)
    return run_slave(args)


def _cmd_master(args: argparse.Namespace) -> int:
    from teleop.arms import is_bimanual
    if is_bimanual(args.config):          # both hands' nodes in one loop (live/bimanual_sides.py)
        from live.bimanual_sides import run_master_group
        return run_master_group(args)
    return run_master(args)


# ---- path arguments ------------------------------------------------------------------------------

#: (argument's dest, its flag, "file" read or written / "dir" written into or read from, the commands it has
#: that meaning in: None every command that has it)
PATH_ARGS: tuple[tuple[str, str, str, tuple[str, ...] | None], ...] = (
    ("config", "--config", "file", None), ("run_dir", "--run-dir", "dir", None),
    ("recording", "--recording", "file", None), ("journals", "--journals", "dir", None),
    ("repair", "--repair", "dir", None), ("out", "--out", "file", None), ("rrd", "--rrd", "file", None),
    ("json", "--json", "file", None), ("calibration", "--calibration", "file", ("replay",)),
    ("model", "--model", "file", None), ("model_out", "--model-out", "dir", ("analyze",)),
    ("model_out", "--model-out", "file", ("calibrate",)),
    ("file", "FILE", "file", ("analyze",)), ("route", "--route", "file", ("analyze",)),
    ("kaist", "--kaist", "dir", ("analyze",)), ("mrd", "--mrd", "dir", ("analyze",)),
    ("report", "--report", "dir", ("analyze",)), ("figures", "--figures", "dir", ("analyze",)),
    ("screenshot_to", "--screenshot-to", "file", ("view",)))


def path_args_problem(args: argparse.Namespace) -> str | None:
    """The first argument of ``args`` that cannot be right, as ``<flag> <value>: <what is wrong>``; None: none.

    A duration (``--max-duration``, ``--timeout``) that is negative or not a number, and a path argument of
    :data:`PATH_ARGS` of the wrong kind (a directory for a file, a file for a directory:
    :func:`teleop.config.paths.path_problem`)."""
    import math

    from teleop.config.paths import path_problem
    for dest, flag in (("max_duration", "--max-duration"), ("timeout", "--timeout")):
        seconds = getattr(args, dest, None)
        if isinstance(seconds, float) and (math.isnan(seconds) or seconds < 0):
            return f"{flag} {seconds!r}: expected a number of seconds >= 0"
    for dest, flag, want, commands in PATH_ARGS:
        value = getattr(args, dest, None)
        if not isinstance(value, str) or not value or (commands is not None and args.command not in commands):
            continue
        if dest == "model_out" and args.command == "analyze" and getattr(args, "file", None):
            continue        # FILE.csv --model-out OUT.yaml: one file, checked by study.tendon_model.check_model_out
        problem = path_problem(value, "file" if want == "file" else "dir")
        if problem is not None:
            return f"{flag} {value}: {problem}"
    return None


# ---- entry point ---------------------------------------------------------------------------------

def main(argv: list[str] | None = None) -> int:
    """Run ``teleop`` with ``argv`` (default ``sys.argv[1:]``); returns the exit code."""
    argv = sys.argv[1:] if argv is None else list(argv)
    try:
        parser = build_parser(argv)
    except ImportError as e:
        print(f"{PROG}: error: {argv[0] if argv else PROG} is not available ({e})", file=sys.stderr)
        return 2
    args = parser.parse_args(argv)
    if args.func is None:
        print(f"{PROG}: error: {args.command} is not available in this build", file=sys.stderr)
        return 2
    problem = path_args_problem(args)       # before any config is read or any process started
    if problem is not None:
        print(f"{PROG}: error: {problem}", file=sys.stderr)
        return 2
    if args.command in ("record", "calibrate", "bridge") and getattr(args, "config", None):
        from teleop.arms import is_bimanual
        if is_bimanual(args.config):      # these serve one instrument: one arm of the two
            print(f"{PROG}: error: {args.config} is a bimanual config; teleop {args.command} takes one arm's config "
                  f"(teleop demo writes each to runs/<id>/<arm id>/config.yaml)", file=sys.stderr)
            return 2
    logging.basicConfig(level=logging.INFO if getattr(args, "verbose", False) or args.command in ("slave", "master",
                                                                                                     "bridge")
                        else logging.WARNING,
                        format=f"[{args.command}] %(levelname)s %(message)s", stream=sys.stderr)
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt as e:   # Ctrl-C, or SIGTERM inside raise_on_sigterm (Terminated)
        from teleop.recording.measured import Terminated
        stopped = isinstance(e, Terminated)
        print(f"{PROG}: {'terminated' if stopped else 'interrupted'}", file=sys.stderr)
        return 143 if stopped else 130
    except (TeleopError, ValueError, FileNotFoundError) as e:
        msg = " ".join(str(e).split()) or type(e).__name__
        print(f"{PROG}: error: {msg}", file=sys.stderr)
        return 2


#: after main has returned (its files flushed and closed), the process ends within this many seconds [s] even
#: if a library's teardown at interpreter exit blocks (a zenoh runtime; see teleop.session.transport.CLOSE_TIMEOUT_S)
EXIT_GRACE_S = 10.0


def run() -> NoReturn:
    """The ``teleop`` program (console script and ``python -m live.cli``): :func:`main`, then exit with
    its code; a watchdog ends the process with that code EXIT_GRACE_S after main returned if the interpreter's
    own exit has not (a non-daemon thread or a native runtime that does not stop). SIGINT stops it cleanly
    (KeyboardInterrupt, exit 130) even when it was started with SIGINT ignored, as a non-interactive shell
    starts a background job (a process that ignored SIGINT would outlive the shell's interrupt)."""
    signal.signal(signal.SIGINT, signal.default_int_handler)
    code = main()
    sys.stdout.flush()
    sys.stderr.flush()
    watchdog = threading.Timer(EXIT_GRACE_S, os._exit, (code,))
    watchdog.daemon = True
    watchdog.start()
    sys.exit(code)


if __name__ == "__main__":  # python -m live.cli
    run()
