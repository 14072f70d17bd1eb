"""Fault injection on the outgoing messages of one process: delay, loss, duplication, reordering, corruption.

A :class:`FaultInjector` wraps the :class:`teleop.session.transport.Publisher` objects of a process (the CLI's
``--inject SPEC`` on ``teleop master`` or ``teleop slave``; tests build one directly). Every message
put on a wrapped publisher passes through it; while the fault is active each one is, in this order:

1. dropped with probability ``drop``;
2. corrupted (``corrupt``): ``nan`` / ``inf`` written over one float field at byte level (the codec
   refuses to encode them), ``range`` a finite but impossible value (the Command's first target = 100, i.e. 100 m of
   a tendon or 100 rad of a joint; the Estimate's first tendon T_out_hat = 1e4 N; Heartbeat.t_sender
   = 1e12 s), ``version``
   the wire version byte + 1;
3. held back with probability ``reorder`` and sent right after the next message of the same stream;
4. sent twice with probability ``dup``;
5. delayed by ``delay`` seconds.

Delayed and held messages wait in a queue that is pumped on every put (the nodes publish at 1 kHz,
so the delay resolution is one cycle) and by :meth:`FaultInjector.pump`. Everything runs on the
injector's clock, so a :class:`teleop.timing.clock.FakeClock` makes it deterministic; random choices come
from a numpy Generator seeded with ``seed``.

Spec strings (``--inject``), comma-separated ``key=value``::

    delay=30ms,drop=0.1,dup=0.05,reorder=0.05,seed=1
    corrupt=nan,stream=command,on=usr1       # from SIGUSR1 on, every command has a NaN
    drop=1,stream=estimate+heartbeat,at=2s,for=0.5s

``stream`` (``command``, ``estimate``, ``heartbeat``, joined with ``+``; default all), ``at`` [s]
after the injector starts or ``on=usr1`` (from the moment the process receives SIGUSR1), ``for`` [s]
(default: until the end). Times take ``ms`` or ``s`` suffixes (bare numbers are seconds).
"""
from __future__ import annotations

import dataclasses
import heapq
import math
import re
import signal
import struct
import threading
from dataclasses import dataclass
from typing import Any

import numpy as np

from teleop.errors import ConfigError
from teleop.timing.clock import Clock, MonotonicClock
from teleop.wire.codec import WIRE_VERSION, decode, encode
from teleop.wire.messages import Command, Estimate, Heartbeat

__all__ = ["FaultSpec", "parse_fault_spec", "FaultInjector", "FaultyPublisher", "corrupt_payload", "STREAMS",
           "CORRUPTIONS"]

STREAMS = ("command", "estimate", "heartbeat")
CORRUPTIONS = ("nan", "inf", "range", "version")
HOLD_MAX = 0.1       # a reordered message waits at most this long for the next one [s]
_SENTINEL = 1234.56789012345



def _estimate_with(msg: Estimate, v: float) -> Estimate:
    """``msg`` with the first tendon's T_out_hat = v."""
    a0 = msg.axes[0]
    t0 = dataclasses.replace(a0.tendons[0], T_out_hat=v)
    return dataclasses.replace(msg, axes=(dataclasses.replace(a0, tendons=(t0, *a0.tendons[1:])), *msg.axes[1:]))


#: The float field each corruption writes over: message type -> (message with the value v, impossible v).
#: A Command's first target: 100 m of a tendon or 100 rad of a joint, out of range either way.
_FIELD = {Command: (lambda m, v: dataclasses.replace(m, targets=(v, *m.targets[1:])), 100.0),
          Estimate: (_estimate_with, 1.0e4),
          Heartbeat: (lambda m, v: dataclasses.replace(m, t_sender=v), 1.0e12)}


@dataclass(frozen=True)
class FaultSpec:
    """What to inject (see the module docstring); probabilities in [0, 1], times in seconds."""

    delay: float = 0.0
    drop: float = 0.0
    dup: float = 0.0
    reorder: float = 0.0
    corrupt: str | None = None
    streams: tuple[str, ...] = STREAMS
    at: float = 0.0
    on_signal: bool = False
    duration: float = math.inf
    seed: int = 0
    text: str = ""


def _seconds(key: str, v: str) -> float:
    m = re.fullmatch(r"\s*([0-9.eE+-]+)\s*(ms|s)?\s*", v)
    try:
        x = float(m.group(1)) * (1e-3 if m.group(2) == "ms" else 1.0) if m else math.nan
    except ValueError:
        x = math.nan
    if not (math.isfinite(x) and x >= 0):
        raise ConfigError(f"--inject: {key}={v!r}: expected a time >= 0 such as 30ms or 0.5s")
    return x


