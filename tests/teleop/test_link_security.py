"""Only authorised peers: TLS + user/password on the zenoh link, and the slave's lock on one master session.

Real zenoh sessions in this process on 127.0.0.1 (free ports, multicast off); a throwaway CA and a
certificate for localhost/127.0.0.1 made with openssl in a tmp dir. Waits are bounded and end when
the awaited event happens; "never received" is checked over a window in which the authorised peer's
messages, published the same way, are received.
"""
from __future__ import annotations

import shutil
import subprocess
import time
from pathlib import Path

import pytest

from estimator.phase import Phase
from teleop.config.schema import TransportAuthConfig, TransportConfig, TransportTlsConfig
from teleop.errors import ConfigError
from teleop.session.link_security import SourceLock, link_security_settings
from teleop.session.transport import Session, free_tcp_port, loopback_endpoint
from teleop.wire.codec import decode
from teleop.wire.keys import command_key, estimate_key
from teleop.wire.messages import Command, Estimate, tendon_estimate

DEADLINE = 5.0   # [s] bound of any wait


def _openssl(tmp: Path, *args: str) -> None:
    subprocess.run(["openssl", *args], cwd=tmp, check=True, capture_output=True, timeout=30)


@pytest.fixture(scope="module")
def pki(tmp_path_factory) -> dict[str, str]:
    """CA, server certificate (DNS:localhost, IP:127.0.0.1) and key, and a credentials dictionary."""
    if shutil.which("openssl") is None:
        pytest.skip("openssl is not installed: cannot make the test certificates")
    d = tmp_path_factory.mktemp("pki")
    _openssl(d, "req", "-x509", "-newkey", "rsa:2048", "-nodes", "-keyout", "ca.key", "-out", "ca.pem", "-days", "1",
             "-subj", "/CN=teleop-test-ca")
    _openssl(d, "req", "-newkey", "rsa:2048", "-nodes", "-keyout", "srv.key", "-out", "srv.csr",
             "-subj", "/CN=localhost")
    (d / "ext.cnf").write_text("subjectAltName=DNS:localhost,IP:127.0.0.1\n")
    _openssl(d, "x509", "-req", "-in", "srv.csr", "-CA", "ca.pem", "-CAkey", "ca.key", "-CAcreateserial", "-out",
             "srv.pem", "-days", "1", "-extfile", "ext.cnf")
    (d / "users.txt").write_text("slave:s3cret\nsurgeon:right\n")
    return {k: str(d / v) for k, v in (("ca", "ca.pem"), ("cert", "srv.pem"), ("key", "srv.key"),
                                       ("users", "users.txt"))}


def _peer(ep: str, user: str, password: str, ca: str) -> TransportConfig:
    return TransportConfig(listen=(), connect=(ep,), auth=TransportAuthConfig(user=user, password=password),
                           tls=TransportTlsConfig(root_ca=ca))


def _until(pub, msg, sub, count: int = 1) -> bool:
    for _ in range(int(DEADLINE / 0.05)):
        pub.put(msg)
        if sub.wait(count, timeout=0.05):
            return True
    return False


def test_wrong_password_peer_can_neither_command_nor_read_estimates(pki):
    ep = f"tls/localhost:{free_tcp_port()}"
    slave_cfg = TransportConfig(listen=(ep,), connect=(),
                                auth=TransportAuthConfig(user="slave", password="s3cret", dictionary_file=pki["users"]),
                                tls=TransportTlsConfig(root_ca=pki["ca"], certificate=pki["cert"],
                                                       private_key=pki["key"]))
    with Session(slave_cfg) as slave, Session(_peer(ep, "surgeon", "right", pki["ca"])) as master, \
            Session(_peer(ep, "surgeon", "wrong", pki["ca"])) as rogue:
        commands = slave.subscriber(command_key("sec1"), Command)
        heard: list[int] = []                              # every command the slave's session receives
        raw = slave.zenoh_session.declare_subscriber(command_key("sec1"),  # noqa: F841 - kept alive
                                               lambda s: heard.append(decode(s.payload.to_bytes()).seq))
        est_pub = slave.publisher(estimate_key("sec1"))
        good_est = master.subscriber(estimate_key("sec1"), Estimate)
        rogue_est = rogue.subscriber(estimate_key("sec1"), Estimate)
        rogue_cmd = rogue.publisher(command_key("sec1"))
        good_cmd = master.publisher(command_key("sec1"))
        est = tendon_estimate(1, 1, 0.0, 2.0, 0.001, 1.5, 1e-5, 0.00099, Phase.HOLD)
        # the authorised master is heard and hears; over the same window the rogue's 100 commands are not
        for i in range(100):
            rogue_cmd.put(Command(10_000 + i, 0.0, (0.002,)))
        assert _until(good_cmd, Command(1, 0.0, (0.001,)), commands)
        assert _until(est_pub, est, good_est, 1)
        for i in range(100):
            rogue_cmd.put(Command(20_000 + i, 0.0, (0.002,)))
            est_pub.put(est)
        assert good_est.wait(good_est.count + 1, timeout=DEADLINE)
        assert heard and all(seq == 1 for seq in heard)    # the rogue's 200 commands never arrived
        assert rogue_est.count == 0 and rogue_est.latest() is None
        assert commands.latest().message == Command(1, 0.0, (0.001,))
        assert str(rogue.zenoh_session.zid()) not in {str(z) for z in slave.zenoh_session.info.peers_zid()}
        assert str(master.zenoh_session.zid()) in {str(z) for z in slave.zenoh_session.info.peers_zid()}


