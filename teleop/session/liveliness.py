"""Liveliness over zenoh: this process's token, and a watcher of the tokens of its peers.

A token disappears for the watchers of a matching key expression when it is closed or when its
session ends. Both sides declare one and watch the other's; the nodes' own heartbeat watchdogs stay
the fast safety stop (docs/concepts/architecture.md). Declared through
:meth:`teleop.session.transport.Session.liveliness_token` and
:meth:`~teleop.session.transport.Session.liveliness_watcher` (both classes build on
:class:`teleop.session.entity.Entity`). The watcher's callback never
lets an exception escape into zenoh's thread: it is logged at a limited rate.
"""
from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from typing import TYPE_CHECKING

import zenoh

from teleop.session.entity import Entity, RateLimitedLog

if TYPE_CHECKING:
    from teleop.session.transport import Session

__all__ = ["LivelinessToken", "LivelinessWatcher"]

log = logging.getLogger("teleop.session.transport")


class LivelinessToken(Entity):
    """This process's liveliness on one key; disappears for watchers when closed or when the session ends."""

    def __init__(self, session: Session, key: str):
        super().__init__(session, key)
        self._declare(session.zenoh_session.liveliness().declare_token, key)


class LivelinessWatcher(Entity):
    """Tracks which liveliness tokens matching a key expression are present.

    Parameters
    ----------
    on_change : callable(key: str, alive: bool), optional
        Called on zenoh's thread for each appearance and disappearance; exceptions are logged and
        swallowed.

    Attributes
    ----------
    alive : bool
        At least one matching token present.
    changes : int
        Appearances plus disappearances seen.
    """

    def __init__(self, session: Session, key: str,
                 on_change: Callable[[str, bool], None] | None = None):
        super().__init__(session, key)
        self.on_change = on_change
        self.changes = 0
        self._present: set[str] = set()
        self._cond = threading.Condition()
        self._log = RateLimitedLog(log, 1.0, session.clock)
        self._declare(session.zenoh_session.liveliness().declare_subscriber, key, self._on_sample, history=True)

    def _on_sample(self, sample: zenoh.Sample) -> None:
        k = str(sample.key_expr)
        up = sample.kind == zenoh.SampleKind.PUT
        with self._cond:
            (self._present.add if up else self._present.discard)(k)
            self.changes += 1
            self._cond.notify_all()
        if self.on_change is not None:
            try:
                self.on_change(k, up)
            except Exception as e:  # noqa: BLE001 - never kill the zenoh callback
                self._log.warning("liveliness callback on %s failed: %r", k, e)

    @property
    def alive(self) -> bool:
        with self._cond:
            return bool(self._present)

    @property
    def present(self) -> frozenset[str]:
        """Keys of the tokens present now."""
        with self._cond:
            return frozenset(self._present)

    def wait_for(self, alive: bool, timeout: float | None = None) -> bool:
        """Block until :attr:`alive` equals ``alive`` or ``timeout`` [s]; True if it does."""
        with self._cond:
            return self._cond.wait_for(lambda: bool(self._present) == alive, timeout)

    def close(self) -> None:
        super().close()
        with self._cond:
            self._cond.notify_all()
