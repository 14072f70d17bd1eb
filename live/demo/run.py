"""What the demo of every instrument shares (:mod:`live.demo.main`; a joint instrument's evaluation:
:mod:`live.demo.joints`): the two processes over Zenoh on 127.0.0.1, and the pieces of the summary that
do not depend on the instrument.

* :func:`run_processes`: the slave (``python -m live.cli slave``) listens on a free TCP port (or
  the first ``--listen``); once the port accepts connections the master connects. When the master
  has finished its protocol it announces STOPPING and the slave exits too. Either running past
  ``--timeout`` is stopped with SIGTERM (recordings are flushed) and reported, as is a non-zero exit;
  the recorder gets :data:`RECORDER_GRACE` after the sides, past ``--timeout`` if need be. The recorder
  (``teleop record``) starts first, or several (:class:`RecorderRun`, one per arm of a bimanual instrument:
  :mod:`live.demo.bimanual`), each ready before the sides start, which connect to all of them.
  With ``rig.type: zenoh`` a third process, ``teleop bridge``, runs the simulated rig behind the
  Zenoh rig interface and the slave connects to it. The processes authenticate with credentials of their own
  (:mod:`teleop.session.credentials`), made for the run in a temporary folder and removed when it ends: no other
  process, whatever credentials it holds, links to the demo's session.
* :func:`full_scale_errors`: max and mean of |estimate - truth| over the range of the truth.
* :func:`master_console_line`, :func:`loop_lines`, :func:`machine_line`, :func:`rt_budget_lines`, :func:`verdict_lines`:
  the lines on the master's console, on both loops, the machine and the link, and on the checks.
* :func:`finish`: checks, problems and wall time into the summary, ``summary.json``, the printed
  table, the exit code.
* :func:`check_protocol`: ``--protocol`` checked against the instrument before anything starts.
* :func:`co_located`: the sides' scheduling on a machine too small for their real-time threads beside the
  recorders (:data:`teleop.timing.realtime.CO_LOCATED_MIN_CPUS`).
"""
from __future__ import annotations

import contextlib
import dataclasses
import json
import math
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from teleop.config.schema import Config

__all__ = ["run_processes", "RecorderRun", "read_json", "full_scale_errors", "master_console_line", "loop_lines",
           "machine_line", "rt_budget_lines", "verdict_lines", "finish", "check_protocol", "co_located"]


def co_located(cfg: Config) -> tuple[Config, str | None]:
    """The run's config with the sides' real-time priorities for one machine that runs both sides and the recorders
    (:func:`teleop.timing.realtime.co_located_priority`; :mod:`live.demo.main` and :mod:`live.demo.bimanual`), and
    the line that says why they changed (None: as configured)."""
    from teleop.timing.realtime import co_located_priority
    master, why = co_located_priority(cfg.master.realtime_priority)
    slave, why_slave = co_located_priority(cfg.slave.realtime_priority)
    if why is None and why_slave is None:
        return cfg, None
    return dataclasses.replace(cfg, master=dataclasses.replace(cfg.master, realtime_priority=master),
                               slave=dataclasses.replace(cfg.slave, realtime_priority=slave)), why or why_slave


def check_protocol(cfg: Config, protocol: str) -> None:
    """Raise ConfigError (one line: ``--protocol <value>: <the name that is wrong> (<the valid ones>)``) when the
    scripted operator of ``cfg`` (``master.device.type: simulated``) has no protocol ``protocol``: the master
    would refuse it only after the calibration and the start of both sides
    (:func:`master.protocols.operator_protocols`)."""
    from master.kinds import operator_protocols
    from teleop.errors import ConfigError
    if cfg.master.device.type != "simulated":       # a hand on a device: no scripted protocol
        return
    try:
        operator_protocols(cfg, protocol)
    except ConfigError as e:
        raise ConfigError(f"--protocol {protocol}: {str(e).removeprefix('protocol: ')}") from None


def full_scale_errors(est: np.ndarray, true: np.ndarray) -> tuple[float, float]:
    """(max, mean) of ``|est - true|`` divided by the range of ``true`` [-]; NaN when the range is 0.

    est, true : ndarray, shape (n_samples,), same unit.
    """
    fs = float(np.ptp(true))
    if fs <= 0:
        return math.nan, math.nan
    err = np.abs(est - true)
    return float(err.max() / fs), float(err.mean() / fs)


def read_json(path: Path) -> dict:
    """The JSON object in ``path``; {} when the file is missing (a process that did not get that far)."""
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return {}


