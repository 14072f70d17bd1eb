"""A thin layer over eclipse-zenoh 1.x: one session, typed publishers, latest-wins subscribers, liveliness.

Over 400 lines: the zenoh config a session opens with and the typed entities declared on it are one wrapper.

Default deployment: two peers on loopback, one listening and one connecting, multicast scouting off
(no traffic leaves 127.0.0.1) and gossip scouting on, so peers that reach one common peer also find
each other. Payloads are :mod:`teleop.wire.codec` bytes; keys come from :mod:`teleop.wire.keys`.

Zenoh calls subscriber callbacks on its own threads. :class:`LatestSubscriber` and
:class:`~teleop.session.liveliness.LivelinessWatcher` never let an exception escape a callback: they count it
and log it at a limited rate, as every real-time path in this project does.

Liveliness tokens and watchers are in :mod:`teleop.session.liveliness`; they are declared through
:class:`Session`.
"""
from __future__ import annotations

import json
import logging
import math
import socket
import threading
from collections.abc import Callable
from typing import Any, Generic, NamedTuple, TypeVar

import zenoh

from teleop.config.schema import TransportConfig
from teleop.errors import CodecError, ConfigError, TransportError
from teleop.recording import journal
from teleop.recording.publish_log import PUBLISH_LOG
from teleop.session.credentials import installation_settings
from teleop.session.entity import Entity, RateLimitedLog, zenoh_error_text
from teleop.session.link_security import link_security_settings
from teleop.session.liveliness import LivelinessToken, LivelinessWatcher
from teleop.timing.clock import Clock, MonotonicClock
from teleop.wire.codec import Message, decode, encode

__all__ = [
    "zenoh_config", "free_tcp_ports", "free_tcp_port", "accepts_connections", "loopback_endpoint", "Session",
    "Publisher", "Received", "LatestSubscriber",
]

log = logging.getLogger(__name__)
M = TypeVar("M", bound=Message)


def _insert(cfg: zenoh.Config, key: str, value, where: str, shown=None) -> None:
    try:
        cfg.insert_json5(key, json.dumps(value))
    except zenoh.ZError as e:
        raise ConfigError(f"{where}: {value if shown is None else shown!r} rejected by zenoh: "
                          f"{zenoh_error_text(e)}") from None


def zenoh_config(transport: TransportConfig, *, listen: tuple[str, ...] | None = None,
                 connect: tuple[str, ...] | None = None, role: str | None = None) -> zenoh.Config:
    """Build the zenoh configuration of one process.

    Parameters
    ----------
    transport : TransportConfig
        ``mode`` (peer | client), ``listen`` and ``connect`` endpoints (``tcp/127.0.0.1:7447``),
        ``multicast_scouting``.
    listen, connect : tuple of str, optional
        Replace the configured endpoints (the CLI's ``--listen``/``--connect``; in one config both
        sides cannot listen on the same port, so one side usually overrides ``listen=()``).
    role : str, optional
        The process's role in a live session: its installation credentials and access control
        (:func:`teleop.session.credentials.installation_settings`); None (a library or test session): none.

    Returns
    -------
    zenoh.Config
        Gossip scouting on (single hop) so loopback peers find each other through a common peer.

    Raises
    ------
    ConfigError
        An endpoint zenoh does not accept (names ``transport.listen[i]`` / ``transport.connect[i]``); the
        installation's credentials cannot be read or created.
    """
    listen = tuple(transport.listen if listen is None else listen)
    connect = tuple(transport.connect if connect is None else connect)
    cfg = zenoh.Config()
    _insert(cfg, "mode", transport.mode, "transport.mode")
    for name, eps in (("listen", listen), ("connect", connect)):
        for i, ep in enumerate(eps):   # validate one by one to name the bad entry
            _insert(zenoh.Config(), f"{name}/endpoints", [ep], f"transport.{name}[{i}]", ep)
        _insert(cfg, f"{name}/endpoints", list(eps), f"transport.{name}")
    _insert(cfg, "scouting/multicast/enabled", bool(transport.multicast_scouting),
            "transport.multicast_scouting")
    _insert(cfg, "scouting/gossip/enabled", True, "scouting/gossip/enabled")
    _insert(cfg, "scouting/gossip/multihop", False, "scouting/gossip/multihop")
    # two peers that learn of each other by gossip dial each other at once, and with user/password authentication
    # such a crossed open can leave no link: of two listening peers only the greater zenoh id dials (a peer that
    # listens nowhere cannot be dialled: it dials always)
    _insert(cfg, "scouting/gossip/autoconnect_strategy",
            {"peer": {"to_router": "always", "to_peer": "greater-zid" if listen else "always"}},
            "scouting/gossip/autoconnect_strategy")
    # 16 queued tx batches (zenoh's default is 2, 16 its maximum): a stall of zenoh's tx thread fills them before
    # anything is dropped (a loaded 2-core machine does stall for tens of ms)
    _insert(cfg, "transport/link/tx/queue/size/real_time", 16, "transport/link/tx/queue/size/real_time")
    # a batch is never held back waiting for more messages (default 1 ms): what a side published is on the
    # socket at once, so a SIGKILL right after a put loses nothing that was put (tests/integration/test_recorder.py)
    _insert(cfg, "transport/link/tx/queue/batching/time_limit", 0, "transport/link/tx/queue/batching/time_limit")
    # TLS, explicit user/password (teleop/session/link_security.py), or the role's installation credentials
    for k, v in {**link_security_settings(transport), **installation_settings(transport.auth, role)}.items():
        _insert(cfg, k, v, k.replace("/", "."), shown="***" if k.endswith("password") else None)
    return cfg


