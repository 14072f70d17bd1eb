"""The listening side's record of refused connections: each one logged once, rate-limited.

Zenoh refuses a peer with a wrong user/password or an untrusted certificate inside its link
establishment and tells the application nothing. What the listening process can observe is the kernel's
table of its TCP sockets (Linux: ``/proc/net/tcp``, ``/proc/net/tcp6``): a connection the listener closed
itself stays in ``TIME_WAIT`` for a minute afterwards. :class:`RefusalWatch` polls that table for sockets
on its listen ports in ``TIME_WAIT`` whose remote end never became a Zenoh link (zenoh's link events
name every accepted link's remote address), and logs each such connection once, through a
:class:`~teleop.session.entity.RateLimitedLog` (a peer that retries every second gives one line per ``log_interval``,
with the count of those suppressed), with the causes a listener on that port's protocol refuses
(:data:`CAUSES`): which one it was, only the connecting side can tell (:mod:`teleop.session.peer_probe`), or
zenoh's own log on stdout (``RUST_LOG=zenoh_link_tls=warn,zenoh_transport::unicast::establishment=debug``).
A connection the peer closed first (a port probe, a peer that gave up) leaves no ``TIME_WAIT`` on this
side and is not reported; a link that came up is never reported.

Limits: which end closes a refused link first is a race between the two processes (zenoh sends its
refusal, then both drop the socket); when the connector wins it, that attempt leaves nothing here.
Zenoh retries a refused connect about once a second, so a persistent mistake is still reported within
seconds; a single attempt may not be. A TLS handshake zenoh refuses to another zenoh (a client certificate
of another CA, none, plain TCP) ends in a reset, as the connector has sent more than the listener read,
and a reset leaves no ``TIME_WAIT``: what is seen of those is the probe a refused teleop side makes of the
endpoint (:func:`teleop.session.peer_probe.probe_endpoint`), which the listener closes.
"""
from __future__ import annotations

import logging
import socket
import struct
import threading
from pathlib import Path

from teleop.session.entity import Entity, RateLimitedLog
from teleop.session.peer_probe import split_endpoint

__all__ = ["CAUSES", "RefusalWatch", "time_wait_remotes"]

log = logging.getLogger("teleop.refusals")
#: What a listener on each protocol refuses before a Zenoh session comes up, as the listening side can only
#: list it: zenoh does not tell the application which it was (the connecting side's probe does,
#: :mod:`teleop.session.peer_probe`).
CAUSES = {"tls": "a client certificate missing or not signed by transport.tls.root_ca (mutual TLS), a tcp/ "
                 "endpoint pointed at this TLS port, or a wrong transport.auth user/password",
          "tcp": "a wrong transport.auth user/password, a tls/ endpoint pointed at this plain TCP port, or not a Zenoh "
                 "peer"}
_TIME_WAIT = "06"
_TABLES = (Path("/proc/net/tcp"), Path("/proc/net/tcp6"))


def _address(hexaddr: str) -> tuple[str, int]:
    """``0100007F:1D27`` (kernel byte order per 32-bit word) -> ("127.0.0.1", 7463)."""
    ip_hex, port_hex = hexaddr.split(":")
    raw = b"".join(struct.pack("<I", int(ip_hex[i:i + 8], 16)) for i in range(0, len(ip_hex), 8))
    if len(raw) == 4:
        return socket.inet_ntop(socket.AF_INET, raw), int(port_hex, 16)
    if raw[:12] == b"\0" * 10 + b"\xff\xff":       # IPv4-mapped IPv6
        return socket.inet_ntop(socket.AF_INET, raw[12:]), int(port_hex, 16)
    return socket.inet_ntop(socket.AF_INET6, raw), int(port_hex, 16)


def time_wait_remotes(ports, tables=_TABLES) -> set[tuple[str, int, int]]:
    """``(remote ip, remote port, local port)`` of every TCP socket in TIME_WAIT on one of ``ports``;
    empty where the kernel has no such table (not Linux)."""
    out = set()
    for table in tables:
        try:
            lines = table.read_text().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            f = line.split()
            if len(f) > 3 and f[3] == _TIME_WAIT:
                local, remote = _address(f[1]), _address(f[2])
                if local[1] in ports:
                    out.add((remote[0], remote[1], local[1]))
    return out


class RefusalWatch(Entity):
    """Poll for refused connections on the TCP/TLS ``listen`` endpoints of ``session`` (module docstring).

    Parameters
    ----------
    session : teleop.session.transport.Session
    listen : iterable of str
        Endpoints this session listens on (``tcp/...``, ``tls/...``; others and port 0 are skipped).
    interval : float
        Poll period [s].
    log_interval : float
        At most one log record per this many seconds [s] (the rest counted as suppressed).
    """

    def __init__(self, session, listen, interval: float = 0.5, log_interval: float = 5.0):
        super().__init__(session, "refusals")
        self.ports: dict[int, str] = {}           # port -> its protocol (tcp, tls)
        for ep in listen:
            try:
                proto, _, port = split_endpoint(ep)
            except ValueError:
                continue
            if proto in ("tcp", "tls") and port:
                self.ports[port] = proto
        self.refused = 0
        self._linked: set[tuple[str, int]] = set()
        self._reported: set[tuple[str, int, int]] = set()
        self._log = RateLimitedLog(log, log_interval)
        self._stop = threading.Event()
        self._declare(session.zenoh_session.info.declare_link_events_listener, self._on_link)
        self._known = time_wait_remotes(self.ports)           # closed before this process listened
        self._thread = threading.Thread(target=self._run, args=(interval,), name="refusal-watch", daemon=True)
        if self.ports:
            self._thread.start()

    def _on_link(self, event) -> None:
        try:
            _, host, port = split_endpoint(str(event.link.dst))
            self._linked.add((host, port))
        except Exception:  # noqa: BLE001 - never let an exception escape a zenoh callback
            pass

    def poll(self) -> int:
        """One look at the socket table; returns the connections newly found refused."""
        new = 0
        current = time_wait_remotes(self.ports)
        self._known &= current                     # TIME_WAIT ends after a minute: the sets stay small
        self._reported &= current
        for rip, rport, lport in current - self._known - self._reported:
            self._reported.add((rip, rport, lport))
            if (rip, rport) in self._linked:
                continue
            new += 1
            self.refused += 1
            proto = self.ports.get(lport, "tcp")
            self._log.warning("refused a connection from %s:%d on %s port %d: it closed before a Zenoh session came "
                              "up: %s; the connecting process's error line names which", rip, rport, proto.upper(),
                              lport, CAUSES[proto])
        return new

    def _run(self, interval: float) -> None:
        while not self._stop.wait(interval):
            try:
                self.poll()
            except Exception as e:  # noqa: BLE001 - a diagnostic must never take the process down
                log.debug("refusal watch: %s", e)

    def close(self) -> None:
        """Stop polling and undeclare the link listener. Idempotent."""
        self._stop.set()
        super().close()
