"""The listening side logs each refused connection once (rate-limited); accepted links are never reported."""
from __future__ import annotations

import logging
import time

from teleop.config.schema import TransportAuthConfig, TransportConfig, TransportTlsConfig
from teleop.session.refusal_watch import CAUSES, RefusalWatch, _address, time_wait_remotes
from teleop.session.transport import Session, free_tcp_port
from tests.live.test_refusals import pki  # noqa: F401 - the certificates, a pytest fixture

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
            with Session(bad), Session(bad), Session(bad):    # three retrying peers: each attempt is a race
                deadline = time.monotonic() + DEADLINE          # which end closes first (module limits)
                while watch.refused == 0 and time.monotonic() < deadline:
                    watch.poll()
                    time.sleep(0.05)
        watch.close()
    assert watch.refused >= 1
    reported = [r for r in caplog.records if r.name == "teleop.refusals"]
    assert len(reported) == 1                                     # rate-limited: one record per 5 s
    assert reported[0].getMessage().startswith("refused a connection from 127.0.0.1:")
    assert f" on TCP port {int(ep.rsplit(':', 1)[1])}: it closed before a Zenoh session came up: {CAUSES['tcp']}" \
        in reported[0].getMessage()
    named = int(reported[0].getMessage().split("127.0.0.1:", 1)[1].split(" ", 1)[0])
    assert named != good_port and ("127.0.0.1", good_port) in watch._linked


def test_no_table_no_report(tmp_path):
    assert time_wait_remotes({7447}, tables=(tmp_path / "missing",)) == set()


def test_a_tls_listener_names_what_it_refuses_once_per_interval(pki, caplog):  # noqa: F811 - the fixture
    """A mutual TLS listener refusing the probes of refused sides (a client certificate of another CA, none; the
    listener closes them, zenoh's own refused handshakes end in a reset and leave nothing to see): one line for
    all of them (rate-limited) with the causes a TLS port refuses; once the interval has passed, the next line
    counts those suppressed."""
    port = free_tcp_port()
    ep = f"tls/localhost:{port}"
    tls = TransportTlsConfig(root_ca=pki["ca"], certificate=pki["cert"], private_key=pki["key"], mutual=True)
    other_ca = TransportTlsConfig(root_ca=pki["ca"], certificate=pki["other_client_cert"],
                                  private_key=pki["client_key"], mutual=True)
    none = TransportTlsConfig(root_ca=pki["ca"])
    with caplog.at_level(logging.WARNING, logger="teleop.refusals"), \
            Session(TransportConfig(listen=(ep,), tls=tls)) as lis:
        watch = RefusalWatch(lis, (ep,), interval=3600.0, log_interval=3600.0)     # polled by hand below
        _refuse_until(watch, ep, (other_ca, none, other_ca), 3)     # what a refused side does before it says why
        before = watch.refused
        watch._log.interval = 0.0                        # the interval has passed: the next refusal is logged
        _refuse_until(watch, ep, (none,), before + 1)
        watch.close()
    first, second = [r.getMessage() for r in caplog.records if r.name == "teleop.refusals"]
    assert first.startswith("refused a connection from 127.0.0.1:")
    assert first.endswith(f" on TLS port {port}: it closed before a Zenoh session came up: {CAUSES['tls']}; the "
                          "connecting process's error line names which")
    assert CAUSES["tls"] == ("a client certificate missing or not signed by transport.tls.root_ca (mutual TLS), a "
                             "tcp/ endpoint pointed at this TLS port, or a wrong transport.auth user/password")
    assert second.endswith(f" ({before - 1} similar suppressed)")


def _refuse_until(watch: RefusalWatch, ep: str, probes: tuple, n: int) -> None:
    """Probe ``ep`` with each of ``probes`` in turn until the watch has seen ``n`` refusals. A refused probe leaves a
    TIME_WAIT socket on the listener only when the listener closes first, which it does nearly always: a probe
    that leaves none is followed by the next."""
    from teleop.session.peer_probe import probe_endpoint
    deadline = time.monotonic() + DEADLINE
    k = 0
    while watch.refused < n:
        assert time.monotonic() < deadline, f"{watch.refused} refusals seen, {n} expected"
        if k < len(probes) or k % 40 == 0:           # each probe once, then one more every 2 s while short
            assert probe_endpoint(ep, probes[k % len(probes)]).kind == "tls"
        k += 1
        watch.poll()
        time.sleep(0.05)


def _poll_until(watch: RefusalWatch, n: int) -> None:
    deadline = time.monotonic() + DEADLINE
    while watch.refused < n:
        assert time.monotonic() < deadline, f"{watch.refused} refusals seen, {n} expected"
        watch.poll()
        time.sleep(0.05)
