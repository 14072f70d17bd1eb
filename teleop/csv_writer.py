"""A measured-data CSV written off the control loop: the loop only queues rows, a thread writes them.

:class:`ThreadedCsvRecorder` is a :class:`teleop.recording.CsvRecorder` whose :meth:`write` appends
the row to a deque (well under a microsecond, no numpy, no formatting, no system call) and whose
writer thread converts, checks, formats and hands the rows to the OS every ``flush_interval``
seconds. A SIGKILL of the process loses at most that interval of rows (the ``teleop record``
process has every message anyway); every other exit (``close``, the ``with`` block, SIGTERM inside
:func:`teleop.recording.raise_on_sigterm`) writes every row. A row the base recorder refuses (wrong
length, a non-finite value) is skipped and counted in :attr:`ThreadedCsvRecorder.rejected` with a
warning: the loop never dies of its own recording. A write the OS refuses (``OSError``: disk full,
file too large) ends the writing with one error line; the rows handed to the OS before stay in the
file, and the later ones are dropped and counted in :attr:`ThreadedCsvRecorder.dropped`. The thread formats while the control loop sleeps
(:data:`teleop.realtime.IDLE`), in chunks of rows that each hold the interpreter lock about
:data:`CHUNK_COST` (formatting is one C call per chunk, and the loop cannot run Python during it:
the 3-joint slave's 20-row batch of 72 columns took 0.58 ms in one piece, longer than the loop's idle
time, and delayed the loop by as much).
"""
from __future__ import annotations

import collections
import logging
import threading

import numpy as np

from teleop.realtime import IDLE
from teleop.recording import CsvRecorder
from teleop.rerun_thread import lower_switch_interval

__all__ = ["ThreadedCsvRecorder", "VALUE_COST", "CHUNK_COST"]

log = logging.getLogger("teleop.recording")
VALUE_COST = 4e-7      # [s] converting and formatting one value, about (measured 0.4 us at %.9g)
CHUNK_COST = 1e-4      # [s] the rows formatted in one piece hold the interpreter about this long


class ThreadedCsvRecorder(CsvRecorder):
    """:class:`~teleop.recording.CsvRecorder` with the writing on a thread (module docstring).

    Parameters
    ----------
    *args, **kwargs
        As :class:`~teleop.recording.CsvRecorder` (path, columns, metadata, units, overwrite...).
    flush_interval : float
        Longest time a queued row waits before it is written and handed to the OS [s], > 0.

    Attributes
    ----------
    rejected : int
        Rows refused by the base recorder (logged, not raised).
    dropped : int
        Rows not written after the OS refused a write (:attr:`error`, logged once, not raised).
    error : str or None
        The OS error that ended the writing.
    """

    def __init__(self, *args, flush_interval: float = 0.02, **kwargs):
        if not flush_interval > 0:
            raise ValueError(f"flush_interval must be > 0 s, got {flush_interval!r}")
        super().__init__(*args, **kwargs)
        self.flush_interval = float(flush_interval)
        self.rejected = self.dropped = self._taken = self._handed = 0     # rows: refused, dropped, queued, to the OS
        self.error: str | None = None
        self._queue: collections.deque = collections.deque()
        self._stop = threading.Event()
        self._io = threading.Lock()
        self._drainer: int | None = None    # the thread inside _drain (holding _io), if any
        lower_switch_interval()             # the woken loop gets the interpreter back within 0.5 ms
        self._thread = threading.Thread(target=self._run, name=f"csv-writer:{self.path.name}", daemon=True)
        self._thread.start()

    def write(self, row) -> None:
        """Queue one row (values in the order of ``columns``, SI units); written by the thread."""
        if self._fh is None:
            raise ValueError(f"{self.path}: recorder is closed")
        self._queue.append(row)

    def write_many(self, rows) -> None:
        """Queue rows, array-like of shape (n_rows, n_columns)."""
        if self._fh is None:
            raise ValueError(f"{self.path}: recorder is closed")
        self._queue.extend(list(rows))

    def _drain(self) -> None:
        """Write the queued rows in order (one thread at a time: rows are taken under the lock)."""
        with self._io:
            self._drainer = threading.get_ident()
            try:
                rows = []
                q = self._queue
                while q:
                    rows.append(q.popleft())
                if not rows:
                    return
                if self.error is not None:
                    self.dropped += len(rows)
                    return
                self._taken += len(rows)
                per_row = VALUE_COST * len(self.columns)
                chunk = max(1, int(CHUNK_COST / per_row))
                try:
                    for i in range(0, len(rows), chunk):
                        part = rows[i:i + chunk]
                        IDLE.wait(per_row * len(part))     # format while the control loop sleeps (teleop/realtime.py)
                        self._write_part(part)
                    self._hand()
                except OSError as e:                   # every row taken and not handed to the OS
                    self.error = f"{type(e).__name__}: {e}"
                    self.dropped = self._taken - self._handed - self.rejected
                    self._pending, self._pending_rows = [], 0
                    log.error("%s is no longer written: %s (%d rows dropped so far)", self.path.name, e, self.dropped)
            finally:
                self._drainer = None

    def _hand(self) -> None:
        """The base recorder's flush, counting the rows it hands to the OS."""
        n = self._pending_rows
        CsvRecorder.flush(self)
        self._handed += n

    def _write_part(self, rows: list) -> None:
        try:
            CsvRecorder.write_many(self, np.asarray(rows, dtype=np.float64))
        except ValueError:                      # a bad row (or ragged rows): write the good ones one by one
            for r in rows:
                try:
                    CsvRecorder.write_many(self, np.asarray(r, dtype=np.float64).reshape(1, -1))
                except ValueError as e:
                    self.rejected += 1
                    if self.rejected <= 3:
                        log.warning("%s: row skipped: %s", self.path.name, e)

    def _run(self) -> None:
        while not self._stop.wait(self.flush_interval):
            self._drain()

    def flush(self) -> None:
        """Write every queued row now and hand it to the OS."""
        if self._fh is None:
            return
        if self._drainer == threading.get_ident():
            # the base recorder's own flush (every flush_every rows) in the middle of a drain: the rows
            # written so far go to the OS; draining again here would wait for the lock this thread holds
            self._hand()
            return
        self._drain()

    def close(self) -> None:
        """Stop the thread, write every queued row, close; safe to call more than once."""
        self._stop.set()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(10.0)
        if self._fh is not None:
            try:
                self._drain()
            finally:
                try:
                    CsvRecorder.close(self)
                except OSError as e:
                    self.error = self.error or f"{type(e).__name__}: {e}"
                    log.error("%s: closing: %s", self.path.name, e)
