"""A measured-data CSV written off the control loop: the loop only queues rows, a thread writes them.

:class:`ThreadedCsvRecorder` is a :class:`teleop.recording.CsvRecorder` whose :meth:`write` appends
the row to a deque (well under a microsecond, no numpy, no formatting, no system call) and whose
writer thread converts, checks, formats and hands the rows to the OS every ``flush_interval``
seconds. A SIGKILL of the process loses at most that interval of rows (the ``teleop record``
process has every message anyway); every other exit (``close``, the ``with`` block, SIGTERM inside
:func:`teleop.recording.raise_on_sigterm`) writes every row. A row the base recorder refuses (wrong
length, a non-finite value) is skipped and counted in :attr:`ThreadedCsvRecorder.rejected` with a
warning: the loop never dies of its own recording. The thread formats while the control loop sleeps
(:data:`teleop.realtime.IDLE`).
"""
from __future__ import annotations

import collections
import logging
import threading

import numpy as np

from teleop.realtime import IDLE
from teleop.recording import CsvRecorder
from teleop.rerun_thread import lower_switch_interval

__all__ = ["ThreadedCsvRecorder"]

log = logging.getLogger("teleop.recording")
ROW_COST = 3e-6        # [s] converting and formatting one row, about (a 20 ms batch: 60 us)


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
    """

    def __init__(self, *args, flush_interval: float = 0.02, **kwargs):
        if not flush_interval > 0:
            raise ValueError(f"flush_interval must be > 0 s, got {flush_interval!r}")
        super().__init__(*args, **kwargs)
        self.flush_interval = float(flush_interval)
        self.rejected = 0
        self._queue: collections.deque = collections.deque()
        self._stop = threading.Event()
        self._io = threading.Lock()
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
        rows = []
        q = self._queue
        while q:
            rows.append(q.popleft())
        if not rows:
            return
        IDLE.wait(min(ROW_COST * len(rows), 5e-4))     # format while the control loop sleeps (teleop/realtime.py)
        with self._io:
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
            CsvRecorder.flush(self)

    def _run(self) -> None:
        while not self._stop.wait(self.flush_interval):
            self._drain()

    def flush(self) -> None:
        """Write every queued row now and hand it to the OS."""
        if self._fh is not None:
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
                CsvRecorder.close(self)
