"""In-memory stand-ins shared by the node tests: a latest-wins topic and a CSV recorder."""
from __future__ import annotations

import math

from teleop.session.transport import Received
from teleop.wire.codec import decode, encode


class Topic:
    """In-memory latest-wins topic: a publisher and a subscriber in one (receive time = the fake clock).

    :attr:`sent` keeps every message put (``keep=False``: none, for long runs); ``codec=True`` sends
    every message through the codec (what a subscriber would decode); setting :attr:`cut` drops
    everything put from then on (a cut link).
    """

    def __init__(self, clock, *, codec: bool = False, keep: bool = True):
        self.clock, self.sent, self.last, self.count, self.errors = clock, [], None, 0, 0
        self.codec, self.keep, self.cut = codec, keep, False

    def put(self, msg) -> None:
        if self.cut:
            return
        if self.keep:
            self.sent.append(msg)
        self.last = Received(decode(encode(msg)) if self.codec else msg, self.clock.now())
        self.count += 1

    def latest(self):
        return self.last

    def age(self, now: float) -> float:
        return math.inf if self.last is None else now - self.last.t_recv


class Rows:
    """A recorder that keeps the rows written."""

    def __init__(self):
        self.rows = []

    def write(self, row):
        self.rows.append(tuple(row))