def test_a_certificate_from_another_ca_is_refused(pki, tmp_path):
    _openssl(tmp_path, "req", "-x509", "-newkey", "rsa:2048", "-nodes", "-keyout", "o.key", "-out", "other.pem",
             "-days", "1", "-subj", "/CN=other-ca")
    ep = f"tls/localhost:{free_tcp_port()}"
    listener = TransportConfig(listen=(ep,), connect=(),
                               tls=TransportTlsConfig(root_ca=pki["ca"], certificate=pki["cert"],
                                                      private_key=pki["key"]))
    with Session(listener) as a, Session(TransportConfig(listen=(), connect=(ep,), tls=TransportTlsConfig(
            root_ca=str(tmp_path / "other.pem")))) as b:
        sub = a.subscriber(command_key("sec2"))
        pub = b.publisher(command_key("sec2"))
        for i in range(20):
            pub.put(Command(i, 0.0, (0.0,)))
        assert not sub.wait(1, timeout=0.5)
        assert list(a.zenoh_session.info.peers_zid()) == []


def test_slave_lock_admits_one_master_session_until_its_token_goes():
    port = free_tcp_port()
    lock = SourceLock()
    with Session(TransportConfig(listen=(loopback_endpoint(port),), connect=())) as slave, \
            Session(TransportConfig(listen=(), connect=(loopback_endpoint(port),))) as master, \
            Session(TransportConfig(listen=(), connect=(loopback_endpoint(port),))) as other:
        sub = slave.subscriber(command_key("sec3"), Command, source_lock=lock)
        first = master.publisher(command_key("sec3"))
        second = other.publisher(command_key("sec3"))
        deadline = time.monotonic() + DEADLINE                 # both publishers know the subscriber
        while not (second._handle.matching_status.matching and first._handle.matching_status.matching):
            assert time.monotonic() < deadline, "routes to the subscriber not established"
            time.sleep(0.01)
        assert _until(first, Command(1, 0.0, (0.001,)), sub)
        assert lock.owner == str(master.zenoh_session.zid())
        for i in range(50):
            second.put(Command(100 + i, 0.0, (0.002,)))
        first.put(Command(2, 0.0, (0.001,)))
        deadline = time.monotonic() + DEADLINE
        while (lock.foreign < 50 or sub.latest().message.seq != 2) and time.monotonic() < deadline:
            time.sleep(0.01)
        assert lock.foreign == 50 and sub.latest().message.seq == 2
        lock.on_liveliness("teleop/sec3/master/alive", False)     # the master's token is gone
        assert _until(second, Command(200, 0.0, (0.002,)), sub, sub.count + 1)
        assert lock.owner == str(other.zenoh_session.zid())


