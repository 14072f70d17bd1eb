"""A bare Zenoh peer for the tests that play a process outside the project (a hostile peer, a foreign client)."""
from __future__ import annotations

import json

import zenoh

from teleop.session.credentials import ensure_credentials


def raw_peer(endpoints: str | list[str], user: str | None = None, password: str | None = None, *,
             role: str | None = None) -> zenoh.Session:
    """A Zenoh peer connecting to ``endpoints`` (listening nowhere, no multicast), authenticating as ``user`` with
    ``password``, or with the installation's credentials of ``role``, or not at all."""
    conf = zenoh.Config()
    eps = [endpoints] if isinstance(endpoints, str) else list(endpoints)
    for k, v in (("mode", "peer"), ("connect/endpoints", eps), ("listen/endpoints", []),
                 ("scouting/multicast/enabled", False)):
        conf.insert_json5(k, json.dumps(v))
    if role is not None:
        user, password = role, ensure_credentials(role).password_file.read_text(encoding="utf-8").strip()
    if user is not None:
        conf.insert_json5("transport/auth/usrpwd/user", json.dumps(user))
        conf.insert_json5("transport/auth/usrpwd/password", json.dumps(password))
    return zenoh.open(conf)
