"""A side's per-cycle CSV written by a child process: the control loop queues rows, another interpreter formats them.

Formatting is the costly part of a CSV row: about 0.3-0.4 us a value, 25-41 us for a bimanual arm's 95 columns,
2 x 95 columns x 1 kHz on a bimanual slave. In a thread of the side's process it holds the interpreter lock
the control loop needs, and it runs at the helpers' real-time priority, so it also counts against the kernel's
real-time budget (docs/how-to/real-time.md). :class:`ProcessCsvRecorder` moves it out of the side's process:

* the recorder writes the file's metadata, units and header itself, so a bad setup or an existing file raises
  here (as :class:`~teleop.recording.measured.CsvRecorder`), before any process starts;
* :meth:`ProcessCsvRecorder.write` from the loop is a deque append (no numpy, no formatting, no system call);
* a sender thread (``csv-writer:<file>``, a helper of :mod:`teleop.timing.realtime`) pickles the queued rows every
  ``flush_interval`` seconds, during the loop's idle window, in chunks that each hold the interpreter about
  :data:`CHUNK_COST` (pickling costs :data:`VALUE_COST` a value, about 1.3 us for a 95-column row), and writes
  them to the stdin pipe of a child process (``python -m teleop.recording.csv_proc``);
* the child, with normal scheduling, on its own interpreter lock, checks and formats the rows exactly as
  :class:`~teleop.recording.measured.CsvRecorder` does and hands them to the OS after every batch it receives (so a
  row reaches the file within about ``flush_interval``; ``flush_every`` rows at most in one hand-over), on
  :meth:`~ProcessCsvRecorder.flush` and at the end. The constructor returns once the child has opened the
  file (about 0.15 s: an interpreter and numpy), so that its start-up is not the control loop's.

Nothing is lost on an exit path: :meth:`~ProcessCsvRecorder.close` (the ``with`` block, SIGTERM inside
:func:`teleop.recording.measured.raise_on_sigterm`) sends every queued row and waits for the child to close the file.
The child runs in a process group of its own, so Ctrl-C at the terminal reaches the side and not the child
(which also ignores SIGINT); the side closes it. When the side is killed
(SIGKILL), the child's stdin ends: it writes every row it received and closes the file, so at most
``flush_interval`` of rows (those not yet sent) are lost. The child holds an exclusive ``flock`` on the file
while it writes; a reader that wants the whole file after a side was killed waits for it with
:func:`wait_written`.

Counts, as the child reports them: a row the recorder refuses (wrong length, a non-finite value) is skipped and
counted in :attr:`~ProcessCsvRecorder.rejected` with a warning (the first three): the loop never dies of its
own recording. A write the OS refuses (``OSError``: disk full, file too large) ends the writing with one error
line (:attr:`~ProcessCsvRecorder.error`); the rows handed to the OS before stay in the file, the later ones are
counted in :attr:`~ProcessCsvRecorder.dropped`, as are the rows the child never received if it died.

Wire: parent -> child, pickles on stdin: ``(path, columns, flush_every)``, then lists of rows, ``"flush"``, and
None (close). Child -> parent, one JSON line per report on stdout: ``{"event", "written", "rejected", "dropped",
"error", "warning"}`` with ``event`` one of ``ready``, ``flushed``, ``warning``, ``error``, ``closed``.
"""
from __future__ import annotations

import collections
import fcntl
import json
import logging
import os
import pickle
import subprocess
import sys
import threading
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import IO, Any

import numpy as np

from teleop.recording.child_pipe import close_stdin, write_pickle
from teleop.recording.measured import CsvRecorder
from teleop.rerun.thread import lower_switch_interval
from teleop.timing.realtime import IDLE

__all__ = ["ProcessCsvRecorder", "wait_written", "VALUE_COST", "CHUNK_COST", "main"]

