"""The installation's credentials (teleop/session/credentials.py): files made once and private, and Zenoh's own
authentication and access control on loopback refusing a process without them and a role putting another's keys."""
from __future__ import annotations

import multiprocessing
import os
import stat
import time

import pytest

from teleop.config.schema import TransportConfig
from teleop.errors import ConfigError
from teleop.session.credentials import ROLES, access_control, ensure_credentials, renew_credentials
from teleop.session.transport import Session, free_tcp_port, loopback_endpoint, zenoh_config
from tests.zenoh_peer import raw_peer


def _make(folder: str) -> str:
    return ensure_credentials("master", folder).password_file.read_text()


def test_made_once_private_and_the_same_for_processes_starting_together(tmp_path):
    folder = tmp_path / "keys"
    with multiprocessing.get_context("spawn").Pool(4) as pool:
        passwords = pool.map(_make, [str(folder)] * 4)
    assert len(set(passwords)) == 1
    assert stat.S_IMODE(folder.stat().st_mode) == 0o700
    for role in ROLES:
        assert stat.S_IMODE((folder / f"{role}.password").stat().st_mode) == 0o600
    lines = (folder / "dictionary").read_text().splitlines()
    assert [ln.split(":")[0] for ln in lines] == list(ROLES) and len({ln.split(":")[1] for ln in lines}) == len(ROLES)
    assert [f.name for f in tmp_path.iterdir()] == ["keys"]          # no temporary folder left behind
    renew_credentials(folder)
    assert ensure_credentials("master", folder).password_file.read_text() != passwords[0]


def test_a_folder_open_to_other_users_or_an_unknown_role_is_refused(tmp_path):
    folder = tmp_path / "keys"
    ensure_credentials("slave", folder)
    os.chmod(folder, 0o755)
    with pytest.raises(ConfigError, match="open to other users"):
        ensure_credentials("slave", folder)
    os.chmod(folder, 0o700)
    with pytest.raises(ConfigError, match="unknown role"):
        ensure_credentials("surgeon", folder)
    (folder / "rig.password").unlink()
    with pytest.raises(ConfigError, match="rig.password: missing"):
        ensure_credentials("slave", folder)


def test_the_rules_deny_each_role_the_keys_of_the_others():
    acl = access_control()
    subjects = {s["id"]: set(s["usernames"]) for s in acl["subjects"]}
    assert acl["default_permission"] == "allow" and subjects["not_master"] == {"slave", "rig", "observer"}
    rules = {r["id"]: r for r in acl["rules"]}
    assert "teleop/*/master/**" in rules["master_owned"]["key_exprs"]
    assert set(rules["master_owned"]["messages"]) >= {"put", "liveliness_token"}
    assert all(r["permission"] == "deny" and r["flows"] == ["ingress"] for r in rules.values())


def test_zenoh_refuses_a_process_without_credentials_and_a_role_putting_the_masters_keys(tmp_path, monkeypatch):
    monkeypatch.setenv("TSM_TELEOP_KEYS", str(tmp_path / "keys"))
    ep = loopback_endpoint(free_tcp_port())
    got: list[bytes] = []
    with Session(zenoh_config(TransportConfig(listen=(ep,), connect=()), role="slave")) as slave:
        slave.zenoh_session.declare_subscriber("teleop/x/master/command", lambda s: got.append(s.payload.to_bytes()))
        pw = {r: (tmp_path / "keys" / f"{r}.password").read_text().strip() for r in ROLES}
        peers = {}
        for who, user, password in (("anonymous", None, None), ("wrong password", "master", "guess"),
                                    ("observer", "observer", pw["observer"]), ("rig", "rig", pw["rig"]),
                                    ("master", "master", pw["master"])):
            z = raw_peer(ep, user, password)
            deadline = time.monotonic() + 2.0
            while not list(z.info.peers_zid()) and time.monotonic() < deadline and user == who:
                time.sleep(0.02)
            time.sleep(0.3)
            peers[who] = bool(list(z.info.peers_zid()))
            z.put("teleop/x/master/command", who.encode())
            time.sleep(0.3)
            z.close()
    assert peers == {"anonymous": False, "wrong password": False, "observer": True, "rig": True, "master": True}
    assert got == [b"master"]