def free_tcp_ports(n: int, host: str = "127.0.0.1") -> list[int]:
    """``n`` distinct TCP ports free on ``host`` right now (for tests: bind them soon after).

    All sockets are held open together, so the ports are distinct; the OS does not hand a just
    released ephemeral port out again soon, which keeps parallel tests apart.
    """
    socks = []
    try:
        for _ in range(n):
            s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            s.bind((host, 0))
            socks.append(s)
        return [s.getsockname()[1] for s in socks]
    finally:
        for s in socks:
            s.close()


def free_tcp_port(host: str = "127.0.0.1") -> int:
    """One free TCP port on ``host`` (see :func:`free_tcp_ports`)."""
    return free_tcp_ports(1, host)[0]


def accepts_connections(port: int, host: str = "127.0.0.1", timeout: float = 0.2) -> bool:
    """True when a TCP connection to ``host:port`` succeeds within ``timeout`` [s] (a peer listens there)."""
    try:
        with socket.create_connection((host, port), timeout=timeout):
            return True
    except OSError:
        return False


def loopback_endpoint(port: int) -> str:
    """``tcp/127.0.0.1:<port>``."""
    return f"tcp/127.0.0.1:{int(port)}"


#: Session.close waits this long [s] for zenoh's teardown, then leaves it to the exit (a bound, added while the
#: recorder/router test failures of sessions 13-14 were blamed on zenoh; their cause was an ignored SIGINT,
#: see live.cli.run)
CLOSE_TIMEOUT_S = 5.0