def _probability(key: str, v: str) -> float:
    try:
        x = float(v)
    except ValueError:
        x = math.nan
    if not 0.0 <= x <= 1.0:
        raise ConfigError(f"--inject: {key}={v!r}: expected a probability in [0, 1]")
    return x


def parse_fault_spec(text: str) -> FaultSpec:
    """Parse an ``--inject`` spec string.

    Raises
    ------
    ConfigError
        Unknown key, malformed item or value out of range (the message names the item).
    """
    kw: dict[str, Any] = {"text": text}
    for item in filter(None, (s.strip() for s in text.split(","))):
        key, sep, v = item.partition("=")
        key, v = key.strip(), v.strip()
        if not sep:
            raise ConfigError(f"--inject: {item!r} is not key=value (e.g. delay=30ms,drop=0.1)")
        if key in ("delay", "at"):
            kw[key] = _seconds(key, v)
        elif key == "for":
            kw["duration"] = _seconds(key, v)
        elif key in ("drop", "dup", "reorder"):
            kw[key] = _probability(key, v)
        elif key == "corrupt":
            if v not in CORRUPTIONS:
                raise ConfigError(f"--inject: corrupt={v!r}: expected one of {', '.join(CORRUPTIONS)}")
            kw["corrupt"] = v
        elif key == "stream":
            names = tuple(s.strip() for s in v.split("+"))
            bad = [s for s in names if s not in STREAMS]
            if bad or not names:
                raise ConfigError(f"--inject: stream={v!r}: expected names from {', '.join(STREAMS)} joined by +")
            kw["streams"] = names
        elif key == "on":
            if v != "usr1":
                raise ConfigError(f"--inject: on={v!r}: the only trigger is usr1 (SIGUSR1)")
            kw["on_signal"] = True
        elif key == "seed":
            if not v.isdigit():
                raise ConfigError(f"--inject: seed={v!r}: expected an integer >= 0")
            kw["seed"] = int(v)
        else:
            raise ConfigError(f"--inject: unknown key {key!r} (expected delay, drop, dup, reorder, corrupt, "
                              f"stream, at, for, on, seed)")
    return FaultSpec(**kw)


def corrupt_payload(payload: bytes, kind: str) -> bytes:
    """``payload`` (a codec message) with one corruption of :data:`CORRUPTIONS` applied.

    ``nan``/``inf`` are written over the float field of ``_FIELD`` at byte level: the message is
    re-encoded with a sentinel there and the sentinel's bytes replaced, so no byte offset is assumed.
    """
    if kind == "version":
        return payload[:1] + bytes([(WIRE_VERSION + 1) & 0xFF]) + payload[2:]
    msg = decode(payload)
    with_value, impossible = _FIELD[type(msg)]
    if kind == "range":
        return encode(with_value(msg, impossible))
    marked = encode(with_value(msg, _SENTINEL))
    bad = math.nan if kind == "nan" else math.inf
    out = marked.replace(struct.pack("<d", _SENTINEL), struct.pack("<d", bad))
    if out == marked:  # pragma: no cover - the codec stores floats as little-endian float64
        raise ValueError(f"cannot find the corrupted field of {type(msg).__name__} in the payload")
    return out


