"""Test-only log of every message a process publishes: ``TELEOP_PUBLISH_LOG=<file>``.

With the variable set, :class:`teleop.transport.Publisher` appends one line ``<key> <seq>`` per
message it has handed to zenoh, written straight to the OS (``os.write`` on an ``O_APPEND`` file, no
Python buffer), so a SIGKILL loses no line of a message that was published. The zero-loss tests
compare these lines with what ``teleop record`` wrote. Unset (always, outside tests): nothing is
done and :data:`PUBLISH_LOG` is None.
"""
from __future__ import annotations

import os
import threading
from pathlib import Path

__all__ = ["PUBLISH_LOG", "PublishLog", "read_publish_log"]

ENV = "TELEOP_PUBLISH_LOG"


class PublishLog:
    """Appends ``<key> <seq>`` lines to ``path`` (one ``os.write`` each, thread-safe)."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self._fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
        self._lock = threading.Lock()

    def note(self, key: str, msg) -> None:
        """Log that ``msg`` (with a ``seq`` field) was published on ``key``."""
        line = f"{key} {getattr(msg, 'seq', -1)}\n".encode()
        with self._lock:
            os.write(self._fd, line)


def read_publish_log(path: str | Path) -> dict[str, list[int]]:
    """``key -> [seq, ...]`` in publishing order from a log file (a torn last line is ignored)."""
    out: dict[str, list[int]] = {}
    for line in Path(path).read_text(encoding="utf-8").splitlines():
        parts = line.split()
        if len(parts) == 2 and parts[1].lstrip("-").isdigit():
            out.setdefault(parts[0], []).append(int(parts[1]))
    return out


PUBLISH_LOG: PublishLog | None = PublishLog(os.environ[ENV]) if os.environ.get(ENV) else None
