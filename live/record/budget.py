"""The recorder's disk use: which streams are high-rate, the byte budget, and writes that fail.

A session at the default rates writes about 0.2 MB/s in all (docs/reference/formats.md, "Disk use"):
most of it is the 1 kHz streams (the slave's estimate, the master's command). The recorder keeps every
message of them in the zstd-compressed ``messages.bin`` and every ``recording.mcap_every``-th in
``session.mcap``; their per-stream CSVs are written only with ``recording.csv: all``. The sides' journals
(``<side>.journal-NNN``) are a ring of at most two 8 MB segments each: they count on the disk, not in the
session's rate. Two limits bound a run:

* ``recording.max_bytes`` [B]: the bytes of every file in the run directory (sides and recorder);
* ``recording.min_free_bytes`` [B]: the free space of the disk that holds it.

:class:`DiskBudget` looks at both every :data:`CHECK_INTERVAL` seconds on the recorder's writer thread.
Past either, the recorder stops writing the high-rate streams (every file), keeps the low-rate ones
(heartbeats at most :data:`LOW_RATE_HZ` per stream and at every state change, state changes,
liveliness) and still counts every message it receives; the control loops never wait on it (they
only put messages on zenoh). :class:`Writes` runs each file write and counts, per file, what an
``OSError`` (disk full ``ENOSPC``, file too large ``EFBIG``, unwritable directory) kept out: the
first error of a file ends the writes to that file, and what was handed to the OS before stays
readable.
"""
from __future__ import annotations

import json
import logging
import os
import re
import shutil
import time
from collections.abc import Callable
from pathlib import Path

__all__ = ["CHECK_INTERVAL", "LOW_RATE_HZ", "DiskBudget", "Writes", "is_low_rate", "dir_bytes"]

log = logging.getLogger("live.record.recorder")
CHECK_INTERVAL = 1.0    # [s] the run directory's size and the disk's free space are read this often
LOW_RATE_HZ = 1.0       # [Hz] a heartbeat stream's rate in the recording once the budget is reached
RATE_AFTER = 10.0       # [s] the bytes per second of the session are measured over its first this long
LIVE_ENV = "TELEOP_LIVE_STATS"   # environment: seconds between two writes of a process's live figures
JOURNAL = ".journal"    # owner suffix of the sides' journal segments (a bounded ring, not in the rate)
_LOW_RATE = ("heartbeat",)


def is_low_rate(key: str) -> bool:
    """Whether the stream on ``key`` is a low-rate one (heartbeats: 50 Hz, kept past the budget)."""
    return key.rsplit("/", 1)[-1] in _LOW_RATE


def live_interval() -> float:
    """[s] ``TELEOP_LIVE_STATS`` of the environment: how often a process writes its live figures; 0: never."""
    try:
        return max(0.0, float(os.environ.get(LIVE_ENV, "0") or 0))
    except ValueError:
        return 0.0


def write_live(path: Path, figures: dict) -> None:
    """``figures`` and the time [s, monotonic] as JSON at ``path``, replaced whole (a reader never sees half)."""
    tmp = Path(str(path) + ".tmp")
    tmp.write_text(json.dumps({"t": time.monotonic(), **figures}) + "\n", encoding="utf-8")
    os.replace(tmp, path)


def dir_bytes(path: Path) -> dict[str, int]:
    """Bytes of the regular files under ``path`` per owner [B]: the top-level folder's name (``recorder``),
    or a top-level file's name up to its first ``.``, ``_`` or ``-`` (``slave.csv``, ``slave_stats.json`` ->
    ``slave``); a side's journal segments its name and :data:`JOURNAL` (``slave.journal-000`` ->
    ``slave.journal``). Recursive; files that vanish meanwhile are skipped."""
    total: dict[str, int] = {}
    stack = [(Path(path), "")]
    while stack:
        folder, owner = stack.pop()
        try:
            entries = list(os.scandir(folder))
        except OSError:
            continue
        for e in entries:
            try:
                if e.is_dir(follow_symlinks=False):
                    stack.append((Path(e.path), owner or e.name))
                elif e.is_file(follow_symlinks=False):
                    who = owner or re.split(r"[._-]", e.name, maxsplit=1)[0]
                    if not owner and f"{JOURNAL}-" in e.name:
                        who += JOURNAL
                    total[who] = total.get(who, 0) + e.stat(follow_symlinks=False).st_size
            except OSError:
                pass
    return total