def master_console_line(m: dict) -> str:
    """The master's console over the run from its stats: engagements, clutches, alignment refusals,
    safe events, the largest rendered force against the limit."""
    return (f"master console: engaged {m.get('engage_count', 0)} time(s), clutches {m.get('clutches', 0)}, "
            f"align refusals {m.get('align_refusals', 0)}, safe events {m.get('safe_events', 0)}, "
            f"max |force| {m.get('max_abs_force', 0.0):.2f} N (limit {m.get('force_limit', 0.0):g} N)")


def loop_lines(s: dict, *, detailed: bool) -> list[str]:
    """One line per side (cycles, rate, overruns, safe events), then the round trip when echoes were
    seen (p50, p99); ``detailed`` adds each loop's stalls (overruns that lost a whole period: one per
    stall, :class:`teleop.timing.clock.Pacer`), skipped deadlines, late starts, worst lateness and the round
    trip's maximum."""
    lines = []
    for side in ("master", "slave"):
        st = s.get(side, {})
        pc = st.get("pacer", {})
        worst = f"worst lateness {1e3 * pc.get('max_lateness', 0):.1f} ms, " if detailed else ""
        stalls = (f"{pc['stalls']} of them stalls > 1 period ({pc.get('skipped', 0)} deadlines skipped), "
                  f"{pc.get('late_starts', 0)} late starts > 1/2 period, " if detailed and "stalls" in pc else "")
        lines.append(f"{side:6s} loop: {pc.get('ticks', 0)} cycles at {pc.get('rate_hz', 0):.0f} Hz, "
                     f"{pc.get('overruns', 0)} overruns ({100 * pc.get('overrun_fraction', 0):.2f} %), "
                     f"{stalls}{worst}safe events {st.get('safe_events', 0)}")
    line = machine_line(s)
    if line and detailed:
        lines.append(line)
    if detailed:
        lines += rt_budget_lines(s)
    lat = s.get("master", {}).get("latency_rtt", {})
    if lat.get("n") and detailed:
        lines.append(f"round trip (command -> estimate echo): p50 {lat['p50_ms']:.2f} ms, p99 {lat['p99_ms']:.2f} ms, "
                     f"max {lat['max_ms']:.2f} ms over {lat['n']} echoes")
    elif lat.get("n"):
        lines.append(f"round trip: p50 {lat['p50_ms']:.2f} ms, p99 {lat['p99_ms']:.2f} ms over {lat['n']} echoes")
    return lines


def machine_line(s: dict) -> str | None:
    """The machine under both loops: the hypervisor's steal during each loop (CPU time a virtual
    machine lost to its host: stalls that stop every process at once, which no priority prevents)
    and the load average at start and end; None when the stats have no ``pacer.machine``."""
    parts = []
    for side in ("master", "slave"):
        m = s.get(side, {}).get("pacer", {}).get("machine")
        if not m:
            continue
        steal = "unknown" if m.get("steal_ms") is None else f"{m['steal_ms']:.0f} ms"
        load = "" if m.get("load_start") is None else f", load {m['load_start']:.1f} -> {m['load_end']:.1f}"
        parts.append(f"{side} {steal} in {m.get('loop_s', 0):.1f} s{load}")
    if not parts:
        return None
    cpus = next((s[k]["pacer"]["machine"].get("cpus") for k in ("master", "slave")
                 if s.get(k, {}).get("pacer", {}).get("machine")), None)
    return f"machine steal (VM stalls, {cpus} CPUs) during the loops: " + "; ".join(parts)


#: a loop's worst stall within these fractions of the kernel's longest real-time stop (40-60 ms for the
#: default 50 ms) points at the kernel's throttling
THROTTLE_WINDOW = (0.8, 1.2)
#: [ms] per second the fair server of Linux 6.12 and later runs ordinary tasks on a CPU held by real-time threads
FAIR_SERVER_MS = 50.0


