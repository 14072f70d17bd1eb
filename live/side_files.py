"""A side's own files on disk: the per-cycle CSV at ``recording.csv_every``, and the disk budget.

A side (``teleop slave``, ``teleop master``) writes two high-rate files: its per-cycle CSV (``slave.csv``,
``slave_joints.csv``, ``master.csv``) and its Rerun recording (``<side>.rrd``). :class:`SideFiles` puts a gate
in front of each (:meth:`SideFiles.csv`, :meth:`SideFiles.rerun`): the CSV gets one row every
``recording.csv_every`` cycles (every control cycle with 1: the 1 kHz record is ``messages.bin`` of
``teleop record``), and both stop once the run directory holds ``recording.max_bytes`` or its disk has less
than ``recording.min_free_bytes`` free (:class:`live.record.budget.DiskBudget`, looked at every
:data:`~live.record.budget.CHECK_INTERVAL` seconds by a helper thread, never by the control loop). Past
either limit the side says so once, counts the rows and Rerun calls it leaves out, and keeps the
low-rate files: its stats, its journal (a bounded ring) and its log; the control loop goes on as before
(a gate's call costs it one attribute test).

``TELEOP_LIVE_STATS=<s>`` (:data:`LIVE_ENV`) in the environment (a diagnostic for long runs, e.g.
``benchmarks/bench_soak.py``) also makes the thread write ``<side>_live.json`` every that many seconds: the loop's
cycles and overruns so far, the messages it sent, the round trip's histogram of a master (:meth:`SideFiles.live`),
replaced atomically.
"""
from __future__ import annotations

import json
import logging
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from live.record.budget import CHECK_INTERVAL, DiskBudget, live_interval, write_live

__all__ = ["SideFiles", "CsvGate", "RerunGate", "add_to_stats"]


class CsvGate:
    """``write(row)`` of a per-cycle CSV recorder: one row in ``every`` kept, none once ``files`` stopped.

    Parameters
    ----------
    rec : object with ``write(row)``
        The CSV recorder (:class:`teleop.recording.csv_proc.ProcessCsvRecorder`).
    every : int
        Rows offered per row written, >= 1 (``recording.csv_every``).
    files : SideFiles
    """

    def __init__(self, rec: Any, every: int, files: SideFiles):
        self.rec, self.every, self.files = rec, max(1, int(every)), files
        self.path = getattr(rec, "path", None)
        self.offered = self.written = self.not_written = 0

    def write(self, row) -> None:
        """Offer the row of this cycle (kept when the cycle count is a multiple of ``every``)."""
        k = self.offered
        self.offered = k + 1
        if k % self.every:
            return
        if self.files.stopped:
            self.not_written += 1
            return
        self.written += 1
        self.rec.write(row)


class RerunGate:
    """A Rerun logger whose ``log_*`` calls stop once ``files`` stopped (counted); the rest passes through."""

    def __init__(self, rr: Any, files: SideFiles):
        self._rr, self._files = rr, files
        self.not_logged = 0

    def __getattr__(self, name: str) -> Any:
        target = getattr(self._rr, name)
        if not name.startswith("log_"):
            return target

        def gated(*args: Any, **kwargs: Any) -> None:
            if self._files.stopped:
                self.not_logged += 1
                return
            target(*args, **kwargs)
        return gated


class SideFiles:
    """The gates of one side's high-rate files and the thread that watches the disk (module docstring).

    Parameters
    ----------
    run_dir : Path
        The run directory (its size counts against ``recording.max_bytes``).
    cfg : Config
        ``recording.csv_every``, ``max_bytes``, ``min_free_bytes``.
    side : str
        ``slave`` or ``master`` (names the files in the warning).
    names : sequence of str
        The side's high-rate files, for the warning (e.g. ``("slave.csv", "slave.rrd")``).
    watch : bool
        Start the helper thread (False: call :meth:`check` yourself, as the tests do).
    """

    def __init__(self, run_dir: Path, cfg: Any, side: str, names=(), *, watch: bool = True):
        self.side, self.dir = side, Path(run_dir)
        what = ", ".join(names) or "its high-rate files"
        self.budget = DiskBudget(self.dir, cfg.recording.max_bytes, cfg.recording.min_free_bytes,
                                 stops=f"{side}: {{reason}}: {what} no longer written (rows counted); its control "
                                       f"loop, journal and stats go on")
        self.every = cfg.recording.csv_every
        self.stopped = False
        self.gates: dict[str, Any] = {}
        self.live_source: Callable[[], dict] | None = None
        self.live_every = live_interval()       # TELEOP_LIVE_STATS [s]; 0: no live file
        self._stop = threading.Event()
        self._thread = None
        if watch:
            self._thread = threading.Thread(target=self._watch, name="side-files", daemon=True)
            self._thread.start()

    def csv(self, rec: Any) -> CsvGate:
        """The gate of the per-cycle CSV recorder ``rec`` (a side of several arms has one per arm)."""
        gate = CsvGate(rec, self.every, self)
        self.gates.setdefault("csv", []).append(gate)
        return gate

    def rerun(self, rr: Any) -> RerunGate:
        """The gate of the Rerun logger ``rr``."""
        gate = RerunGate(rr, self)
        self.gates.setdefault("rerun", []).append(gate)
        return gate

    def check(self, now: float) -> bool:
        """Look at the disk (when :data:`CHECK_INTERVAL` has passed since the last look, ``now`` [s]); True
        the first time a limit is passed: the gates stop from then on (logged once)."""
        if self.budget.check(now, now, measure=False):
            self.stopped = True
            return True
        return False

    def _watch(self) -> None:
        next_live = time.monotonic()
        while not self._stop.wait(min(CHECK_INTERVAL, self.live_every or CHECK_INTERVAL)):
            now = time.monotonic()
            try:
                self.check(now)
                if self.live_every > 0 and self.live_source is not None and now >= next_live:
                    next_live = now + self.live_every
                    self.live()
            except Exception as e:  # noqa: BLE001 - the watcher must never take the side down
                logging.getLogger(f"teleop.{self.side}").warning("%s: disk watch: %r", self.side, e)

    def live(self) -> Path:
        """Write ``<side>_live.json`` (``live_source()`` and the time [s, monotonic]) by an atomic replace."""
        path = self.dir / f"{self.side}_live.json"
        write_live(path, {**(self.live_source() if self.live_source else {}), "disk": self.summary()})
        return path

    def summary(self) -> dict:
        """``{"csv_every", "stopped", "reached", "run_bytes", "csv_rows_written", "csv_rows_not_written",
        "rerun_calls_not_logged"}`` for the side's stats."""
        csv, rr = self.gates.get("csv", []), self.gates.get("rerun", [])
        return {"csv_every": self.every, "stopped": self.stopped, "reached": self.budget.reached,
                "run_bytes": self.budget.run_bytes,
                "csv_rows_written": sum(g.written for g in csv),
                "csv_rows_not_written": sum(g.not_written for g in csv),
                "rerun_calls_not_logged": sum(g.not_logged for g in rr)}

    def close(self) -> None:
        """Stop the helper thread. Idempotent."""
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(2.0)


def add_to_stats(path: Path, key: str, value: Any) -> None:
    """Add ``key: value`` to the JSON stats file at ``path`` (created when missing or unreadable)."""
    try:
        stats = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        stats = {}
    stats[key] = value
    path.write_text(json.dumps(stats, indent=2) + "\n", encoding="utf-8")