class DiskBudget:
    """``recording.max_bytes`` and ``recording.min_free_bytes`` of one run directory.

    Parameters
    ----------
    run_dir : Path
        The run directory (its files count against ``max_bytes``; its disk's free space against the floor).
    max_bytes : float or None
        Bytes of the run directory past which the high-rate streams stop [B]; None: no limit.
    min_free_bytes : float or None
        Free space of the disk below which the high-rate streams stop [B]; None: no floor.
    stops : str
        The one warning past a limit, ``{reason}`` standing for the limit passed (default: the recorder's).
    own : str
        The owner (:func:`dir_bytes`) of the files written by the process that measures, e.g. ``recorder``:
        its rate is taken over the time its messages span (``t_data`` of :meth:`check`), so a recorder
        catching up a backlog does not count its catching up as the session's rate.
    """

    def __init__(self, run_dir: Path, max_bytes: float | None, min_free_bytes: float | None, stops: str | None = None,
                 own: str | None = None):
        self.dir, self.own = Path(run_dir), own
        self.stops = stops or (f"recorder: {{reason}}: the high-rate streams are no longer written (counted only); "
                               f"heartbeats at {LOW_RATE_HZ:g} Hz, state changes and liveliness still are")
        self.max_bytes, self.min_free_bytes = max_bytes, min_free_bytes
        self.run_bytes = 0
        self.free_bytes: int | None = None
        self.reached: dict | None = None        # {"reason", "time", "run_bytes", "free_bytes"} once past a limit
        self._next = -float("inf")
        self._first: tuple[float, dict[str, int], float | None] | None = None
        self.rates: dict[str, float] | None = None  # owner -> bytes per second, measured once [B/s]
        # TELEOP_LIVE_STATS=<s> (live/side_files.py): (file, figures()) written every that many seconds
        self.live: tuple[Path, Callable[[], dict]] | None = None
        self._live_every = live_interval()
        self._next_live = 0.0

    def check(self, now: float, t: float, measure: bool = True, t_data: float | None = None) -> bool:
        """Measure when :data:`CHECK_INTERVAL` has passed since the last look (``now`` [s, monotonic]);
        True the first time a limit is passed (logged once, kept in :attr:`reached` with the recorder's
        time ``t`` [s]). ``measure``: the session has started (its rate is measured from then on);
        ``t_data``: the receive time of the last message written [s] (the rate of :attr:`own`'s files)."""
        if self.reached is not None or now < self._next:
            return False
        self._next = now + CHECK_INTERVAL
        if self.live is not None and self._live_every > 0 and now >= self._next_live:
            self._next_live = now + self._live_every
            write_live(self.live[0], {**self.live[1](), "run_bytes": self.run_bytes})
        owners = dir_bytes(self.dir)
        self.run_bytes = sum(owners.values())
        if measure:
            self._measure(now, owners, t_data)
        try:
            self.free_bytes = shutil.disk_usage(self.dir).free
        except OSError:
            self.free_bytes = None
        reason = None
        if self.max_bytes is not None and self.run_bytes >= self.max_bytes:
            reason = f"run directory {self.run_bytes / 1e6:.1f} MB >= recording.max_bytes {self.max_bytes / 1e6:.1f} MB"
        elif (self.min_free_bytes is not None and self.free_bytes is not None
              and self.free_bytes < self.min_free_bytes):
            reason = (f"free space {self.free_bytes / 1e6:.1f} MB < recording.min_free_bytes "
                      f"{self.min_free_bytes / 1e6:.1f} MB")
        if reason is None:
            return False
        self.reached = {"reason": reason, "time": t, "run_bytes": self.run_bytes, "free_bytes": self.free_bytes}
        log.warning("%s", self.stops.replace("{reason}", reason))
        return True

    def _measure(self, now: float, owners: dict[str, int], t_data: float | None = None) -> None:
        """Once :data:`RATE_AFTER` seconds of the session have passed: print its bytes per second, per owner
        (the journals' bounded ring left out)."""
        if self._first is None:
            self._first = (now, owners, t_data)
            return
        t0, first, d0 = self._first
        if self.rates is not None or now - t0 < RATE_AFTER:
            return
        span = {k: now - t0 for k in owners}
        if self.own is not None and t_data is not None and d0 is not None and t_data > d0:
            span[self.own] = t_data - d0             # its messages' time: a backlog written now is not the rate
        self.rates = {k: (owners.get(k, 0) - first.get(k, 0)) / span[k] for k in sorted(owners)
                      if not k.endswith(JOURNAL)}
        total = sum(self.rates.values())
        parts = ", ".join(f"{k} {v / 1e3:.0f} kB/s" for k, v in self.rates.items() if v >= 500)
        until = ("" if self.max_bytes is None or total <= 0 else
                 f"; recording.max_bytes {self.max_bytes / 1e9:.3g} GB reached in about "
                 f"{max(0.0, self.max_bytes - self.run_bytes) / total / 60:.0f} min")
        print(f"teleop record: the session writes {total / 1e3:.0f} kB/s ({parts}), {total * 3600 / 1e9:.2f} GB "
              f"per hour (journals: a ring of at most 16 MB per side){until}", flush=True)

    def summary(self) -> dict:
        """``{"max_bytes", "min_free_bytes", "run_bytes", "free_bytes", "bytes_per_second", "reached"}`` (bytes
        [B], rates [B/s] per owner, measured over the first :data:`RATE_AFTER` seconds)."""
        return {"max_bytes": self.max_bytes, "min_free_bytes": self.min_free_bytes, "run_bytes": self.run_bytes,
                "free_bytes": self.free_bytes, "bytes_per_second": self.rates, "reached": self.reached}


