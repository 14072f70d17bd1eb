"""Measured-data files: one tendon per CSV (docs/reference/formats.md, "Measured-data CSV").

The format and its reader are in :mod:`teleop.recording.measured_csv`
(:func:`~teleop.recording.measured_csv.read_measured_csv`).

Writing goes through :class:`CsvRecorder`, which streams rows and is closed and flushed on every
exit path of its ``with`` block; wrap it in :func:`raise_on_sigterm` so that SIGTERM unwinds the
block too (``with raise_on_sigterm(), CsvRecorder(...) as rec:``).
"""
from __future__ import annotations

import signal
import threading
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Self

import numpy as np

from estimator.data import MeasuredData
from teleop.recording.measured_csv import (
    COLUMN_NAME,
    META_LINE,
    SI_UNITS,
    parse_units,
)

__all__ = [
    "write_measured_csv", "CsvRecorder", "Terminated", "raise_on_sigterm", "StopAtCycleEnd", "stop_at_cycle_end",
]


class CsvRecorder:
    """Streaming writer of the measured-data CSV format (metadata, ``# units:``, header, rows).

    Rows are kept in memory and handed to the OS as whole lines every ``flush_every`` rows, on
    :meth:`flush` and on :meth:`close`, so the file on disk always ends at a row boundary and is
    readable while recording or after a crash (up to the last flush). As a context manager it is
    closed on every exit path: normal exit, exception, ``KeyboardInterrupt``, and SIGTERM when the
    block runs inside :func:`raise_on_sigterm`.

    Parameters
    ----------
    path : str or Path
        File to create (parent directories are created).
    columns : sequence of str
        Column names, e.g. ``("time", "x_in", "T_in", "T_out")``; unique, no commas or spaces.
    metadata : mapping of str -> str, optional
        Written as ``# key: value`` lines; the key ``units`` is reserved.
    units : mapping of str -> str, optional
        Units of non-standard columns (standard ones are always SI, see :data:`SI_UNITS`).
    flush_every : int
        Rows between flushes to the OS, >= 1.
    overwrite : bool
        Replace an existing file; by default an existing file raises ``FileExistsError``.

    Raises
    ------
    ValueError
        Bad column names, metadata, units or ``flush_every``; in :meth:`write`/:meth:`write_many`,
        a wrong row length or a non-finite value, or the recorder is closed.
    """

    _fh: IO[str] | None

    def __init__(self, path: str | Path, columns: Sequence[str],
                 metadata: Mapping[str, str] | None = None, *,
                 units: Mapping[str, str] | None = None, flush_every: int = 100,
                 overwrite: bool = False) -> None:
        self.path, self.columns = Path(path), tuple(columns)
        metadata = {str(k): str(v) for k, v in (metadata or {}).items()}
        bad = [c for c in self.columns if not COLUMN_NAME.match(c)]
        bad += [f"{k}: {v}" for k, v in metadata.items()
                if k == "units" or not META_LINE.match(f"# {k}: {v}") or "\n" in v or "\r" in v]
        bad += [f"{c}={u}" for c, u in (units or {}).items() if SI_UNITS.get(c, u) != u]
        unique = len(set(self.columns)) == len(self.columns)
        if bad or not self.columns or not unique or flush_every < 1:
            raise ValueError(f"{self.path}: bad recorder setup: columns {self.columns}, "
                             f"flush_every {flush_every}, rejected {bad} (key 'units' is reserved, "
                             f"standard columns are SI)")
        all_units = {c: SI_UNITS[c] for c in self.columns if c in SI_UNITS}
        all_units.update({c: u for c, u in (units or {}).items() if c in self.columns})
        self._start(flush_every)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        fh = open(self.path, "w" if overwrite else "x", encoding="utf-8")
        self._fh = fh
        head = [f"# {k}: {v}" for k, v in metadata.items()]
        if all_units:
            head.append("# units: " + ", ".join(f"{c}={u}" for c, u in all_units.items()))
        fh.write("\n".join(head + [",".join(self.columns)]) + "\n")
        fh.flush()

    def _start(self, flush_every: int) -> None:
        self.flush_every, self.rows_written = int(flush_every), 0
        self._line = ",".join("%.12g" if c == "time" else "%.9g" for c in self.columns) + "\n"
        self._pending: list[str] = []  # formatted whole lines not yet handed to the OS
        self._pending_rows = 0
        self._fh = None

    @classmethod
    def reopen(cls, path: str | Path, columns: Sequence[str], *, flush_every: int = 100) -> Self:
        """Go on writing rows at the end of ``path``, a recording whose header a recorder with the same
        ``columns`` wrote (:class:`teleop.recording.csv_proc.ProcessCsvRecorder`'s writing process). Raises ``OSError``
        when the file cannot be opened for appending."""
        self = cls.__new__(cls)
        self.path, self.columns = Path(path), tuple(columns)
        self._start(flush_every)
        self._fh = open(self.path, "a", encoding="utf-8")
        return self

    @property
    def closed(self) -> bool:
        return self._fh is None

    def write(self, row: Sequence[float]) -> None:
        """Append one row, values in the order of ``columns`` (SI units)."""
        self.write_many(np.asarray(row, dtype=np.float64).reshape(1, -1))

    def write_many(self, rows: np.ndarray) -> None:
        """Append rows, array-like of shape (n_rows, n_columns) in SI units."""
        if self._fh is None:
            raise ValueError(f"{self.path}: recorder is closed")
        arr = np.asarray(rows, dtype=np.float64)
        if arr.ndim != 2 or arr.shape[1] != len(self.columns):
            raise ValueError(f"{self.path}: rows have shape {arr.shape}, expected "
                             f"(n, {len(self.columns)}) for {', '.join(self.columns)}")
        bad = ~np.isfinite(arr)
        if bad.any():
            r, c = np.argwhere(bad)[0]
            raise ValueError(f"{self.path}: row {r}, column '{self.columns[c]}': non-finite "
                             f"value {float(arr[r, c])!r}")
        for i in range(0, arr.shape[0], 4096):  # one C-level % per block, ~2x np.savetxt
            block = arr[i:i + 4096]
            self._pending.append((self._line * block.shape[0]) % tuple(block.ravel().tolist()))
        self.rows_written += arr.shape[0]
        self._pending_rows += arr.shape[0]
        if self._pending_rows >= self.flush_every:
            self.flush()

    def flush(self) -> None:
        """Hand every written row to the OS as whole lines (no-op when closed)."""
        if self._fh is not None:
            text, self._pending, self._pending_rows = "".join(self._pending), [], 0
            self._fh.write(text)
            self._fh.flush()

    def close(self) -> None:
        """Flush and close; safe to call more than once."""
        try:
            self.flush()
        finally:
            fh, self._fh = self._fh, None
            if fh is not None:
                fh.close()

    def __enter__(self) -> CsvRecorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def write_measured_csv(path: str | Path, data: MeasuredData, *, overwrite: bool = False) -> None:
    """Write ``data`` in the measured-data format (its metadata and ``# units:`` included)."""
    metadata = {k: v for k, v in data.metadata.items() if k != "units"}
    units = parse_units(data.metadata.get("units", ""), f"{data.source}: metadata")
    cols = data.columns()
    with CsvRecorder(path, list(cols), metadata, units={k: u for k, u in units.items()
                                                        if k in cols and k not in SI_UNITS},
                     flush_every=1 << 30, overwrite=overwrite) as rec:
        rec.write_many(np.column_stack(list(cols.values())))