def rt_budget_lines(s: dict) -> list[str]:
    """The kernel's real-time budget under the loops (``pacer.rt_budget_ms``, ``pacer.rt_stop_ms``:
    :func:`teleop.timing.realtime.rt_budget`), then, per loop at ``SCHED_FIFO`` whose worst stall (its worst
    lateness or longest step) lies in :data:`THROTTLE_WINDOW` of the kernel's longest hold (the budget's
    stop when it is limited, else :data:`FAIR_SERVER_MS`), a note that the stall is likely the kernel
    making room for ordinary tasks; [] when no side reports a budget or neither runs at ``SCHED_FIFO`` (the budget
    holds back real-time threads only)."""
    sides = [(side, s.get(side, {}).get("pacer", {})) for side in ("master", "slave")]
    sides = [(side, pc) for side, pc in sides if "rt_budget_ms" in pc]
    if not any(str(pc.get("scheduling", "")).startswith("SCHED_FIFO") for _, pc in sides):
        return []
    pc0 = sides[0][1]
    if pc0["rt_budget_ms"] == "unlimited":
        stop = FAIR_SERVER_MS
        lines = ["kernel real-time budget: unlimited (sched_rt_runtime_us = -1)"]
    else:
        stop = float(pc0.get("rt_stop_ms", 0.0))
        lines = [f"kernel real-time budget: {float(pc0['rt_budget_ms']):.0f} ms of a CPU per second, then real-time "
                 f"threads stop for up to {stop:.0f} ms (sched_rt_runtime_us)"]
    for side, pc in sides:
        worst = max(1e3 * pc.get("max_lateness", 0.0), pc.get("step_ms", {}).get("max", 0.0))
        if (str(pc.get("scheduling", "")).startswith("SCHED_FIFO")
                and THROTTLE_WINDOW[0] * stop <= worst <= THROTTLE_WINDOW[1] * stop):
            lines.append(f"{side} stall of {worst:.1f} ms: likely the kernel holding the real-time threads back so "
                         "that ordinary tasks run (real-time throttling, or the fair server of kernels from 6.12), "
                         "not the loop's code; see docs/how-to/real-time.md")
    return lines


def verdict_lines(s: dict) -> list[str]:
    """``[PASS]``/``[FAIL]`` per check, then ``[FAIL]`` per problem."""
    lines = [f"[{'PASS' if ok else 'FAIL'}] {name}" for name, ok in s.get("checks", {}).items()]
    lines += [f"[FAIL] {p}" for p in s.get("problems", [])]
    return lines