def test_security_settings_and_their_errors(pki, tmp_path):
    t = TransportConfig(auth=TransportAuthConfig(user="u", password="p"),
                        tls=TransportTlsConfig(root_ca=pki["ca"], certificate=pki["cert"], private_key=pki["key"],
                                               mutual=True))
    s = link_security_settings(t)
    assert s["transport/auth/usrpwd/user"] == "u" and s["transport/auth/usrpwd/password"] == "p"
    assert s["transport/link/tls/connect_certificate"] == str(Path(pki["cert"]).resolve())
    assert s["transport/link/tls/enable_mtls"] is True
    assert link_security_settings(TransportConfig()) == {}
    (tmp_path / "pw").write_text("from-file\n")
    s = link_security_settings(TransportConfig(auth=TransportAuthConfig(user="u", password_file=str(tmp_path / "pw"))))
    assert s["transport/auth/usrpwd/password"] == "from-file"
    with pytest.raises(ConfigError, match="a password needs a user"):
        link_security_settings(TransportConfig(auth=TransportAuthConfig(password="p")))
    with pytest.raises(ConfigError, match="both certificate and private_key"):
        link_security_settings(TransportConfig(tls=TransportTlsConfig(certificate=pki["cert"])))
    with pytest.raises(ConfigError, match=r"transport.tls.root_ca: file .*nowhere.pem.* not found"):
        link_security_settings(TransportConfig(tls=TransportTlsConfig(root_ca=str(tmp_path / "nowhere.pem"))))
    with pytest.raises(ConfigError, match="exactly one of password and password_file"):
        link_security_settings(TransportConfig(auth=TransportAuthConfig(user="u")))


def test_the_slaves_links_hear_one_master_session_and_follow_a_new_one_after_its_token_goes():
    from live.sides import slave_links
    from teleop.wire.keys import liveliness_key
    port = free_tcp_port()
    with Session(TransportConfig(listen=(loopback_endpoint(port),), connect=())) as slave:
        slave.lock_master = True                             # what live.discovery sets from transport.lock_master
        links = slave_links(slave, "sec4", None)
        with Session(TransportConfig(listen=(), connect=(loopback_endpoint(port),))) as master, \
                Session(TransportConfig(listen=(), connect=(loopback_endpoint(port),))) as intruder:
            token = master.liveliness_token(liveliness_key("sec4", "master"))
            mine, theirs = master.publisher(command_key("sec4")), intruder.publisher(command_key("sec4"))
            assert _until(mine, Command(1, 0.0, (0.001,)), links.command)
            deadline = time.monotonic() + DEADLINE
            while not theirs._handle.matching_status.matching:     # the intruder's puts do reach the slave
                assert time.monotonic() < deadline
                time.sleep(0.01)
            n, lock = links.command.count, links.command.source_lock
            for i in range(30):
                theirs.put(Command(500 + i, 0.0, (0.002,)))
            mine.put(Command(2, 0.0, (0.001,)))
            assert links.command.wait(n + 1, timeout=DEADLINE)
            while lock.foreign < 30 and time.monotonic() < deadline:
                time.sleep(0.01)
            assert lock.foreign == 30 and links.master_heartbeat.source_lock is lock
            assert links.command.latest().message.seq == 2 and links.command.count == n + 1
            token.close()                                    # the master is gone: the next session is admitted
            deadline = time.monotonic() + DEADLINE
            while links.master_alive() and time.monotonic() < deadline:
                time.sleep(0.01)
            assert _until(theirs, Command(600, 0.0, (0.002,)), links.command, n + 2)


def test_a_router_with_a_credentials_dictionary_routes_only_for_authorised_clients(pki):
    from live.router import router_config
    from teleop.config.load import config_from_dict
    from teleop.errors import TransportError
    ep = loopback_endpoint(free_tcp_port())
    router_cfg = config_from_dict({"transport": {"listen": [ep], "auth": {"user": "router", "password": "s3cret",
                                                                          "dictionary_file": pki["users"]}}})

    def client(user: str, password: str) -> TransportConfig:
        return TransportConfig(mode="client", listen=(), connect=(ep,),
                               auth=TransportAuthConfig(user=user, password=password))
    with Session(router_config(router_cfg)), Session(client("slave", "s3cret")) as slave, \
            Session(client("surgeon", "right")) as master:
        commands = slave.subscriber(command_key("sec5"), Command)
        good_est = master.subscriber(estimate_key("sec5"), Estimate)
        with pytest.raises(TransportError, match="Unable to connect"):   # a client with a wrong password: no session
            Session(client("surgeon", "guess"))
        assert _until(master.publisher(command_key("sec5")), Command(1, 0.0, (0.001,)), commands)
        assert _until(slave.publisher(estimate_key("sec5")),
                      tendon_estimate(1, 1, 0.0, 2.0, 0.0, 1.5, 0.0, 0.0, Phase.HOLD), good_est)
