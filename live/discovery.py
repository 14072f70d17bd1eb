"""Bare start: processes of one session find each other on loopback and share one run id.

``teleop slave`` and ``teleop master`` (and ``teleop record``) started without ``--listen`` or
``--connect`` in two terminals, in either order:

1. **Who listens** (:func:`open_auto_session`): the first process opens the configured
   ``transport.listen`` endpoints (default ``tcp/127.0.0.1:7447``). A later one finds the port taken
   ("Address already in use"), connects to those endpoints instead and listens on an ephemeral port
   of the same kind (``tcp/127.0.0.1:0``), so that gossip scouting lets a third process (the
   recorder) open a direct link to it too. Flags, ``transport.auto_connect: false``, a client or an
   empty listen list: the configured endpoints as they are (a router deployment).
2. **Which run** (:func:`agree_run_id`): every process answers the query ``teleop/<id>/run`` with its
   run id. The one that got the port (or was given ``--run-dir``) makes the id, a timestamp; one that
   connected asks its peers for up to ``transport.run_id_timeout`` seconds and takes their answer.
   All of them then write into ``<recording.dir>/<run id>/`` (different file names per process).

Two processes started within the same instant with nobody listening beforehand can still pick two
ids (each asks, nobody has one yet); the listener rule makes that impossible on one machine.
"""
from __future__ import annotations

import logging
import os
import re
import socket
import time
from pathlib import Path

import zenoh

from teleop.config.schema import Config
from teleop.errors import ConfigError, TransportError
from teleop.session.entity import Entity, zenoh_error_text
from teleop.session.peer_probe import no_peer_reason
from teleop.session.transport import Session, zenoh_config
from teleop.wire.keys import run_key

__all__ = ["RunIdServer", "RoleServer", "claim_role", "agree_run_id", "new_run_id", "open_auto_session", "side_run_dir",
           "side_session"]

log = logging.getLogger("live.discovery")
_RUN_ID = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]{0,127}")
_IN_USE = ("Address already in use", "os error 98", "AddrInUse")


def _with_port(endpoint: str, port: int) -> str:
    head, sep, _ = endpoint.rpartition(":")
    if not sep or "/" not in head:
        raise TransportError(f"transport.listen: {endpoint!r} has no port to replace")
    return f"{head}:{int(port)}"


def _describe(listen, connect) -> str:
    return f"listen: {', '.join(listen) or 'none'}; connect: {', '.join(connect) or 'none'}"


def _can_listen_tls(cfg: Config) -> bool:
    return bool(cfg.transport.tls.certificate and cfg.transport.tls.private_key)


#: The credentials role (teleop/session/credentials.py) of each ``teleop`` command that opens a session.
COMMAND_ROLES = {"slave": "slave", "master": "master", "bridge": "rig", "calibrate": "slave", "record": "observer",
                 "router": "observer"}


def credentials_role(args) -> str | None:
    """The credentials role of the process running ``args``: its ``teleop`` command's (observer for a command
    not in :data:`COMMAND_ROLES`), None for arguments of no command (a library caller: no credentials)."""
    command = getattr(args, "command", None)
    return None if command is None else COMMAND_ROLES.get(command, "observer")


def _open(cfg: Config, listen, connect, clock, role: str | None) -> Session:
    tls_listen = [ep for ep in listen if ep.startswith("tls/")]
    if tls_listen and not _can_listen_tls(cfg):
        raise ConfigError(f"transport.listen: {tls_listen[0]!r} needs transport.tls.certificate and private_key (a "
                          f"TLS listener presents them; a connector needs only root_ca: --connect {tls_listen[0]})")
    try:
        return Session(zenoh_config(cfg.transport, listen=tuple(listen), connect=tuple(connect), role=role),
                       clock=clock)
    except TransportError as e:
        raise TransportError(f"{e} ({_describe(listen, connect)})") from None