def finish(summary: dict, checks: dict[str, bool], problems: list[str], t0: float, run_dir: Path,
           fmt: Callable[[dict], str]) -> int:
    """Complete ``summary`` (checks, problems, wall time since ``t0`` [s, monotonic], ok), write
    ``run_dir/summary.json``, print ``fmt(summary)`` and the wall time; 0 when ok, else 1."""
    summary["checks"] = checks
    summary["problems"] = problems
    summary["wall_time_s"] = time.monotonic() - t0
    summary["ok"] = not problems and all(summary["checks"].values())
    (run_dir / "summary.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    print(fmt(summary))
    print(f"wall time {summary['wall_time_s']:.1f} s")
    return 0 if summary["ok"] else 1


#: [s] once both sides have ended, the recorder gets at least this long to finish (even past ``--timeout``):
#: it runs niced and, on a loaded machine, writes the last messages, the journals' recovery and its
#: figure well after the sides (seen: 22 s after them with two CPU hogs and a load average of 7.7)
RECORDER_GRACE = 20.0


def _wait_listening(port: int, proc: subprocess.Popen, deadline: float) -> bool:
    from teleop.session.transport import accepts_connections
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            return False
        if accepts_connections(port):
            return True
        time.sleep(0.05)
    return False


def _stop(proc: subprocess.Popen) -> None:
    """SIGTERM (the child flushes its recordings), then SIGKILL after 5 s."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(5.0)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


@dataclasses.dataclass(frozen=True)
class RecorderRun:
    """One ``teleop record`` beside the sides (:func:`run_processes`).

    Attributes
    ----------
    name : str
        What the problems call it (``recorder``, ``recorder of left``).
    args : list of str
        Its arguments after ``record --listen <endpoint> --exit-when-done`` (``--config``, ``--run-dir``, ...).
    run_dir : Path
        Its run directory: ``recorder.log`` and ``recorder/`` go there.
    """

    name: str
    args: list[str]
    run_dir: Path


def _start_recorders(base: list[str], recorders: list[RecorderRun], env: dict, deadline: float,
                     procs: list, problems: list[str]) -> list[str] | None:
    """Start every recorder, each ready before the next; the ``--connect`` arguments to all of them, or None
    (into ``problems``) when one did not become ready before ``deadline`` [s, monotonic]."""
    from live.record.beside_demo import start_recorder
    links: list[str] = []
    for r in recorders:
        proc, link = start_recorder(base, r.args, r.run_dir, env, deadline)
        procs.append((r.name, proc, r.run_dir / "recorder.log"))
        if link is None:
            problems.append(f"the {r.name} did not start (see {r.run_dir}/recorder.log)")
            return None
        links += link
    return links


def _wait_all(procs: list, deadline: float, timeout: float, problems: list[str]) -> None:
    """Wait for the processes, the last started first (the bridge serves until stopped); one past ``deadline``
    [s, monotonic] (a recorder: past :data:`RECORDER_GRACE` after the sides, if later) is stopped; that and a
    non-zero exit into ``problems``."""
    for name, p, log in procs[::-1]:
        if name == "bridge":
            continue                 # serves until stopped below
        wait = deadline - time.monotonic()
        recorder = name.startswith("recorder")
        if recorder:                 # the sides are done; a niced recorder on a busy machine catches up
            wait = max(wait, RECORDER_GRACE)
        try:
            rc = p.wait(max(0.1, wait))
        except subprocess.TimeoutExpired:
            extra = f" and {RECORDER_GRACE:g} s after the sides" if recorder else ""
            problems.append(f"the {name} did not finish within --timeout {timeout:g} s{extra}; stopped")
            _stop(p)
            rc = p.returncode
        if rc != 0:
            problems.append(f"the {name} exited with code {rc} (see {log})")


def run_processes(args, cfg_file: Path, run_dir: Path, problems: list[str], *, bridge: bool = False,
                  doing: str | None = None, recorders: list[RecorderRun] | None = None,
                  sides: str = "slave and master", report: bool = True) -> None:
    """Slave and master as two processes with ``cfg_file`` (module docstring); what went wrong is
    appended to ``problems``. ``args``: ``listen``, ``timeout`` [s], ``protocol``. ``bridge``: the rig
    is ``rig.type: zenoh``, so ``teleop bridge`` runs the simulated rig as a third process on its own
    loopback port, which the slave connects to (stopped once slave and master are done). ``doing``: what
    the start-up line says the sides do (default: calibration, then the protocol); ``sides``: what it calls
    them. ``recorders``: the recorders started first, which the sides connect to (default: one with the
    sides' arguments in ``run_dir``); ``report``: print each one's summary line at the end."""
    from teleop.session.transport import free_tcp_port, loopback_endpoint
    if args.listen:
        ep = args.listen[0]
        port = int(ep.rsplit(":", 1)[1])
    else:
        port = free_tcp_port()
        ep = loopback_endpoint(port)
    timeout = float(args.timeout)
    base = [sys.executable, "-m", "live.cli"]
    common = ["--config", str(cfg_file), "--run-dir", str(run_dir), "--max-duration", f"{timeout:g}"]
    recorders = [RecorderRun("recorder", common, run_dir)] if recorders is None else recorders
    # the run's own credentials (teleop/session/credentials.py)
    keys = Path(tempfile.mkdtemp(prefix="tsm-teleop-demo-"))
    env = dict(os.environ, PYTHONUNBUFFERED="1", TSM_TELEOP_KEYS=str(keys / "keys"))
    deadline = time.monotonic() + timeout
    procs: list[tuple[str, subprocess.Popen, Path]] = []
    rig_link: list[str] = []
    with open(run_dir / "slave.log", "w") as slog, open(run_dir / "master.log", "w") as mlog, \
            open(run_dir / "bridge.log", "w") if bridge else contextlib.nullcontext() as blog:
        try:
            rec_link = _start_recorders(base, recorders, env, deadline, procs, problems)
            if rec_link is None:
                return
            if bridge:
                port_b = free_tcp_port()
                ep_b = loopback_endpoint(port_b)
                rig = subprocess.Popen(base + ["bridge", "--listen", ep_b, "--config", str(cfg_file), "--run-dir",
                                               str(run_dir), "--max-duration", f"{timeout:g}"],
                                       stdout=blog, stderr=subprocess.STDOUT, env=env)
                procs.append(("bridge", rig, run_dir / "bridge.log"))
                if not _wait_listening(port_b, rig, deadline):
                    problems.append(f"the bridge did not listen on {ep_b} (see {run_dir}/bridge.log)")
                    return
                rig_link = ["--connect", ep_b]
            # the sides' view, not the recorder's
            view = ["--rerun", args.rerun] if getattr(args, "rerun", None) else []
            slave = subprocess.Popen(base + ["slave", "--listen", ep, "--exit-on-master-stop"] + rig_link + rec_link
                                     + view + common,
                                     stdout=slog, stderr=subprocess.STDOUT, env=env)
            procs.append(("slave", slave, run_dir / "slave.log"))
            if not _wait_listening(port, slave, deadline):
                problems.append(f"the slave did not listen on {ep} (see {run_dir}/slave.log)")
                return
            master = subprocess.Popen(base + ["master", "--connect", ep, "--protocol", args.protocol] + rec_link + view
                                      + common,
                                      stdout=mlog, stderr=subprocess.STDOUT, env=env)
            procs.append(("master", master, run_dir / "master.log"))
            doing = doing or f"calibration, then protocol {args.protocol}"
            print(f"{sides} running on {ep} ({doing}) ...", flush=True)
            _wait_all(procs, deadline, timeout, problems)
            from live.record.beside_demo import summary_line
            for r in recorders if report else ():
                print(summary_line(r.run_dir / "recorder"), flush=True)
        finally:
            for _, p, _ in procs:
                _stop(p)
            shutil.rmtree(keys, ignore_errors=True)
