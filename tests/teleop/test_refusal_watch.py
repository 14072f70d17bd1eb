"""The listening side logs each refused connection once (rate-limited); accepted links are never reported."""
from __future__ import annotations

import logging
import time

from teleop.config import TransportAuthConfig, TransportConfig
from teleop.refusal_watch import RefusalWatch, _address, time_wait_remotes
from teleop.transport import Session, free_tcp_port

DEADLINE = 30.0   # [s] bound of the wait for zenoh's retries (about one a second; see the module's limits)


def test_kernel_addresses_decode():
    assert _address("0100007F:1D27") == ("127.0.0.1", 7463)
    assert _address("0000000000000000FFFF00000100007F:0050") == ("127.0.0.1", 80)
    assert _address("00000000000000000000000001000000:0016") == ("::1", 22)


def test_a_wrong_password_is_reported_and_the_authorised_peer_is_not(tmp_path, caplog):
    users = tmp_path / "users.txt"
    users.write_text("slave:s3cret\nsurgeon:right\n")
    ep = f"tcp/127.0.0.1:{free_tcp_port()}"
    listener = TransportConfig(listen=(ep,), auth=TransportAuthConfig(user="slave", password="s3cret",
                                                                     dictionary_file=str(users)))
    good = TransportConfig(listen=(), connect=(ep,), auth=TransportAuthConfig(user="surgeon", password="right"))
    bad = TransportConfig(listen=(), connect=(ep,), auth=TransportAuthConfig(user="surgeon", password="wrong"))
    with caplog.at_level(logging.WARNING, logger="teleop.refusals"), Session(listener) as lis:
        watch = RefusalWatch(lis, (ep,), interval=3600.0)        # polled by hand below
        with Session(good) as g:
            deadline = time.monotonic() + DEADLINE
            while not lis.zenoh_session.info.peers_zid() and time.monotonic() < deadline:
                g.zenoh_session.info.peers_zid()
                time.sleep(0.01)
            good_port = int(str(next(iter(lis.zenoh_session.info.links())).dst).rsplit(":", 1)[1])
            with Session(bad):
                deadline = time.monotonic() + DEADLINE
                while watch.refused == 0 and time.monotonic() < deadline:
                    watch.poll()
                    time.sleep(0.05)
        watch.close()
    assert watch.refused >= 1
    reported = [r for r in caplog.records if r.name == "teleop.refusals"]
    assert len(reported) == 1                                     # rate-limited: one record per 5 s
    assert reported[0].getMessage().startswith("refused a connection from 127.0.0.1:")
    named = int(reported[0].getMessage().split("127.0.0.1:", 1)[1].split(" ", 1)[0])
    assert named != good_port and ("127.0.0.1", good_port) in watch._linked


def test_no_table_no_report(tmp_path):
    assert time_wait_remotes({7447}, tables=(tmp_path / "missing",)) == set()