def open_auto_session(cfg: Config, listen: tuple[str, ...] | None = None, connect: tuple[str, ...] | None = None,
                      clock=None, credentials: str | None = None) -> tuple[Session, str]:
    """Open this process's session (module docstring, step 1).

    Parameters
    ----------
    cfg : Config
        ``transport`` (mode, listen, connect, auto_connect, auth, tls).
    listen, connect : tuple of str, optional
        The ``--listen``/``--connect`` flags (either given: used as they are, no automatic choice).
    clock : Clock, optional
    credentials : str, optional
        The process's credentials role (:data:`COMMAND_ROLES`; None: no installation credentials).

    Returns
    -------
    (Session, role)
        ``role`` is ``"listening"`` (got the configured port), ``"connected"`` (the port was taken:
        connected to it) or ``"configured"`` (endpoints used as given).

    Raises
    ------
    TransportError
        The session cannot be opened (message names the endpoints tried).
    """
    t = cfg.transport
    if listen is not None or connect is not None:
        return _open(cfg, listen or (), connect or (), clock, credentials), "configured"
    if not t.auto_connect or t.mode != "peer" or not t.listen:
        return _open(cfg, t.listen, t.connect, clock, credentials), "configured"
    if any(ep.startswith("tls/") for ep in t.listen) and not _can_listen_tls(cfg):
        # no certificate of its own: this process cannot listen on TLS, it can only connect to the listener
        log.info("%s: no transport.tls.certificate to listen with: connecting to it", ", ".join(t.listen))
        return _open(cfg, (), tuple(t.listen) + tuple(t.connect), clock, credentials), "connected"
    try:
        return _open(cfg, t.listen, t.connect, clock, credentials), "listening"
    except TransportError as e:
        if not any(s in str(e) for s in _IN_USE):
            raise
    ephemeral = tuple(_with_port(ep, 0) for ep in t.listen)
    log.info("%s in use: connecting to it", ", ".join(t.listen))
    return _open(cfg, ephemeral, tuple(t.listen) + tuple(t.connect), clock, credentials), "connected"


def new_run_id(base: str | Path) -> str:
    """A fresh ``YYYYmmdd-HHMMSS[-n]`` id with no directory of that name in ``base`` yet."""
    stamp = time.strftime("%Y%m%d-%H%M%S")
    rid, n = stamp, 1
    while (Path(base) / rid).exists():
        rid, n = f"{stamp}-{n}", n + 1
    return rid


class RunIdServer(Entity):
    """Answers queries on ``teleop/<id>/run`` with this process's run id (UTF-8)."""

    def __init__(self, session: Session, instrument: str, run_id: str):
        super().__init__(session, run_key(instrument))
        self.run_id = run_id
        self._declare(session.zenoh_session.declare_queryable, self.key, self._on_query)

    def _on_query(self, query: zenoh.Query) -> None:
        try:
            query.reply(self.key, self.run_id.encode())
        except zenoh.ZError as e:   # pragma: no cover - the querier went away
            log.debug("run id reply failed: %s", zenoh_error_text(e))


def ask_run_id(session: Session, instrument: str, timeout: float) -> str | None:
    """The run id a peer answers on ``teleop/<id>/run`` within ``timeout`` [s], or None."""
    deadline = time.monotonic() + timeout
    key = run_key(instrument)
    while True:
        left = deadline - time.monotonic()
        if left <= 0:
            return None
        for reply in session.zenoh_session.get(key, timeout=max(0.05, min(0.5, left))):
            if reply.ok is not None:
                rid = reply.ok.payload.to_bytes().decode("utf-8", "replace")
                if _RUN_ID.fullmatch(rid) and ".." not in rid:
                    return rid
                log.warning("ignored a malformed run id %r from a peer", rid)
        time.sleep(0.05)


def agree_run_id(session: Session, cfg: Config, role: str, given: str | None = None) -> str:
    """The run id of this process, served on ``teleop/<id>/run`` from now on (module docstring, step 2).

    Parameters
    ----------
    session : Session
    cfg : Config
        ``instrument.id``, ``recording.dir``, ``transport.run_id_timeout`` [s].
    role : str
        From :func:`open_auto_session`; ``"listening"`` makes a new id without asking.
    given : str, optional
        An id fixed by the caller (the name of ``--run-dir``): served, never asked for.
    """
    ident = cfg.instrument.id
    rid = given
    if rid is None and role != "listening":
        rid = ask_run_id(session, ident, cfg.transport.run_id_timeout)
        if rid is not None:
            log.info("joined run %s", rid)
        elif session.zenoh_session.info.peers_zid():
            rid = new_run_id(cfg.recording.dir)
            log.warning("connected to a Zenoh peer, but none answered the run id of instrument %r within %g s: the "
                        "peers serve another instrument.id or are not teleop sides; this process starts run %s alone",
                        ident, cfg.transport.run_id_timeout, rid)
    if rid is None:
        rid = new_run_id(cfg.recording.dir)
    session._track(RunIdServer(session, ident, rid))
    return rid


class RoleServer(Entity):
    """Answers queries on ``teleop/<id>/run/<role>`` with who plays ``role``: ``process <pid> on <host>
    (run <run id>)``, so that a second process of the same role can name the one it would collide with."""

    def __init__(self, session: Session, instrument: str, role: str, run_id: str):
        super().__init__(session, f"{run_key(instrument)}/{role}")
        self.holder = f"process {os.getpid()} on {socket.gethostname()} (run {run_id})"
        self._declare(session.zenoh_session.declare_queryable, self.key, self._on_query)

    def _on_query(self, query: zenoh.Query) -> None:
        try:
            query.reply(self.key, self.holder.encode())
        except zenoh.ZError as e:   # pragma: no cover - the querier went away
            log.debug("role reply failed: %s", zenoh_error_text(e))


