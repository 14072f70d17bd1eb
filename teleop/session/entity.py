"""The base of everything declared on a zenoh session, and a rate-limited log for recurring problems.

:class:`Entity` is subclassed by the publishers and subscribers of :mod:`teleop.session.transport` and by the
liveliness tokens and watchers of :mod:`teleop.session.liveliness`; it knows the session only through its
``zenoh_session`` and ``clock`` attributes, so neither of those modules imports the other's classes
at run time.
"""
from __future__ import annotations

import logging
import math
import re
import threading
from typing import TYPE_CHECKING, Any

import zenoh

from teleop.errors import TransportError
from teleop.timing.clock import Clock, MonotonicClock

if TYPE_CHECKING:
    from teleop.session.transport import Session

__all__ = ["Entity", "RateLimitedLog", "zenoh_error_text"]


def zenoh_error_text(e: Exception) -> str:
    """The human part of a zenoh error (without the Rust source locations)."""
    text = str(e)
    m = re.search(r'msg: "(.*?)(?: at /[^"]*)?"', text)
    return (m.group(1) if m else text.split(" at /")[0]).strip()


class RateLimitedLog:
    """Log a recurring problem at most once per ``interval`` seconds, with the count suppressed.

    Parameters
    ----------
    logger : logging.Logger
    interval : float
        Minimum time between two records [s].
    clock : Clock, optional
        Time source (default :class:`MonotonicClock`).
    """

    def __init__(self, logger: logging.Logger, interval: float = 1.0, clock: Clock | None = None):
        self.logger, self.interval = logger, interval
        self.clock = clock or MonotonicClock()
        self._last = -math.inf
        self._suppressed = 0
        self._lock = threading.Lock()

    def warning(self, msg: str, *args) -> bool:
        """Log ``msg % args`` unless one was logged less than ``interval`` ago. Returns True if logged."""
        with self._lock:
            now = self.clock.now()
            if now - self._last < self.interval:
                self._suppressed += 1
                return False
            suppressed, self._suppressed, self._last = self._suppressed, 0, now
        tail = f" ({suppressed} similar suppressed)" if suppressed else ""
        self.logger.warning(msg + tail, *args)
        return True


class Entity:
    """Something declared on a session, undeclared once by :meth:`close`."""

    def __init__(self, session: Session, key: str):
        self.session, self.key = session, key
        self._handle: Any = None
        self._closed = False

    def _declare(self, fn, *args, **kwargs) -> None:
        try:
            self._handle = fn(*args, **kwargs)
        except zenoh.ZError as e:
            raise TransportError(f"cannot declare {type(self).__name__} on {self.key!r}: "
                                 f"{zenoh_error_text(e)}") from None

    @property
    def closed(self) -> bool:
        return self._closed

    def close(self) -> None:
        """Undeclare. Idempotent; a no-op once the session is closed."""
        if self._closed:
            return
        self._closed = True
        try:
            self._handle.undeclare()
        except zenoh.ZError:  # pragma: no cover - undeclare after session close is a no-op
            pass

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()
