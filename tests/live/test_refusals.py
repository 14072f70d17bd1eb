"""Refusals that explain themselves: a side that cannot reach its peer says why in one line, exit status 2.

The listener is a real zenoh session in this process (or a plain socket server that is not Zenoh) on
127.0.0.1; the side is `teleop master` started bare (the port is taken, so it connects), as in the
two-terminal how-to. Multicast scouting stays off (the default).
"""
from __future__ import annotations

import shutil
import socket
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from live.discovery import open_auto_session, wait_for_peer
from teleop.config.load import config_from_dict
from teleop.config.schema import TransportAuthConfig, TransportConfig, TransportTlsConfig
from teleop.session.transport import Session, free_tcp_port

ROOT = Path(__file__).resolve().parents[2]


def _openssl(tmp: Path, *args: str) -> None:
    subprocess.run(["openssl", *args], cwd=tmp, check=True, capture_output=True, timeout=30)


def _ca(d: Path, name: str) -> None:
    _openssl(d, "req", "-x509", "-newkey", "rsa:2048", "-nodes", "-keyout", f"{name}.key", "-out", f"{name}.pem",
             "-days", "1", "-subj", f"/CN={name}")


@pytest.fixture(scope="module")
def pki(tmp_path_factory) -> dict[str, str]:
    """Two CAs; a listener certificate for localhost/127.0.0.1 signed by the first."""
    if shutil.which("openssl") is None:
        pytest.skip("openssl is not installed: cannot make the test certificates")
    d = tmp_path_factory.mktemp("pki")
    _ca(d, "ca-one")
    _ca(d, "ca-other")
    _openssl(d, "req", "-newkey", "rsa:2048", "-nodes", "-keyout", "srv.key", "-out", "srv.csr",
             "-subj", "/CN=localhost")
    (d / "ext.cnf").write_text("subjectAltName=DNS:localhost,IP:127.0.0.1\n")
    _openssl(d, "x509", "-req", "-in", "srv.csr", "-CA", "ca-one.pem", "-CAkey", "ca-one.key", "-CAcreateserial",
             "-out", "srv.pem", "-days", "1", "-extfile", "ext.cnf")
    _openssl(d, "req", "-newkey", "rsa:2048", "-nodes", "-keyout", "cli.key", "-out", "cli.csr", "-subj", "/CN=client")
    for ca in ("ca-one", "ca-other"):               # a client certificate of each CA, on one key
        _openssl(d, "x509", "-req", "-in", "cli.csr", "-CA", f"{ca}.pem", "-CAkey", f"{ca}.key", "-CAcreateserial",
                 "-out", f"cli-{ca}.pem", "-days", "1", "-extfile", "ext.cnf")          # X.509 v3
    return {"ca": str(d / "ca-one.pem"), "other_ca": str(d / "ca-other.pem"), "cert": str(d / "srv.pem"),
            "key": str(d / "srv.key"), "client_cert": str(d / "cli-ca-one.pem"),
            "other_client_cert": str(d / "cli-ca-other.pem"), "client_key": str(d / "cli.key")}


def _side(tmp_path: Path, transport: str) -> subprocess.CompletedProcess:
    cfg = tmp_path / "side.yaml"
    cfg.write_text(f"instrument: {{id: refuse}}\nrecording: {{rerun: 'off', dir: '{tmp_path / 'runs'}'}}\n"
                   f"transport:\n{transport}", encoding="utf-8")
    return subprocess.run([sys.executable, "-m", "live.cli", "master", "--config", str(cfg), "--max-duration", "3"],
                          capture_output=True, text=True, timeout=120, cwd=tmp_path)


def _error_line(r: subprocess.CompletedProcess) -> str:
    assert r.returncode == 2, r.stderr[-2000:]
    assert "Traceback" not in r.stderr
    (line,) = [line for line in r.stderr.splitlines() if line.startswith("teleop: error:")]
    return line


def test_wrong_password(tmp_path):
    users = tmp_path / "users.txt"
    users.write_text("slave:s3cret\nsurgeon:right\n")
    port = free_tcp_port()
    ep = f"tcp/127.0.0.1:{port}"
    listener = TransportConfig(listen=(ep,), auth=TransportAuthConfig(user="slave", password="s3cret",
                                                                     dictionary_file=str(users)))
    with Session(listener):
        r = _side(tmp_path, f"  listen: ['{ep}']\n  auth: {{user: surgeon, password: wrong}}\n")
    assert _error_line(r) == (f"teleop: error: no Zenoh peer answered at {ep} within 1.5 s: the listener accepted "
                              f"the connection but no Zenoh session came up: it refused this peer (wrong "
                              f"transport.auth user/password) or it is not a teleop side")


