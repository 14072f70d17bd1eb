"""Test-only log of every message a process publishes: ``TELEOP_PUBLISH_LOG=<file>``.

With the variable set, :class:`teleop.session.transport.Publisher` writes two lines per message, straight to
the OS (``os.write`` on an ``O_APPEND`` file, no Python buffer, so a SIGKILL loses no line that was
written): ``b <key> <seq> <crc32>`` before anything else is done with the message (journal, zenoh),
and ``e <key> <seq>`` once zenoh's put has returned. The zero-loss tests compare them with what
``teleop record`` wrote: every message with an ``e`` line must be in the recording (its publication
was complete), and every recorded message must have a ``b`` line with the same CRC-32 of its payload
(nothing invented, nothing altered). The one message a SIGKILL can catch between its two lines may be
either way. This log is the tests' oracle: it is written by its own code and file, never read by
the recorder, and it does not use the side's journal (:mod:`teleop.recording.journal`) that the recorder
completes its recording from. Unset (always, outside tests): nothing is done and :data:`PUBLISH_LOG`
is None.
"""
from __future__ import annotations

import os
import threading
import zlib
from pathlib import Path

__all__ = ["PUBLISH_LOG", "PublishLog", "read_publish_log", "read_publish_attempts"]

ENV = "TELEOP_PUBLISH_LOG"


class PublishLog:
    """Appends the ``b``/``e`` lines of the module docstring to ``path`` (one ``os.write`` each, thread-safe)."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self._fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
        self._lock = threading.Lock()

    def _write(self, line: str) -> None:
        with self._lock:
            os.write(self._fd, line.encode())

    def begin(self, key: str, msg, payload: bytes) -> None:
        """``msg`` (with a ``seq`` field), encoded as ``payload``, is about to be published on ``key``."""
        self._write(f"b {key} {getattr(msg, 'seq', -1)} {zlib.crc32(payload)}\n")

    def done(self, key: str, msg) -> None:
        """The put of ``msg`` on ``key`` has returned."""
        self._write(f"e {key} {getattr(msg, 'seq', -1)}\n")


def _lines(path: str | Path):
    for line in Path(path).read_text(encoding="utf-8").splitlines():
        parts = line.split()
        if len(parts) >= 3 and parts[0] in ("b", "e") and parts[2].lstrip("-").isdigit():
            yield parts


def read_publish_log(path: str | Path) -> dict[str, list[int]]:
    """``key -> [seq, ...]`` of the messages whose put returned (``e`` lines), in publishing order (a
    torn last line is ignored)."""
    out: dict[str, list[int]] = {}
    for parts in _lines(path):
        if parts[0] == "e":
            out.setdefault(parts[1], []).append(int(parts[2]))
    return out


def read_publish_attempts(path: str | Path) -> dict[str, dict[int, int]]:
    """``key -> {seq: crc32 of the payload}`` of every message whose publication began (``b`` lines)."""
    out: dict[str, dict[int, int]] = {}
    for parts in _lines(path):
        if parts[0] == "b" and len(parts) == 4 and parts[3].isdigit():
            out.setdefault(parts[1], {})[int(parts[2])] = int(parts[3])
    return out


PUBLISH_LOG: PublishLog | None = PublishLog(os.environ[ENV]) if os.environ.get(ENV) else None