class Writes:
    """Runs the recorder's file writes; counts, per file, the writes an ``OSError`` kept out, and per stream the
    messages that are not in the lossless record (``record``, ``messages.bin``).

    After the first error of a file its later writes are not tried (counted): a file whose buffer
    could not be handed to the OS is cut there, and what it held before stays readable. A message handed to
    the record is written once a flush (or the close) of the record succeeds after it; the record's first error
    cuts the ones handed to it since its last flush, which count as not written with those refused after it.
    """

    def __init__(self, record: str = "messages.bin") -> None:
        self.record = record
        self.failed: dict[str, str] = {}       # file name -> its first error
        self.not_written: dict[str, int] = {}  # file name -> writes not done
        self.skipped: dict[str, int] = {}      # stream key -> messages not written past the budget
        self.lost: dict[str, int] = {}         # stream key -> messages a write error kept out of the record
        self._pending: dict[str, int] = {}     # stream key -> messages handed to the record since its last flush

    def __call__(self, name: str, fn: Callable, *args) -> bool:
        """``fn(*args)`` for the file ``name``; False (counted) when it failed now or before."""
        if name in self.failed:
            self.not_written[name] = self.not_written.get(name, 0) + 1
            return False
        try:
            fn(*args)
            return True
        except OSError as e:
            self.failed[name] = f"{type(e).__name__}: {e}"
            self.not_written[name] = self.not_written.get(name, 0) + 1
            self._cut(name)
            log.error("recorder: %s is no longer written: %s (what it holds stays readable)", name, e)
            return False

    def message(self, key: str, fn: Callable, *args) -> bool:
        """Hand one message on the stream ``key`` to the record with ``fn(*args)``; False (counted as not
        written on ``key``) when the record failed now or before."""
        if self(self.record, fn, *args):
            self._pending[key] = self._pending.get(key, 0) + 1
            return True
        self.lost[key] = self.lost.get(key, 0) + 1
        return False

    def flush_record(self, fn: Callable) -> bool:
        """Flush the record with ``fn()``: the messages handed to it since its last flush are written once it
        succeeds. False when it failed now or before."""
        if self(self.record, fn):
            self._pending.clear()
            return True
        return False

    def _cut(self, name: str) -> None:
        """The record's first error: the messages handed to it since its last flush are not written."""
        if name == self.record:
            for key, n in self._pending.items():
                self.lost[key] = self.lost.get(key, 0) + n
            self._pending.clear()

    def close(self, name: str, fn: Callable) -> None:
        """Close the file ``name`` with ``fn()``, also after an error of it (what its buffer holds is
        handed to the OS where the OS takes it); an ``OSError`` is counted, not raised."""
        try:
            fn()
        except OSError as e:
            self.failed.setdefault(name, f"{type(e).__name__}: {e}")
            self.not_written[name] = self.not_written.get(name, 0) + 1
            self._cut(name)
        else:
            if name == self.record and name not in self.failed:
                self._pending.clear()           # the close handed the last block to the OS

    def skip(self, key: str) -> None:
        """One message on ``key`` not written because the budget is reached."""
        self.skipped[key] = self.skipped.get(key, 0) + 1

    def messages_not_written(self, key: str) -> int:
        """Messages of the stream ``key`` not in the record: kept out by a write error (or cut by one, see the
        class docstring) and left out past the disk budget. The one count of them, for ``summary.json``'s
        streams and the recorder's last line."""
        return self.lost.get(key, 0) + self.skipped.get(key, 0)

    def summary(self) -> dict:
        """``{"write_errors": {file: error}, "not_written": {file: n}, "over_budget_not_written": {key: n}}``."""
        return {"write_errors": dict(sorted(self.failed.items())),
                "not_written": dict(sorted(self.not_written.items())),
                "over_budget_not_written": dict(sorted(self.skipped.items()))}
