"""The listening side's record of refused connections: each one logged once, rate-limited.

Zenoh refuses a peer with a wrong user/password or an untrusted certificate inside its link
establishment and tells the application nothing. What the listening process can observe is the kernel's
table of its TCP sockets (Linux: ``/proc/net/tcp``, ``/proc/net/tcp6``): a connection the listener closed
itself stays in ``TIME_WAIT`` for a minute afterwards. :class:`RefusalWatch` polls that table for sockets
on its listen ports in ``TIME_WAIT`` whose remote end never became a Zenoh link (zenoh's link events
name every accepted link's remote address), and logs each such connection once, through a
:class:`~teleop.entity.RateLimitedLog`. A connection the peer closed first (a port probe, a peer that
gave up) leaves no ``TIME_WAIT`` on this side and is not reported; a link that came up is never reported.

Limits: which end closes a refused link first is a race between the two processes (zenoh sends its
refusal, then both drop the socket); when the connector wins it, that attempt leaves nothing here.
Zenoh retries a refused connect about once a second, so a persistent mistake is still reported within
seconds; a single attempt may not be.
"""
from __future__ import annotations

import logging
import socket
import struct
import threading
from pathlib import Path

from teleop.entity import Entity, RateLimitedLog
from teleop.peer_probe import split_endpoint

__all__ = ["RefusalWatch", "time_wait_remotes"]

log = logging.getLogger("teleop.refusals")
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
    session : teleop.transport.Session
    listen : iterable of str
        Endpoints this session listens on (``tcp/...``, ``tls/...``; others and port 0 are skipped).
    interval : float
        Poll period [s].
    log_interval : float
        At most one log record per this many seconds [s] (the rest counted as suppressed).
    """

    def __init__(self, session, listen, interval: float = 0.5, log_interval: float = 5.0):
        super().__init__(session, "refusals")
        self.ports = set()
        for ep in listen:
            try:
                proto, _, port = split_endpoint(ep)
            except ValueError:
                continue
            if proto in ("tcp", "tls") and port:
                self.ports.add(port)
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
            self._log.warning("refused a connection from %s:%d on port %d: it closed before a Zenoh session came "
                              "up (wrong transport.auth user/password or certificate, another deployment, or not a "
                              "Zenoh peer)", rip, rport, lport)
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