class Session:
    """One zenoh session; a context manager. Entities declared through it close with it.

    Parameters
    ----------
    transport : TransportConfig or zenoh.Config
        Built with :func:`zenoh_config` when a TransportConfig.
    clock : Clock, optional
        Receive-time source of the subscribers declared here (default :class:`MonotonicClock`).

    Raises
    ------
    TransportError
        The session could not be opened (e.g. a listen port already in use).

    Attributes
    ----------
    lock_master : bool
        The slave's links on this session accept commands from one master session only
        (``transport.lock_master``; False when built from a bare zenoh.Config).
    refusal_watch : teleop.session.refusal_watch.RefusalWatch or None
        The watch of the connections its listener refused, when a side set one (live/discovery.py).
    """

    def __init__(self, transport: TransportConfig | zenoh.Config, *, clock: Clock | None = None):
        zcfg = zenoh_config(transport) if isinstance(transport, TransportConfig) else transport
        self.lock_master = transport.lock_master if isinstance(transport, TransportConfig) else False
        self.refusal_watch: Any = None
        self.clock = clock or MonotonicClock()
        self._entities: list = []
        self._lock = threading.Lock()
        zenoh.try_init_log_from_env()
        try:
            self._z = zenoh.open(zcfg)
        except zenoh.ZError as e:
            raise TransportError(f"cannot open zenoh session: {zenoh_error_text(e)}") from None
        self._closed = False

    @property
    def zenoh_session(self) -> zenoh.Session:
        """The underlying zenoh session (escape hatch; prefer the typed methods)."""
        return self._z

    @property
    def closed(self) -> bool:
        return self._closed

    def _check_open(self) -> None:
        if self._closed:
            raise TransportError("zenoh session already closed")

    def _track(self, entity):
        with self._lock:
            self._entities.append(entity)
        return entity

    def publisher(self, key: str, *, express: bool = False, priority: zenoh.Priority = zenoh.Priority.REAL_TIME,
                  encoder: Callable[[Any], bytes] = encode) -> Publisher:
        """Declare a :class:`Publisher` on ``key`` (batched only while the link is busy, dropped rather than
        queued without bound when congested: see :class:`Publisher`);
        ``encoder``: another byte format (e.g. :func:`teleop.wire.rig.encode_rig`)."""
        self._check_open()
        return self._track(Publisher(self, key, express=express, priority=priority, encoder=encoder))

    def subscriber(self, key: str, expect: type[M] | None = None, *, decoder: Callable[[bytes], Any] = decode,
                   source_lock=None) -> LatestSubscriber[M]:
        """Declare a :class:`LatestSubscriber` on ``key``; ``expect`` rejects other message types;
        ``decoder``: another byte format (e.g. :func:`teleop.wire.rig.decode_rig`); ``source_lock``: a
        :class:`teleop.session.link_security.SourceLock` admitting one sending session only."""
        self._check_open()
        return self._track(LatestSubscriber(self, key, expect=expect, decoder=decoder, source_lock=source_lock))

    def liveliness_token(self, key: str) -> LivelinessToken:
        """Declare this process alive on ``key`` until the token or the session closes."""
        self._check_open()
        return self._track(LivelinessToken(self, key))

    def liveliness_watcher(self, key: str,
                           on_change: Callable[[str, bool], None] | None = None) -> LivelinessWatcher:
        """Watch the tokens matching ``key`` (already present ones included)."""
        self._check_open()
        return self._track(LivelinessWatcher(self, key, on_change))

    def close(self) -> None:
        """Undeclare every entity, then close the session; returns within CLOSE_TIMEOUT_S [s] whatever
        zenoh does (the teardown goes on in a daemon thread and a warning is logged). Idempotent."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            entities, self._entities = self._entities, []
        done = threading.Event()
        failed: list[BaseException] = []

        def teardown() -> None:
            try:
                for ent in reversed(entities):
                    ent.close()
                self._z.close()
            except zenoh.ZError as e:   # pragma: no cover - zenoh closes cleanly in practice
                log.warning("closing zenoh session: %s", e)
            except BaseException as e:  # noqa: BLE001 - raised again in the caller below
                failed.append(e)
            finally:
                done.set()

        threading.Thread(target=teardown, name="zenoh-close", daemon=True).start()
        if not done.wait(CLOSE_TIMEOUT_S):
            log.warning("the zenoh session did not close within %g s; the process exit ends it", CLOSE_TIMEOUT_S)
        elif failed:
            raise failed[0]

    def __enter__(self) -> Session:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class Publisher(Entity):
    """Publishes messages encoded by :mod:`teleop.wire.codec` on one key. Attribute ``sent``: puts so far.

    Reliable, real-time priority, congestion control DROP (the loop never blocks for long), and not
    ``express`` by default: zenoh then batches only while the link is busy, so at 1 kHz the latency is
    that of express (ping-pong p50 0.12 ms either way, measured) but a burst fills 16 queued batches of
    many messages instead of 16 messages (100 000 puts in a tight loop: all delivered; express: 34-48 %
    dropped). With the batching time limit at 0 (:func:`zenoh_config`) nothing waits for a batch to
    fill. That is what makes the recorder lose nothing when a side's tx thread stalls; what a SIGKILL
    catches still queued in the process is kept by the side's journal (:mod:`teleop.recording.journal`), written
    before the put.
    """

    def __init__(self, session: Session, key: str, *, express: bool = False,
                 priority: zenoh.Priority = zenoh.Priority.REAL_TIME, encoder: Callable[[Any], bytes] = encode):
        super().__init__(session, key)
        self.sent = 0
        self.encoder = encoder
        self._declare(session.zenoh_session.declare_publisher, key, express=express, priority=priority,
                      congestion_control=zenoh.CongestionControl.DROP, reliability=zenoh.Reliability.RELIABLE)
        self._source = zenoh.SourceInfo(self._handle.id, 0)   # receivers can tell the sending session

    def put(self, msg: Message) -> None:
        """Encode and send ``msg`` (journaled first when this process has a journal: :mod:`teleop.recording.journal`).

        Raises
        ------
        CodecError
            ``msg`` cannot be encoded (non-finite float, ...): a bug of the sender.
        TransportError
            The publisher or its session is closed.
        """
        payload = self.encoder(msg)
        if PUBLISH_LOG is not None:       # test-only oracle: TELEOP_PUBLISH_LOG names a file
            PUBLISH_LOG.begin(self.key, msg, payload)
        self.put_bytes(payload)
        if PUBLISH_LOG is not None:
            PUBLISH_LOG.done(self.key, msg)

    def put_bytes(self, payload: bytes) -> None:
        """Send raw bytes (tests and tools only: receivers expect codec payloads); journaled first."""
        if self._closed or self.session.closed:
            raise TransportError(f"publisher on {self.key!r} is closed")
        j = journal.JOURNAL
        if j is not None:                 # before zenoh: what a SIGKILL catches in zenoh's queue is kept
            j.append(self.key, payload)
        try:
            self._handle.put(payload, source_info=self._source)
        except zenoh.ZError as e:
            raise TransportError(f"put on {self.key!r} failed: {zenoh_error_text(e)}") from None
        self.sent += 1


class Received(NamedTuple, Generic[M]):
    """A decoded message and when it arrived [s, the subscriber's clock]."""

    message: M
    t_recv: float


class LatestSubscriber(Entity, Generic[M]):
    """Keeps only the newest decoded message on a key (latest wins), thread-safe.

    Attributes
    ----------
    count : int
        Messages decoded and kept.
    errors : int
        Payloads that did not decode (or were of another type than ``expect``); never raised.
    """

    def __init__(self, session: Session, key: str, *, expect: type[M] | None = None,
                 decoder: Callable[[bytes], Any] = decode, source_lock=None):
        super().__init__(session, key)
        self.expect = expect
        self.decoder = decoder
        self.source_lock = source_lock      # SourceLock: samples of other sessions are dropped (counted there)
        self.clock = session.clock
        self.count = 0
        self.errors = 0
        self._latest: Received[M] | None = None
        self._cond = threading.Condition()
        self._log = RateLimitedLog(log, 1.0, self.clock)
        self._declare(session.zenoh_session.declare_subscriber, key, self._on_sample)

    def _on_sample(self, sample: zenoh.Sample) -> None:
        if self.source_lock is not None and not self.source_lock.admit(sample):
            self._log.warning("dropped a message on %s from another session than the admitted one "
                              "(transport.lock_master; counted as foreign_source)", self.key)
            return
        try:
            msg = self.decoder(sample.payload.to_bytes())
            if self.expect is not None and type(msg) is not self.expect:
                raise CodecError(f"got a {type(msg).__name__}, expected a {self.expect.__name__}")
        except Exception as e:  # noqa: BLE001 - a bad payload must never kill the zenoh callback
            with self._cond:
                self.errors += 1
                self._cond.notify_all()
            self._log.warning("dropped a bad message on %s: %s", self.key, e)
            return
        rec = Received(msg, self.clock.now())
        with self._cond:
            self._latest = rec
            self.count += 1
            self._cond.notify_all()

    def latest(self) -> Received[M] | None:
        """The newest message with its receive time, or None before the first one."""
        with self._cond:
            return self._latest

    def age(self, now: float) -> float:
        """Time since the newest message arrived [s] (``now`` from the same clock); inf if none."""
        rec = self._latest
        return math.inf if rec is None else now - rec.t_recv

    def wait(self, count: int = 1, timeout: float | None = None) -> bool:
        """Block until ``self.count >= count`` or ``timeout`` [s] of real time; True if reached."""
        with self._cond:
            return self._cond.wait_for(lambda: self.count >= count, timeout)

    def wait_errors(self, errors: int = 1, timeout: float | None = None) -> bool:
        """Block until ``self.errors >= errors`` or ``timeout`` [s]; True if reached."""
        with self._cond:
            return self._cond.wait_for(lambda: self.errors >= errors, timeout)

    def close(self) -> None:
        super().close()
        with self._cond:
            self._cond.notify_all()