def test_certificate_not_trusted_names_the_listeners_certificate(tmp_path, pki):
    ep = f"tls/localhost:{free_tcp_port()}"
    listener = TransportConfig(listen=(ep,), tls=TransportTlsConfig(root_ca=pki["ca"], certificate=pki["cert"],
                                                                    private_key=pki["key"]))
    with Session(listener):
        r = _side(tmp_path, f"  listen: ['{ep}']\n  tls: {{root_ca: '{pki['other_ca']}'}}\n")
    line = _error_line(r)
    assert line.startswith(f"teleop: error: no Zenoh peer answered at {ep} within 1.5 s: certificate not trusted: "
                           f"the listener's certificate")
    assert f"is not signed by {pki['other_ca']}" in line
    assert "(CN=localhost, issued by CN=ca-one)" in line


def test_a_tls_listener_without_its_files(tmp_path, pki):
    ep = f"tls/localhost:{free_tcp_port()}"
    cfg = tmp_path / "side.yaml"
    cfg.write_text(f"instrument: {{id: refuse}}\ntransport:\n  tls: {{root_ca: '{pki['ca']}'}}\n", encoding="utf-8")
    r = subprocess.run([sys.executable, "-m", "live.cli", "slave", "--config", str(cfg), "--listen", ep,
                        "--run-dir", str(tmp_path / "run")], capture_output=True, text=True, timeout=120)
    assert _error_line(r) == (f"teleop: error: transport.listen: '{ep}' needs transport.tls.certificate and "
                              f"private_key (a TLS listener presents them; a connector needs only root_ca: "
                              f"--connect {ep})")


def test_a_port_held_by_something_that_is_not_zenoh(tmp_path):
    server = socket.create_server(("127.0.0.1", 0))
    port = server.getsockname()[1]
    stop = threading.Event()

    def serve() -> None:                     # an SSH-like service: it greets every connection first
        server.settimeout(0.1)
        while not stop.is_set():
            try:
                conn, _ = server.accept()
            except TimeoutError:
                continue
            with conn:
                conn.sendall(b"SSH-2.0-OpenSSH_9.6\r\n")
    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    try:
        r = _side(tmp_path, f"  listen: ['tcp/127.0.0.1:{port}']\n")
    finally:
        stop.set()
        thread.join()
        server.close()
    assert _error_line(r) == (f"teleop: error: no Zenoh peer answered at tcp/127.0.0.1:{port} within 1.5 s: the "
                              f"listener is not a Zenoh peer: it answered 'SSH-2.0-OpenSSH_9.6'")


def test_the_tls_snippet_works_for_a_bare_connector_with_the_root_ca_only(pki):
    """The how-to's TLS config: the listener has certificate and key; a connector started bare with the
    same listen endpoint and only root_ca connects (it cannot listen on TLS without a certificate)."""
    ep = f"tls/localhost:{free_tcp_port()}"
    listener = TransportConfig(listen=(ep,), tls=TransportTlsConfig(root_ca=pki["ca"], certificate=pki["cert"],
                                                                    private_key=pki["key"]))
    connector = config_from_dict({"transport": {"listen": [ep], "tls": {"root_ca": pki["ca"]}}})
    with Session(listener):
        session, role = open_auto_session(connector)
        with session:
            assert role == "connected"
            wait_for_peer(session, (ep,), connector.transport.tls)          # raises if no peer came
            assert session.zenoh_session.info.peers_zid()


def test_a_peer_of_another_instrument_is_named_in_one_warning(tmp_path, caplog):
    from live.discovery import agree_run_id
    ep = f"tcp/127.0.0.1:{free_tcp_port()}"
    theirs = config_from_dict({"instrument": {"id": "theirs"}, "recording": {"dir": str(tmp_path / "a")},
                               "transport": {"listen": [ep]}})
    mine = config_from_dict({"instrument": {"id": "mine"}, "recording": {"dir": str(tmp_path / "b")},
                             "transport": {"listen": [ep], "run_id_timeout": 0.3}})
    first, role_first = open_auto_session(theirs)
    with first:
        agree_run_id(first, theirs, role_first)
        session, role = open_auto_session(mine)
        with session, caplog.at_level("WARNING", logger="live.discovery"):
            wait_for_peer(session, (ep,), mine.transport.tls)
            rid = agree_run_id(session, mine, role)
    (warning,) = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]
    assert warning == ("connected to a Zenoh peer, but none answered the run id of instrument 'mine' within 0.3 s: "
                       f"the peers serve another instrument.id or are not teleop sides; this process starts run {rid} "
                       "alone")


