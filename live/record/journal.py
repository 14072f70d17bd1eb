"""The recorder's side of the sides' write-ahead journals (:mod:`teleop.recording.journal`).

``teleop record`` completes its recording from the journals in its run directory: when a side's
liveliness is lost (after :data:`DELAY`, so that what is still on its way arrives first) and at the
recorder's end, every journaled message the recording does not have is added to it, marked as
recovered. A message is known by its ``seq`` on its key (a message received twice is one message; one
without a ``seq``: by the hash of its payload bytes). The recording's messages are remembered in constant
memory, the newest :data:`SEEN` per key (more than a journal's ring of two 8 MB segments holds of any
stream), so an hour at 1 kHz costs no more than a minute. Journal records published before the recorder started (an
earlier session in the same run directory, or a side that started first) are left out and counted. So are the records of
keys the recorder does not subscribe to (``keys``): a bimanual side journals every arm's messages in one journal
(:mod:`live.bimanual_sides`), and each arm's recorder takes its own arm's only.
"""
from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from teleop.recording.journal import JournalReader, journal_segments

__all__ = ["JournalRecovery", "DELAY", "SEEN"]

DELAY = 0.3     # [s] after a side's liveliness is lost, its journal is read this much later
SEEN = 1 << 19  # messages of one key remembered (a journal's 16 MB ring holds fewer: >= 60 B per record)


class _Seen:
    """The newest :data:`SEEN` messages of one key: seqs in a ring (slot ``seq % SEEN``, 4 MB), payload hashes
    of messages without a seq in two generations of sets (the older dropped when the newer is full)."""

    def __init__(self) -> None:
        self.seqs = np.full(SEEN, -1, dtype=np.int64)
        self.new: set[int] = set()
        self.old: set[int] = set()

    def has(self, seq: int | None, h: int) -> bool:
        return (seq is not None and bool(self.seqs[seq % SEEN] == seq)) or h in self.new or h in self.old

    def add(self, seq: int | None, h: int) -> None:
        if seq is not None:
            self.seqs[seq % SEEN] = seq
            return
        if len(self.new) >= SEEN // 2:
            self.old, self.new = self.new, set()
        self.new.add(h)


def _side(key: str) -> str:
    parts = key.split("/")
    return parts[2] if len(parts) > 3 else key


class JournalRecovery:
    """Which messages the recording has, and the journal records it lacks.

    Parameters
    ----------
    run_dir : Path
        Where the sides write ``<side>.journal-NNN``.
    t_start : float, optional
        The recorder's start [s, :func:`time.monotonic`]; older journal records are left out.
    keys : str, optional
        The Zenoh key expression the recorder subscribes to (``teleop/<id>/**``,
        :func:`teleop.wire.keys.instrument_keys`); journal records of keys it does not include are left out and
        counted (default: every key).
    """

    def __init__(self, run_dir: Path, t_start: float | None = None, keys: str | None = None):
        self.dir = Path(run_dir)
        self.t_start = time.monotonic() if t_start is None else t_start
        self.keys = keys
        self._takes: dict[str, bool] = {}
        self.other_keys = 0
        self._readers: dict[str, JournalReader] = {}
        self._due: dict[str, float] = {}
        self._seen: dict[str, _Seen] = {}
        self._recovered: dict[str, set[int]] = {}
        self.counts: dict[str, int] = {}
        self.before_start = 0
        self.late = 0

    def note(self, key: str, payload: bytes, recovered: bool, seq: int | None = None) -> bool:
        """Whether to record this message (``seq``: its sequence number, if it has one): a received one unless
        it was recovered already (it then arrived late), a recovered one unless it was received."""
        h = hash(payload)
        seen = self._seen.get(key)
        if seen is None:
            seen = self._seen[key] = _Seen()
        if recovered:
            if seen.has(seq, h):
                return False
            seen.add(seq, h)
            self._recovered.setdefault(key, set()).add(h)
            side = _side(key)
            self.counts[side] = self.counts.get(side, 0) + 1
            return True
        if h in self._recovered.get(key, ()):
            self.late += 1
            return False
        seen.add(seq, h)
        return True

    def schedule(self, side: str, now: float) -> None:
        """``side`` is gone at ``now`` [s, monotonic]: read its journal :data:`DELAY` later."""
        self._due[side] = now + DELAY

    def due(self, now: float) -> list[str]:
        """The sides whose journal is due at ``now`` [s, monotonic] (each returned once)."""
        sides = [s for s, t in self._due.items() if t <= now]
        for s in sides:
            del self._due[s]
        return sides

    def records(self, side: str | None) -> Iterator[tuple[float, str, bytes]]:
        """``(t_publish, key, payload)`` of the journal records of ``side`` (all sides: None) not looked
        at before and not received (records older than the recorder are counted and skipped)."""
        sides = [side] if side is not None else sorted(journal_segments(self.dir))
        for s in sides:
            reader = self._readers.get(s)
            if reader is None:
                reader = self._readers[s] = JournalReader(self.dir, s)
            for t, key, payload in reader.new_records():
                if not self._included(key):
                    self.other_keys += 1
                elif t < self.t_start:
                    self.before_start += 1
                elif not self._known(key, payload):
                    yield t, key, payload

    def _included(self, key: str) -> bool:
        """Whether ``key`` is one of :attr:`keys` (a key that is no valid key expression is not)."""
        if self.keys is None:
            return True
        ok = self._takes.get(key)
        if ok is None:
            import zenoh
            try:
                ok = bool(zenoh.KeyExpr(self.keys).includes(zenoh.KeyExpr(key)))
            except Exception:  # noqa: BLE001 - ZError: a torn or foreign key is none of the recorder's
                ok = False
            if len(self._takes) < 4096:        # a journal's keys are few; a corrupt one costs a lookup each
                self._takes[key] = ok
        return ok

    def _known(self, key: str, payload: bytes) -> bool:
        """Whether the message ``payload`` on ``key`` is one the recording has."""
        seen = self._seen.get(key)
        if seen is None:
            return False
        from live.record.files import decode_any
        try:
            seq = getattr(decode_any(payload), "seq", None)
        except Exception:  # noqa: BLE001 - CodecError: known by its hash only
            seq = None
        return seen.has(seq, hash(payload))

    def summary(self) -> dict:
        """``{"journal_dir", "journals": {side: segments found}, "recovered": {side: n}, "before_start",
        "other_keys", "arrived_after_recovery"}`` (``other_keys``: records of keys not recorded, left out)."""
        return {"journal_dir": str(self.dir),
                "journals": {s: len(v) for s, v in sorted(journal_segments(self.dir).items())},
                "recovered": dict(sorted(self.counts.items())), "before_start": self.before_start,
                "other_keys": self.other_keys, "arrived_after_recovery": self.late}
