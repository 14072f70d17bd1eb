"""Bare start: the first session listens, the next ones find the port taken and connect, and all of them
agree one run id over zenoh. Real sessions in this process on a free 127.0.0.1 port; waits bounded."""
from __future__ import annotations

import argparse
import re

import pytest

from live.discovery import agree_run_id, ask_run_id, open_auto_session, side_run_dir, side_session
from teleop.config.load import config_from_dict
from teleop.config.schema import Config
from teleop.errors import TransportError
from teleop.session.transport import free_tcp_port


def _cfg(tmp_path, port: int, **transport) -> Config:
    return config_from_dict({"instrument": {"id": "disc"}, "recording": {"dir": str(tmp_path / "runs")},
                             "transport": {"listen": [f"tcp/127.0.0.1:{port}"], "run_id_timeout": 5.0, **transport}})


def test_first_listens_second_connects_and_both_share_the_run_id(tmp_path):
    cfg = _cfg(tmp_path, free_tcp_port())
    first, role1 = open_auto_session(cfg)
    try:
        second, role2 = open_auto_session(cfg)
        third, role3 = open_auto_session(cfg)
        try:
            assert (role1, role2, role3) == ("listening", "connected", "connected")
            rid = agree_run_id(first, cfg, role1)
            assert re.fullmatch(r"\d{8}-\d{6}(-\d+)?", rid), rid                # a timestamp
            assert agree_run_id(second, cfg, role2) == rid
            assert agree_run_id(third, cfg, role3) == rid            # answered by either peer
            # the two connectors see each other directly too (each listens on an ephemeral port; gossip)
            peers = {str(z) for z in third.zenoh_session.info.peers_zid()}
            assert {str(first.zenoh_session.zid()), str(second.zenoh_session.zid())} <= peers
        finally:
            third.close()
            second.close()
    finally:
        first.close()


def test_given_run_dir_is_served_and_nobody_answering_makes_a_new_id(tmp_path):
    port = free_tcp_port()
    cfg = _cfg(tmp_path, port, auto_connect=False, run_id_timeout=0.3)
    args = argparse.Namespace(listen=None, connect=None, run_dir=str(tmp_path / "given" / "run-7"))
    with side_session(cfg, args):
        assert side_session(cfg, args) is side_session(cfg, args)   # one session per process
        run_dir = side_run_dir(args, cfg)
        assert run_dir == tmp_path / "given" / "run-7" and run_dir.is_dir()
        other = _cfg(tmp_path, port)
        with open_auto_session(other)[0] as s:
            assert ask_run_id(s, "disc", 5.0) == "run-7"
    with open_auto_session(cfg)[0] as alone:                      # nobody to ask: a fresh id after the timeout
        rid = agree_run_id(alone, cfg, "configured")
        assert rid and not (tmp_path / "runs" / rid).exists()


def test_flags_are_used_as_given_and_a_port_in_use_names_the_endpoints(tmp_path):
    port = free_tcp_port()
    cfg = _cfg(tmp_path, port)
    with open_auto_session(cfg)[0]:
        with pytest.raises(TransportError, match=rf"Address already in use.*listen: tcp/127.0.0.1:{port}"):
            open_auto_session(cfg, listen=(f"tcp/127.0.0.1:{port}",), connect=())