def test_a_mutual_tls_listener_and_a_connector_without_a_certificate(tmp_path, pki):
    ep = f"tls/localhost:{free_tcp_port()}"
    listener = TransportConfig(listen=(ep,), tls=TransportTlsConfig(root_ca=pki["ca"], certificate=pki["cert"],
                                                                    private_key=pki["key"], mutual=True))
    with Session(listener):
        r = _side(tmp_path, f"  listen: ['{ep}']\n  tls: {{root_ca: '{pki['ca']}'}}\n")
    line = _error_line(r)
    assert line.startswith(f"teleop: error: no Zenoh peer answered at {ep} within 1.5 s: the TLS listener requires "
                           f"a client certificate (mutual TLS) and this peer presented none (")
    assert line.endswith("): set transport.tls.certificate, private_key and mutual: true")


def _mutual_listener(pki, ep: str, auth: TransportAuthConfig | None = None) -> TransportConfig:
    return TransportConfig(listen=(ep,), auth=auth or TransportAuthConfig(),
                           tls=TransportTlsConfig(root_ca=pki["ca"], certificate=pki["cert"], private_key=pki["key"],
                                                  mutual=True))


def test_a_client_certificate_of_another_ca_is_named_as_not_signed_by_the_listeners_root_ca(tmp_path, pki):
    ep = f"tls/localhost:{free_tcp_port()}"
    with Session(_mutual_listener(pki, ep)):
        r = _side(tmp_path, f"  listen: ['{ep}']\n  tls: {{root_ca: '{pki['ca']}', certificate: "
                            f"'{pki['other_client_cert']}', private_key: '{pki['client_key']}', mutual: true}}\n")
    assert _error_line(r) == (f"teleop: error: no Zenoh peer answered at {ep} within 1.5 s: the TLS listener does "
                              f"not trust this peer's certificate (CN=client, issued by CN=ca-other): it is not "
                              f"signed by the CA of the listener's transport.tls.root_ca (unknown CA, "
                              f"TLSV1_ALERT_UNKNOWN_CA); give transport.tls.certificate a certificate of that CA")


def test_plain_tcp_to_a_tls_port_is_told_the_port_speaks_tls(tmp_path, pki):
    port = free_tcp_port()
    with Session(_mutual_listener(pki, f"tls/localhost:{port}")):
        r = _side(tmp_path, f"  listen: ['tcp/localhost:{port}']\n")
    assert _error_line(r) == (f"teleop: error: no Zenoh peer answered at tcp/localhost:{port} within 1.5 s: the port "
                              f"speaks TLS (it answered plain TCP with a TLS alert): the endpoint is "
                              f"tls/localhost:{port}, with transport.tls.root_ca (and the certificate of a mutual "
                              f"TLS listener)")


def test_each_refusal_of_a_tls_listener_is_named_by_the_probe(tmp_path, pki):
    """The four refusals of a mutual TLS listener with a user/password, probed as a connecting side probes them,
    and a tls/ endpoint pointed at a plain TCP listener."""
    from teleop.session.peer_probe import probe_endpoint
    users = tmp_path / "users.txt"
    users.write_text("slave:s3cret\nsurgeon:right\n")
    port = free_tcp_port()
    ep = f"tls/localhost:{port}"
    mine = TransportTlsConfig(root_ca=pki["ca"], certificate=pki["client_cert"], private_key=pki["client_key"],
                              mutual=True)
    with Session(_mutual_listener(pki, ep, TransportAuthConfig(user="slave", password="s3cret",
                                                               dictionary_file=str(users)))):
        unknown_ca = probe_endpoint(ep, TransportTlsConfig(root_ca=pki["ca"], certificate=pki["other_client_cert"],
                                                           private_key=pki["client_key"], mutual=True))
        no_certificate = probe_endpoint(ep, TransportTlsConfig(root_ca=pki["ca"], certificate=pki["client_cert"],
                                                               private_key=pki["client_key"]))
        handshake_ok = probe_endpoint(ep, mine)          # a wrong password shows only at the Zenoh level
        plain = probe_endpoint(f"tcp/localhost:{port}", None)
    assert unknown_ca.kind == "tls" and "does not trust this peer's certificate (CN=client, issued by CN=ca-other)" \
        in unknown_ca.text and "(unknown CA, TLSV1_ALERT_UNKNOWN_CA)" in unknown_ca.text
    assert no_certificate.kind == "tls" and no_certificate.text.startswith(
        "the TLS listener requires a client certificate (mutual TLS) and this peer presented none (")
    assert no_certificate.text.endswith("): set transport.tls.mutual: true")           # certificate and key are set
    assert handshake_ok.kind == "silent" and "most likely a wrong transport.auth user/password" in handshake_ok.text
    assert plain.kind == "tls_port" and f"the endpoint is tls/localhost:{port}" in plain.text
    tcp = f"tcp/localhost:{free_tcp_port()}"
    with Session(TransportConfig(listen=(tcp,))):
        not_tls = probe_endpoint("tls" + tcp[3:], mine)
    assert not_tls.kind == "not_tls" and not_tls.text.endswith(
        f"it does not speak TLS (a plain TCP Zenoh listener: the endpoint is {tcp})")
