"""``teleop router``: a Zenoh router (mode ``router``) that master, slave and recorder on different
machines connect to with a config change only (``transport: {mode: client, connect: [tcp/<router>:7447],
listen: []}``; peers work too).

It listens on ``--listen`` (else ``transport.listen``), applies ``transport.auth`` (its
``dictionary_file`` says who may connect) and ``transport.tls``, keeps multicast scouting as
configured (off by default), and runs until Ctrl-C, SIGTERM or ``--max-duration``.
"""
from __future__ import annotations

import json
import logging
import time

__all__ = ["router_config", "run_router"]

log = logging.getLogger("live.router")


def router_config(cfg, listen: tuple[str, ...] | None = None, role: str | None = None):
    """The zenoh.Config of a router on ``listen`` (default ``cfg.transport.listen``), auth/TLS included; with
    ``role`` (``teleop router``: observer) the installation's credentials and access control
    (:func:`teleop.session.transport.zenoh_config`).

    Raises
    ------
    ConfigError
        An endpoint or security setting zenoh rejects (named).
    """
    from teleop.session.transport import zenoh_config
    zcfg = zenoh_config(cfg.transport, listen=tuple(cfg.transport.listen if listen is None else listen), connect=(),
                        role=role)
    zcfg.insert_json5("mode", json.dumps("router"))
    return zcfg


def run_router(args) -> int:
    """``teleop router``: open the router, print where it listens, serve until stopped."""
    from live.discovery import credentials_role
    from teleop.config.load import load_config
    from teleop.recording.measured import raise_on_sigterm
    from teleop.session.transport import Session

    cfg = load_config(args.config)
    listen = tuple(args.listen) if args.listen else None
    with raise_on_sigterm(), Session(router_config(cfg, listen, role=credentials_role(args))) as session:
        eps = ", ".join(listen or cfg.transport.listen)
        print(f"teleop router: {session.zenoh_session.zid()} listening on {eps} (ready)", flush=True)
        t0 = time.monotonic()
        while args.max_duration is None or time.monotonic() - t0 < args.max_duration:
            time.sleep(0.1)
    return 0