log = logging.getLogger("teleop.recording.measured")
VALUE_COST = 1.5e-8     # [s] pickling one value of a row, about (1.3 us for 95 columns)
CHUNK_COST = 1e-4       # [s] the rows pickled in one piece hold the interpreter about this long
MAX_WARNINGS = 3        # skipped rows said one by one; the rest only counted
READY_TIMEOUT = 30.0    # [s] longest wait in the constructor for the child to have opened the file


class ProcessCsvRecorder:
    """A per-cycle CSV whose rows a child process formats and writes (module docstring).

    Parameters
    ----------
    path, columns, metadata, units, flush_every, overwrite
        As :class:`~teleop.recording.measured.CsvRecorder`: the file (its parent directories are created), the column
        names, the ``# key: value`` lines, the units of non-standard columns, the most rows the child hands
        to the OS at once and whether an existing file is replaced.
    flush_interval : float
        Longest time a queued row waits before it is sent to the child, which writes it at once [s], > 0.

    Attributes
    ----------
    rows_written : int
        Rows the child has handed to the OS, as of its last report (final after :meth:`close`).
    rejected : int
        Rows refused (wrong length, a non-finite value): skipped and counted, not raised.
    error : str or None
        The OS error that ended the writing, or why the child is gone.

    Raises
    ------
    ValueError
        As :class:`~teleop.recording.measured.CsvRecorder` for a bad setup; ``flush_interval`` <= 0. :meth:`write` after
        :meth:`close`.
    FileExistsError
        ``path`` exists and ``overwrite`` is False.
    OSError
        The file cannot be created, or the child process cannot be started.
    """

    def __init__(self, path: str | Path, columns: Sequence[str], metadata: Mapping[str, str] | None = None, *,
                 units: Mapping[str, str] | None = None, flush_every: int = 100, overwrite: bool = False,
                 flush_interval: float = 0.02):
        if not flush_interval > 0:
            raise ValueError(f"flush_interval must be > 0 s, got {flush_interval!r}")
        head = CsvRecorder(path, columns, metadata, units=units, flush_every=flush_every, overwrite=overwrite)
        head.close()                                  # the header is on disk; the child appends the rows
        self.path, self.columns, self.flush_every = head.path, head.columns, head.flush_every
        self.flush_interval = float(flush_interval)
        self.rows_written = self.rejected = 0
        self.error: str | None = None
        self._child_dropped = self._lost = 0          # rows: dropped by the child, never received by it
        self._queue: collections.deque = collections.deque()
        self._open = True
        self._stop = threading.Event()
        self._io = threading.Lock()                   # one writer of the pipe at a time: sender, flush, close
        self._flushed = threading.Event()
        self._ready = threading.Event()
        lower_switch_interval()                       # the woken loop gets the interpreter back within 0.5 ms
        self._proc = subprocess.Popen([sys.executable, "-m", "teleop.recording.csv_proc"], stdin=subprocess.PIPE,
                                      stdout=subprocess.PIPE, close_fds=True, process_group=0)
        self._pipe_ok = write_pickle(self._proc, (str(self.path), self.columns, self.flush_every))
        name = self.path.name
        self._reader = threading.Thread(target=self._read, name=f"csv-writer-reader:{name}", daemon=True)
        self._reader.start()
        self._thread = threading.Thread(target=self._run, name=f"csv-writer:{name}", daemon=True)
        self._thread.start()
        self._ready.wait(READY_TIMEOUT)               # its start-up (an interpreter, numpy) before the loop's

    @property
    def closed(self) -> bool:
        return not self._open

    @property
    def dropped(self) -> int:
        """Rows not written: after the OS refused a write (:attr:`error`), or never received by a child gone."""
        return self._child_dropped + self._lost

    # ---- the loop's side: a deque append ------------------------------------------------------------------
    def write(self, row: Sequence[float]) -> None:
        """Queue one row (values in the order of ``columns``, SI units); sent to the child by the thread."""
        if not self._open:
            raise ValueError(f"{self.path}: recorder is closed")
        self._queue.append(row)

    def write_many(self, rows: Any) -> None:
        """Queue rows, array-like of shape (n_rows, n_columns)."""
        if not self._open:
            raise ValueError(f"{self.path}: recorder is closed")
        self._queue.extend(rows.tolist() if isinstance(rows, np.ndarray) else list(rows))

    # ---- the sender thread --------------------------------------------------------------------------------
    def _run(self) -> None:
        while not self._stop.wait(self.flush_interval):
            self._drain()

    def _drain(self) -> None:
        """Send the queued rows in order, in chunks pickled while the control loop sleeps
        (teleop/timing/realtime.py)."""
        q = self._queue
        per_row = VALUE_COST * len(self.columns)
        chunk = max(1, int(CHUNK_COST / per_row))
        with self._io:
            while q:
                n = min(len(q), chunk)
                IDLE.wait(per_row * n)
                part = [q.popleft() for _ in range(n)]
                self._send(part, len(part))

    def _send(self, msg: Any, rows: int = 0) -> bool:
        """Pickle ``msg`` onto the child's stdin (the caller holds ``_io``); once the child is gone, its rows
        are counted as lost (one error line)."""
        if self._pipe_ok:
            self._pipe_ok = write_pickle(self._proc, msg)
        if not self._pipe_ok:
            self._lost += rows
            if self.error is None:
                self.error = f"the CSV writing process of {self.path.name} has ended (exit code {self._proc.poll()})"
                log.error("%s is no longer written: %s", self.path.name, self.error)
        return self._pipe_ok

    def _read(self) -> None:
        """The child's reports (module docstring); the end of its stdout releases a waiting flush."""
        assert self._proc.stdout is not None
        for line in self._proc.stdout:
            try:
                r = json.loads(line)
                self.rows_written, self.rejected, self._child_dropped = r["written"], r["rejected"], r["dropped"]
            except (ValueError, KeyError, TypeError):
                continue
            if r.get("warning"):
                log.warning("%s: row skipped: %s", self.path.name, r["warning"])
            if r.get("error") and self.error is None:
                self.error = r["error"]
                log.error("%s is no longer written: %s (%d rows dropped so far)", self.path.name, r["error"],
                          self.dropped)
            if r.get("event") == "flushed":
                self._flushed.set()
            elif r.get("event") == "ready":
                self._ready.set()
        self._flushed.set()
        self._ready.set()

    # ---- end ----------------------------------------------------------------------------------------------
    def flush(self, timeout: float = 10.0) -> None:
        """Send every queued row and wait until the child has handed it to the OS (at most ``timeout`` [s])."""
        if not self._open:
            return
        self._drain()
        with self._io:
            self._flushed.clear()
            sent = self._send("flush")
        if sent:
            self._flushed.wait(timeout)

    def close(self, timeout: float = 30.0) -> None:
        """Send every queued row, then close: the child writes them, closes the file and exits (at most
        ``timeout`` [s], then it is killed). Safe to call more than once."""
        if not self._open:
            return
        self._open = False
        self._stop.set()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(timeout)
        self._drain()
        with self._io:
            self._send(None)
            close_stdin(self._proc)
        try:
            self._proc.wait(timeout)
        except subprocess.TimeoutExpired:
            log.warning("%s: the CSV writing process did not finish within %g s: killed", self.path.name, timeout)
            self._proc.kill()
            self._proc.wait()
        self._reader.join(timeout)

    def __enter__(self) -> ProcessCsvRecorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def wait_written(path: str | Path, timeout: float = 10.0) -> bool:
    """Wait until no writing process holds ``path`` (module docstring: a side killed leaves its child writing
    the rows it received, for milliseconds). Returns True once the file is free, False after ``timeout`` [s];
    raises ``OSError`` when ``path`` cannot be opened."""
    deadline = time.monotonic() + timeout
    with open(path, "rb") as fh:
        while True:
            try:
                fcntl.flock(fh.fileno(), fcntl.LOCK_SH | fcntl.LOCK_NB)
                return True
            except BlockingIOError:
                if time.monotonic() >= deadline:
                    return False
                time.sleep(0.005)