#: [s] how long a starting side asks whether a peer already plays its role
ROLE_QUERY_S = 0.5


def claim_role(session: Session, cfg: Config, role: str, run_id: str, timeout: float = ROLE_QUERY_S) -> None:
    """Serve ``role`` of this instrument from now on, unless a peer already plays it.

    Raises
    ------
    TransportError
        A reachable peer already plays ``role`` for ``instrument.id``: one line naming the run and the
        process (pid, host, its run).
    """
    ident = cfg.instrument.id
    key = f"{run_key(ident)}/{role}"
    for reply in session.zenoh_session.get(key, timeout=timeout):
        if reply.ok is not None:
            holder = reply.ok.payload.to_bytes().decode("utf-8", "replace")[:200]
            raise TransportError(f"run {run_id} already has a {role} of instrument {ident!r}: {holder}; stop it "
                                 f"first, or give this {role} another instrument.id or endpoint")
    session._track(RoleServer(session, ident, role, run_id))


#: [s] a connecting process expects a peer this soon; then it probes the endpoints and says why not
PEER_WAIT_S = 1.5


def wait_for_peer(session: Session, endpoints, tls, wait: float = PEER_WAIT_S) -> None:
    """Return once ``session`` has a peer or router; after ``wait`` [s] without one, probe ``endpoints``
    (:func:`teleop.session.peer_probe.no_peer_reason`): where nothing listens yet, warn and go on (the peer may
    start later); where a listener refused this process or is not a Zenoh peer, raise.

    Raises
    ------
    TransportError
        One line: what answered at each endpoint and the most likely reason no peer came.
    """
    if not endpoints:
        return
    info = session.zenoh_session.info
    deadline = time.monotonic() + wait
    while not (info.peers_zid() or info.routers_zid()):
        if time.monotonic() >= deadline:
            line, may_come = no_peer_reason(endpoints, tls, wait)
            if info.peers_zid() or info.routers_zid():      # came while probing
                return
            if may_come:
                log.warning("%s; still trying", line)
                return
            raise TransportError(line)
        time.sleep(0.02)


# ---- the hooks of `teleop slave|master|record` (live/sides.py, live/record/recorder.py) ----------------

_ATTR = "_teleop_session"


def side_session(cfg: Config, args, clock=None) -> Session:
    """The session of a side process: the one :func:`side_run_dir` opened (its clock set to ``clock``),
    else a new one (:func:`open_auto_session` with the ``--listen``/``--connect`` flags)."""
    session = getattr(args, _ATTR, None)
    if session is not None and not session.closed:
        if clock is not None:
            session.clock = clock
        return session
    listen = None if getattr(args, "listen", None) is None and getattr(args, "connect", None) is None else \
        tuple(args.listen or ())
    connect = None if listen is None else tuple(args.connect or ())
    session, role = open_auto_session(cfg, listen, connect, clock, credentials_role(args))
    endpoints = tuple(cfg.transport.listen) + tuple(cfg.transport.connect) if role == "connected" else \
        (tuple(cfg.transport.connect) if connect is None else connect)
    try:
        wait_for_peer(session, endpoints, cfg.transport.tls)
    except TransportError:
        session.close()          # refused: nothing declared, no runtime left to wait for at exit
        raise
    session.lock_master = cfg.transport.lock_master     # read by live.sides when declaring the slave's links
    listening = tuple(cfg.transport.listen) if listen is None and role != "connected" else (listen or ())
    if listening:                                        # each refused connection logged once, rate-limited
        from teleop.session.refusal_watch import RefusalWatch
        session.refusal_watch = session._track(RefusalWatch(session, listening))   # counted in the side's stats
    setattr(args, _ATTR, session)
    args._teleop_role = role
    return session


def side_run_dir(args, cfg: Config, role: str | None = None) -> Path:
    """Open the side's session now (:func:`side_session`), agree the run id, claim ``role`` (``slave``,
    ``master``: :func:`claim_role`; None: no role), create and return the run directory: ``--run-dir``
    when given, else ``<recording.dir>/<agreed id>``.

    Raises
    ------
    TransportError
        The session cannot be opened, or a peer already plays ``role``.
    """
    session = side_session(cfg, args)
    given = Path(args.run_dir).name if getattr(args, "run_dir", None) else None
    rid = agree_run_id(session, cfg, getattr(args, "_teleop_role", "configured"), given)
    if role is not None:
        try:
            claim_role(session, cfg, role, rid)
        except TransportError:
            session.close()      # refused: leave nothing declared and no runtime to wait for at exit
            raise
    run_dir = Path(args.run_dir) if given else Path(cfg.recording.dir) / rid
    run_dir.mkdir(parents=True, exist_ok=True)
    return run_dir
