"""Starting, waiting for and stopping `teleop` processes in the integration tests (one copy).

Deadlines only bound waits: every wait polls a condition and gives up with a message naming it.
"""
from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

from teleop.timing.realtime import co_located_priority

BARE_CONFIG = """\
instrument:
  id: {ident}
calibration:
  speed: 0.02
  dir: "{runs}-calibration"
recording:
  rerun: "off"
  dir: "{runs}"
  csv_every: 1
transport:
  listen: ["tcp/127.0.0.1:{port}"]
"""


def co_located(text: str) -> str:
    """A config's YAML ``text`` with the sides' real-time priorities that ``teleop demo`` gives them on this machine
    (:func:`teleop.timing.realtime.co_located_priority`): every integration test runs both sides, and most a recorder
    too, on it. Unchanged on a machine with the CPUs for ``SCHED_FIFO`` loops; else ``realtime_priority: 0`` in the
    ``master`` and ``slave`` sections (added where the text has none)."""
    if co_located_priority(1)[1] is None:
        return text
    for side in ("master", "slave"):
        head = re.compile(rf"^{side}:[ \t]*(#[^\n]*)?\n", re.M)
        if head.search(text):
            text = head.sub(f"{side}:\n  realtime_priority: 0\n", text, count=1)
        else:
            text = text.rstrip("\n") + f"\n{side}:\n  realtime_priority: 0\n"
    return text


def write_bare_config(path: Path, ident: str, runs: Path, port: int) -> Path:
    """A quiet config for sides started bare: instrument ``ident``, runs under ``runs``, listening on ``port``; the
    sides' priorities those of one shared machine (:func:`co_located`)."""
    path.write_text(co_located(BARE_CONFIG.format(ident=ident, runs=runs, port=port)), encoding="utf-8")
    return path


def start(args: list[str], log: Path, env: dict | None = None) -> subprocess.Popen:
    """``python -m live.cli *args`` with stdout and stderr in ``log`` (unbuffered; ``env`` added)."""
    with open(log, "w") as fh:
        return subprocess.Popen([sys.executable, "-m", "live.cli", *args], stdout=fh, stderr=subprocess.STDOUT,
                                env=dict(os.environ, PYTHONUNBUFFERED="1", **(env or {})))


def wait_for(predicate, timeout: float, what: str) -> None:
    """Poll ``predicate`` until true; AssertionError naming ``what`` after ``timeout`` [s]."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return
        time.sleep(0.02)
    raise AssertionError(f"gave up waiting {timeout:g} s for {what}")


def wait_text(path: Path, text: str, timeout: float) -> None:
    """Wait until the file ``path`` contains ``text``; the AssertionError shows the file's tail."""
    try:
        wait_for(lambda: path.is_file() and text in path.read_text(), timeout, f"{text!r} in {path.name}")
    except AssertionError as e:
        tail = path.read_text()[-2000:] if path.is_file() else "(no file)"
        raise AssertionError(f"{e}: {tail}") from None


def stop_all(procs) -> None:
    """SIGKILL every process still running and reap it."""
    for p in procs:
        if p.poll() is None:
            p.kill()
            p.wait()


def stalled_past_watchdog(stats: list[dict], watchdog_s: float = 0.050) -> bool:
    """Whether the shared virtual machine, not the loops, stopped a side for longer than the watchdog
    (``slave.watchdog_ms``, ``master.watchdog_ms``, 50 ms by default): some side's cycle started more than
    ``watchdog_s`` late (``pacer.max_lateness``) while the hypervisor took at least that much from the
    machine during its loop (``pacer.machine.steal_ms``). Only then may a run's watchdog go SAFE: the
    watchdog doing its job on a stall no process could prevent, which a test may not count as a fault."""
    late = max(s["pacer"]["max_lateness"] for s in stats)
    steal = max((s["pacer"].get("machine") or {}).get("steal_ms") or 0.0 for s in stats)
    return late > watchdog_s and 1e-3 * steal >= watchdog_s


def quiet_instrument(config: Path, tmp_path: Path, shipped_id: str, ident: str, name: str = "inst.yaml") -> Path:
    """A shipped instrument config under its own id ``ident`` (replacing ``shipped_id``), without Rerun recording,
    with its calibration files under ``tmp_path/calibration``; written to ``tmp_path/name``."""
    text = config.read_text().replace(f"id: {shipped_id}", f"id: {ident}").replace("rerun: save", "rerun: off")
    text = text.replace("\ncalibration:\n", f"\ncalibration:\n  dir: {tmp_path / 'calibration'}\n")
    path = tmp_path / name
    path.write_text(text)
    return path


def run_demo(cfg: Path, run_dir: Path) -> tuple[subprocess.CompletedProcess, dict]:
    """``teleop demo --config cfg`` as its own process; asserts no traceback, no problem, exit 0 and that the slave
    reloaded the calibration file; returns the finished process and the run's summary.json."""
    proc = subprocess.run([sys.executable, "-m", "live.cli", "demo", "--config", str(cfg), "--run-dir", str(run_dir),
                           "--timeout", "50"], capture_output=True, text=True, timeout=90)
    logs = proc.stderr + (run_dir / "slave.log").read_text() + (run_dir / "master.log").read_text()
    assert "Traceback" not in logs, logs[-3000:]
    summary = json.loads((run_dir / "summary.json").read_text())
    # the failed checks first: pytest truncates a long message, and a timing check failing under load
    # (docs/concepts/haptic-loop.md, the real-time-limit signature) must be told from the others
    failed = [k for k, ok in summary["checks"].items() if not ok]
    assert summary["problems"] == [] and proc.returncode == 0, (failed, summary["problems"], summary.get("haptic_loop"),
                                                                summary.get("joints"), logs[-6000:])
    assert "calibration loaded from" in (run_dir / "slave.log").read_text()       # the slave reloaded the file
    return proc, summary