# ---- the child ----------------------------------------------------------------------------------------------
class _Counted(CsvRecorder):
    """The recorder of the child, counting the rows it hands to the OS."""

    handed = 0

    def flush(self) -> None:
        n = self._pending_rows
        CsvRecorder.flush(self)
        self.handed += n


class _Writer:
    """The child's writing: the rows checked and formatted by the recorder, the counts reported (module
    docstring)."""

    def __init__(self, path: str, columns: Sequence[str], flush_every: int, out: int):
        self.out, self.taken, self.rejected, self.dropped = out, 0, 0, 0
        self.error: str | None = None
        self.rec: _Counted | None = None
        try:
            self.rec = rec = _Counted.reopen(path, columns, flush_every=flush_every)
            assert rec._fh is not None
            fcntl.flock(rec._fh.fileno(), fcntl.LOCK_EX)          # released when the file is closed
        except OSError as e:
            self._fail(e)
        self.report("ready")

    def rows(self, rows: list) -> None:
        self.taken += len(rows)
        if self.rec is None or self.error is not None:
            self.dropped += len(rows)
            return
        try:
            self._write(self.rec, rows)
        except OSError as e:
            self._fail(e)

    def _write(self, rec: _Counted, rows: list) -> None:
        try:
            rec.write_many(np.asarray(rows, dtype=np.float64))
            return
        except (ValueError, TypeError):        # a bad row (or ragged rows): write the good ones one by one
            pass
        for r in rows:
            try:
                rec.write_many(np.asarray(r, dtype=np.float64).reshape(1, -1))
            except (ValueError, TypeError) as e:
                self.rejected += 1
                if self.rejected <= MAX_WARNINGS:
                    self.report("warning", warning=str(e))

    def _fail(self, e: OSError) -> None:
        self.error = f"{type(e).__name__}: {e}"
        if self.rec is not None:
            self.rec._pending, self.rec._pending_rows = [], 0
        self.dropped = self.taken - self.written - self.rejected
        self.report("error")

    @property
    def written(self) -> int:
        return 0 if self.rec is None else self.rec.handed

    def hand(self) -> None:
        """Hand the rows written so far to the OS."""
        if self.rec is not None and self.error is None:
            try:
                self.rec.flush()
            except OSError as e:
                self._fail(e)

    def flush(self) -> None:
        self.hand()
        self.report("flushed")

    def close(self) -> None:
        self.hand()
        if self.rec is not None:
            try:
                self.rec.close()
            except OSError as e:
                self.error = self.error or f"{type(e).__name__}: {e}"
        self.report("closed")

    def report(self, event: str, **extra: str) -> None:
        line = json.dumps({"event": event, "written": self.written, "rejected": self.rejected,
                           "dropped": self.dropped, "error": self.error, **extra}) + "\n"
        try:
            os.write(self.out, line.encode())      # unbuffered: nothing left to flush at exit if the side is gone
        except OSError:
            pass


def main() -> int:
    """The child: the file's path, columns and ``flush_every``, then batches of rows, from stdin until None or
    EOF (the side ended or was killed: every row received is written)."""
    import signal
    signal.signal(signal.SIGINT, signal.SIG_IGN)   # Ctrl-C is the side's to handle: the side closes us
    inp: IO[bytes] = sys.stdin.buffer
    try:
        path, columns, flush_every = pickle.load(inp)
    except EOFError:
        return 0
    w = _Writer(path, columns, flush_every, sys.stdout.fileno())
    try:
        while True:
            try:
                msg = pickle.load(inp)
            except EOFError:
                break
            if msg is None:
                break
            if msg == "flush":
                w.flush()
            else:
                w.rows(msg)
                w.hand()                      # each batch on disk: a row waits at most flush_interval
    finally:
        w.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
