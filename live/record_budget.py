"""The recorder's disk use: which streams are high-rate, the byte budget, and writes that fail.

A session at the default rates writes about 1 MB/s in all (docs/reference/formats.md, "Disk use"):
most of it is the 1 kHz streams (the slave's estimate, the master's command). The recorder keeps them in
``messages.bin`` and the zstd-compressed ``session.mcap``; their per-stream CSVs are written only with
``recording.csv: all``. Two limits bound a run:

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

import logging
import os
import re
import shutil
from pathlib import Path
from typing import Callable

__all__ = ["CHECK_INTERVAL", "LOW_RATE_HZ", "DiskBudget", "Writes", "is_low_rate", "dir_bytes"]

log = logging.getLogger("live.record")
CHECK_INTERVAL = 1.0    # [s] the run directory's size and the disk's free space are read this often
LOW_RATE_HZ = 1.0       # [Hz] a heartbeat stream's rate in the recording once the budget is reached
RATE_AFTER = 3.0        # [s] the bytes per second of the session are measured over its first this long
_LOW_RATE = ("heartbeat",)


def is_low_rate(key: str) -> bool:
    """Whether the stream on ``key`` is a low-rate one (heartbeats: 50 Hz, kept past the budget)."""
    return key.rsplit("/", 1)[-1] in _LOW_RATE


def dir_bytes(path: Path) -> dict[str, int]:
    """Bytes of the regular files under ``path`` per owner [B]: the top-level folder's name (``recorder``),
    or a top-level file's name up to its first ``.``, ``_`` or ``-`` (``slave.csv``, ``slave.journal-000`` ->
    ``slave``). Recursive; files that vanish meanwhile are skipped."""
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
    """

    def __init__(self, run_dir: Path, max_bytes: float | None, min_free_bytes: float | None):
        self.dir = Path(run_dir)
        self.max_bytes, self.min_free_bytes = max_bytes, min_free_bytes
        self.run_bytes = 0
        self.free_bytes: int | None = None
        self.reached: dict | None = None        # {"reason", "time", "run_bytes", "free_bytes"} once past a limit
        self._next = -float("inf")
        self._first: tuple[float, dict[str, int]] | None = None
        self.rates: dict[str, float] | None = None  # owner -> bytes per second, measured once [B/s]

    def check(self, now: float, t: float, measure: bool = True) -> bool:
        """Measure when :data:`CHECK_INTERVAL` has passed since the last look (``now`` [s, monotonic]);
        True the first time a limit is passed (logged once, kept in :attr:`reached` with the recorder's
        time ``t`` [s]). ``measure``: the session has started (its rate is measured from then on)."""
        if self.reached is not None or now < self._next:
            return False
        self._next = now + CHECK_INTERVAL
        owners = dir_bytes(self.dir)
        self.run_bytes = sum(owners.values())
        if measure:
            self._measure(now, owners)
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
        log.warning("recorder: %s: the high-rate streams are no longer written (counted only); heartbeats at "
                    "%g Hz, state changes and liveliness still are", reason, LOW_RATE_HZ)
        return True

    def _measure(self, now: float, owners: dict[str, int]) -> None:
        """Once :data:`RATE_AFTER` seconds of the session have passed: print its bytes per second, per owner."""
        if self._first is None:
            self._first = (now, owners)
            return
        t0, first = self._first
        if self.rates is not None or now - t0 < RATE_AFTER:
            return
        self.rates = {k: (owners.get(k, 0) - first.get(k, 0)) / (now - t0) for k in sorted(owners)}
        total = sum(self.rates.values())
        parts = ", ".join(f"{k} {v / 1e3:.0f} kB/s" for k, v in self.rates.items() if v >= 500)
        until = ("" if self.max_bytes is None or total <= 0 else
                 f"; recording.max_bytes {self.max_bytes / 1e9:.3g} GB reached in about "
                 f"{max(0.0, self.max_bytes - self.run_bytes) / total / 60:.0f} min")
        print(f"teleop record: the session writes {total / 1e3:.0f} kB/s ({parts}), {total * 3600 / 1e9:.2f} GB "
              f"per hour{until}", flush=True)

    def summary(self) -> dict:
        """``{"max_bytes", "min_free_bytes", "run_bytes", "free_bytes", "bytes_per_second", "reached"}`` (bytes
        [B], rates [B/s] per owner, measured over the first :data:`RATE_AFTER` seconds)."""
        return {"max_bytes": self.max_bytes, "min_free_bytes": self.min_free_bytes, "run_bytes": self.run_bytes,
                "free_bytes": self.free_bytes, "bytes_per_second": self.rates, "reached": self.reached}


class Writes:
    """Runs the recorder's file writes; counts, per file, the writes an ``OSError`` kept out.

    After the first error of a file its later writes are not tried (counted): a file whose buffer
    could not be handed to the OS is cut there, and what it held before stays readable.
    """

    def __init__(self) -> None:
        self.failed: dict[str, str] = {}       # file name -> its first error
        self.not_written: dict[str, int] = {}  # file name -> writes not done
        self.skipped: dict[str, int] = {}      # stream key -> messages not written past the budget

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
            log.error("recorder: %s is no longer written: %s (what it holds stays readable)", name, e)
            return False

    def close(self, name: str, fn: Callable) -> None:
        """Close the file ``name`` with ``fn()``, also after an error of it (what its buffer holds is
        handed to the OS where the OS takes it); an ``OSError`` is counted, not raised."""
        try:
            fn()
        except OSError as e:
            self.failed.setdefault(name, f"{type(e).__name__}: {e}")
            self.not_written[name] = self.not_written.get(name, 0) + 1

    def skip(self, key: str) -> None:
        """One message on ``key`` not written because the budget is reached."""
        self.skipped[key] = self.skipped.get(key, 0) + 1

    def summary(self) -> dict:
        """``{"write_errors": {file: error}, "not_written": {file: n}, "over_budget_not_written": {key: n}}``."""
        return {"write_errors": dict(sorted(self.failed.items())), "not_written": dict(sorted(self.not_written.items())),
                "over_budget_not_written": dict(sorted(self.skipped.items()))}