class FaultInjector:
    """Applies a :class:`FaultSpec` to every publisher made by :meth:`wrap` (see the module docstring).

    Parameters
    ----------
    spec : FaultSpec or str
    clock : Clock, optional
        Time source (default :class:`MonotonicClock`); the same clock as the node's.

    Attributes
    ----------
    counts : dict
        ``passed, dropped, corrupted, reordered, duplicated, delayed`` messages so far.
    t_fault : float or None
        When the fault became active [s, clock]; None before.
    """

    def __init__(self, spec: FaultSpec | str, clock: Clock | None = None):
        self.spec = parse_fault_spec(spec) if isinstance(spec, str) else spec
        self.clock = clock or MonotonicClock()
        self.rng = np.random.default_rng(self.spec.seed)
        self.counts = dict.fromkeys(("passed", "dropped", "corrupted", "reordered", "duplicated", "delayed"), 0)
        self.t_fault: float | None = None
        self._t0: float | None = None
        self._signalled: float | None = None
        self._queue: list[tuple[float, int, FaultyPublisher, bytes]] = []
        self._held: dict[int, tuple[float, bytes, FaultyPublisher]] = {}
        self._order = 0
        self._lock = threading.Lock()

    def wrap(self, publisher: Any, stream: str) -> FaultyPublisher:
        """A publisher that sends through this injector; ``stream`` is one of :data:`STREAMS`."""
        if stream not in STREAMS:
            raise ValueError(f"unknown stream {stream!r}: expected one of {', '.join(STREAMS)}")
        return FaultyPublisher(self, publisher, stream)

    def trigger(self, now: float | None = None) -> None:
        """Start the fault now (what SIGUSR1 does with ``on=usr1``)."""
        self._signalled = self.clock.now() if now is None else now

    def install_signal(self) -> None:
        """With ``on=usr1``: SIGUSR1 triggers the fault (main thread only)."""
        if self.spec.on_signal:
            signal.signal(signal.SIGUSR1, lambda signum, frame: self.trigger())

    def active(self, now: float) -> bool:
        """Whether the fault applies to a message put at ``now`` [s]."""
        if self._t0 is None:
            self._t0 = now
        start = self._signalled if self.spec.on_signal else self._t0 + self.spec.at
        if start is None or now < start or now >= start + self.spec.duration:
            return False
        if self.t_fault is None:
            self.t_fault = start
        return True

    def send(self, pub: FaultyPublisher, payload: bytes, now: float) -> None:
        """Pass one encoded message of ``pub`` through the fault (module docstring order)."""
        with self._lock:
            self._pump(now)
            sp = self.spec
            if pub.stream not in sp.streams or not self.active(now):
                self._emit(pub, payload, now, now)
                return
            r = self.rng.random(3)
            if sp.drop and r[0] < sp.drop:
                self.counts["dropped"] += 1
                return
            if sp.corrupt:
                payload = corrupt_payload(payload, sp.corrupt)
                self.counts["corrupted"] += 1
            held = self._held.pop(id(pub), None)
            if sp.reorder and r[1] < sp.reorder and held is None:
                self._held[id(pub)] = (now, payload, pub)
                self.counts["reordered"] += 1
                return
            due = now + sp.delay
            copies = 2 if sp.dup and r[2] < sp.dup else 1
            self.counts["duplicated"] += copies - 1
            for _ in range(copies):
                self._emit(pub, payload, due, now)
            if held is not None:
                self._emit(pub, held[1], due, now)

    def pump(self, now: float | None = None) -> int:
        """Send every queued message that is due at ``now`` [s]; returns how many were sent."""
        with self._lock:
            return self._pump(self.clock.now() if now is None else now)

    def pending(self) -> int:
        """Messages waiting (delayed or held back)."""
        with self._lock:
            return len(self._queue) + len(self._held)

    def stats(self) -> dict[str, Any]:
        """Counters, the spec and the fault start time (JSON-ready)."""
        return {"spec": self.spec.text, **self.counts, "t_fault": self.t_fault, "pending": self.pending()}

    # ---- internals ---------------------------------------------------------------------------------
    def _emit(self, pub: FaultyPublisher, payload: bytes, due: float, now: float) -> None:
        if due <= now and not self._queue:
            pub.inner.put_bytes(payload)
            self.counts["passed"] += 1
            return
        self.counts["delayed"] += due > now
        self._order += 1
        heapq.heappush(self._queue, (due, self._order, pub, payload))

    def _pump(self, now: float) -> int:
        n = 0
        for key, (t_held, payload, pub) in list(self._held.items()):
            if now - t_held >= HOLD_MAX:          # no next message came: let it go
                del self._held[key]
                self._order += 1
                heapq.heappush(self._queue, (now, self._order, pub, payload))
        while self._queue and self._queue[0][0] <= now:
            _, _, pub, payload = heapq.heappop(self._queue)
            pub.inner.put_bytes(payload)
            self.counts["passed"] += 1
            n += 1
        return n


class FaultyPublisher:
    """A publisher whose messages go through a :class:`FaultInjector` (same ``put`` interface)."""

    def __init__(self, injector: FaultInjector, inner: Any, stream: str):
        self.injector, self.inner, self.stream = injector, inner, stream
        self.key = getattr(inner, "key", stream)
        self.sent = 0                       # puts so far (before the fault decides their fate)

    def put(self, msg) -> None:
        """Encode ``msg`` (CodecError for a bad message, as :meth:`Publisher.put`) and pass it on."""
        self.put_bytes(encode(msg))

    def put_bytes(self, payload: bytes) -> None:
        self.sent += 1
        self.injector.send(self, payload, self.injector.clock.now())

    def close(self) -> None:
        self.inner.close()