class Terminated(KeyboardInterrupt):
    """Raised in the main thread by :func:`raise_on_sigterm` when SIGTERM arrives."""


def _terminated(signum: int) -> Terminated:
    return Terminated(f"signal {signum} (SIGTERM)")


@contextmanager
def raise_on_sigterm() -> Iterator[None]:
    """Within the block, SIGTERM raises :class:`Terminated` (a ``KeyboardInterrupt``), so ``with``
    blocks unwind (files flushed, closed) when stopped by a process manager. Restores the previous
    handler on exit.

    Raises
    ------
    RuntimeError
        If called outside the main thread (Python delivers signals to the main thread only).
    """
    if threading.current_thread() is not threading.main_thread():
        raise RuntimeError("raise_on_sigterm() must be used in the main thread")

    def _handler(signum: int, frame: object) -> None:
        raise _terminated(signum)

    previous = signal.signal(signal.SIGTERM, _handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


class StopAtCycleEnd:
    """The stop request held by :func:`stop_at_cycle_end`: ``pending`` is the exception the first
    SIGINT (``KeyboardInterrupt``) or SIGTERM (:class:`Terminated`) would have raised, or None."""

    def __init__(self) -> None:
        self.pending: KeyboardInterrupt | None = None

    def reraise(self) -> None:
        """Raise the held exception, if any (after the loop has ended and cleaned up)."""
        if self.pending is not None:
            raise self.pending


@contextmanager
def stop_at_cycle_end() -> Iterator[StopAtCycleEnd]:
    """Within the block, the first Ctrl-C (SIGINT) or SIGTERM does not raise where the main thread happens
    to be but is held in the yielded :class:`StopAtCycleEnd`, for a real-time loop to check once per cycle
    and end between two steps; the handlers in force before the block are put back at once, so a second
    signal acts as usual (raises at once: the way out of a loop stuck inside one step).

    Why: an exception raised in the middle of a step can tear it (a command half applied), and one raised
    while compiled code calls back into Python (numba's run-time helpers) comes out as a ``SystemError``
    with a traceback instead of a clean Ctrl-C exit. Outside the main thread (where Python delivers no
    signals) the block holds nothing and changes nothing. Raises nothing itself; call
    :meth:`StopAtCycleEnd.reraise` after the loop's clean-up.
    """
    stop = StopAtCycleEnd()
    if threading.current_thread() is not threading.main_thread():
        yield stop
        return
    previous = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}

    def _restore() -> None:
        for sig, handler in previous.items():
            signal.signal(sig, handler)

    def _hold(signum: int, frame: object) -> None:
        if stop.pending is None:
            stop.pending = _terminated(signum) if signum == signal.SIGTERM else KeyboardInterrupt()
        _restore()

    for sig in previous:
        signal.signal(sig, _hold)
    try:
        yield stop
    finally:
        _restore()
