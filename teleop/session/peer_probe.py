"""Why a connecting side found no Zenoh peer: a probe of the endpoint that tells what is (not) there.

Zenoh does not tell the application why a link was refused (wrong user/password, a certificate its
CA does not sign): the session opens and no peer ever appears. What a process can observe is the
endpoint itself, so :func:`probe_endpoint` opens one TCP connection to it and reads what answers:

* the connection is refused: nothing listens there;
* ``tls/`` endpoints: a TLS handshake with this process's ``transport.tls`` files; a listener certificate
  the configured ``root_ca`` does not sign (named by its subject and issuer); a mutual TLS listener that
  got no client certificate (the settings missing are named) or one it does not trust (its alert: an
  unknown CA; this process's certificate named); a listener that does not speak TLS at all (a plain
  Zenoh TCP listener waits for the rest of a frame: the handshake times out);
* ``tcp/`` endpoints to a TLS listener: it answers the line of text below with a TLS alert record;
* a listener that talks first, or answers a line of text, is not a Zenoh peer (a Zenoh listener
  says nothing until it has a whole frame): its first line is quoted (``SSH-2.0-...``, ``HTTP/1.1 400``);
* a listener that accepts the connection and says nothing is most likely a Zenoh peer that refused
  this one at the Zenoh level: wrong ``transport.auth`` user/password, or a router/peer of another
  deployment.

:func:`no_peer_reason` turns the findings into the one line a side prints.
"""
from __future__ import annotations

import socket
import ssl
from dataclasses import dataclass
from pathlib import Path

__all__ = ["Finding", "probe_endpoint", "no_peer_reason", "split_endpoint"]

#: [s] connect, handshake and read timeouts of one probe
PROBE_TIMEOUT_S = 0.25
_TEXT_PROBE = b"\r\n\r\nHEAD / HTTP/1.0\r\n\r\n"
#: the first byte of a TLS record (the second is 3, the protocol's major version) -> what it is
_TLS_RECORDS = {b"\x15": "alert", b"\x16": "handshake"}


@dataclass(frozen=True)
class Finding:
    """What :func:`probe_endpoint` found: ``kind`` and a phrase for the user.

    ``kind``: ``nothing`` (connection refused or unreachable), ``not_zenoh`` (something else answered),
    ``tls`` (a TLS problem the phrase names), ``tls_port`` (a ``tcp/`` endpoint whose listener speaks TLS),
    ``not_tls`` (a ``tls/`` endpoint whose listener does not), ``silent`` (a listener that accepted and said
    nothing: a Zenoh peer that refused this one, most likely), ``bad_endpoint``.
    """

    kind: str
    text: str


def split_endpoint(endpoint: str) -> tuple[str, str, int]:
    """``tcp/127.0.0.1:7447`` -> ("tcp", "127.0.0.1", 7447); ``[::1]`` loses its brackets; ``#...`` options go.

    Raises
    ------
    ValueError
        No ``proto/host:port`` form.
    """
    proto, _, rest = endpoint.partition("/")
    rest = rest.split("#", 1)[0].split("?", 1)[0]
    host, sep, port = rest.rpartition(":")
    if not proto or not sep or not port.isdigit():
        raise ValueError(f"{endpoint!r} is not a proto/host:port endpoint")
    return proto, host.strip("[]"), int(port)


def _first_line(data: bytes) -> str:
    line = data.split(b"\n", 1)[0].strip()
    text = line.decode("utf-8", "replace")
    return "".join(c if c.isprintable() else "?" for c in text)[:60]


def _listen_talk(sock: socket.socket, timeout: float) -> bytes | None:
    """What the listener sends first, else its answer to a line of text; None: it said nothing."""
    sock.settimeout(timeout)
    for payload in (None, _TEXT_PROBE):
        try:
            if payload is not None:
                sock.sendall(payload)
            data = sock.recv(256)
        except TimeoutError:
            continue
        except OSError:
            return None
        return data or None           # b"": closed without a word (a Zenoh listener refusing a bad frame)
    return None


def _rdn(name) -> str:
    """``CN=localhost,O=...`` of the ``subject``/``issuer`` tuple of :func:`ssl._ssl._test_decode_cert`."""
    return ",".join(f"{k}={v}" for rdn in name for k, v in rdn).replace("commonName", "CN") \
        .replace("organizationName", "O").replace("countryName", "C")


def _cert_names(der: bytes | None) -> str:
    """`` (subject, issued by issuer)`` of a DER certificate, else ''. The standard library decodes a
    certificate only from a file (its test helper, present in every CPython 3)."""
    if not der:
        return ""
    import os
    import tempfile
    fd, path = tempfile.mkstemp(suffix=".pem")
    try:
        with os.fdopen(fd, "w") as fh:
            fh.write(ssl.DER_cert_to_PEM_cert(der))
        info = ssl._ssl._test_decode_cert(path)  # type: ignore[attr-defined]
        return f" ({_rdn(info['subject'])}, issued by {_rdn(info['issuer'])})"
    except Exception:  # noqa: BLE001 - a name is a courtesy: an odd certificate gives none
        return ""
    finally:
        os.unlink(path)


def _peer_certificate(host: str, port: int, timeout: float) -> bytes | None:
    ctx = ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT)
    ctx.check_hostname, ctx.verify_mode = False, ssl.CERT_NONE
    try:
        with socket.create_connection((host, port), timeout=timeout) as raw, \
                ctx.wrap_socket(raw, server_hostname=host) as s:
            return s.getpeercert(binary_form=True)
    except (OSError, ssl.SSLError):
        return None


def _own_certificate(tls) -> str:
    """`` (subject, issued by issuer)`` of this process's ``transport.tls.certificate``, else ''."""
    try:
        info = ssl._ssl._test_decode_cert(tls.certificate)  # type: ignore[attr-defined]
        return f" ({_rdn(info['subject'])}, issued by {_rdn(info['issuer'])})"
    except Exception:  # noqa: BLE001 - a name is a courtesy: an odd certificate gives none
        return ""


def _missing_client_files(tls) -> str:
    """``transport.tls`` settings this process lacks to present a client certificate, e.g. ``certificate,
    private_key and mutual: true``."""
    missing = [n for n, v in (("certificate", tls.certificate), ("private_key", tls.private_key)) if not v]
    missing += [] if tls.mutual else ["mutual: true"]
    return ", ".join(missing[:-1]) + (" and " if len(missing) > 1 else "") + missing[-1] if missing else ""


def _refused_certificate(tls, reason: str) -> Finding:
    """The finding for a TLS listener that refused this peer's client certificate (alert ``reason``)."""
    presented = bool(tls.mutual and tls.certificate and tls.private_key)
    low = reason.lower()
    if not presented or "certificate_required" in low:
        missing = _missing_client_files(tls) or "certificate, private_key and mutual: true"
        return Finding("tls", f"the TLS listener requires a client certificate (mutual TLS) and this peer presented "
                              f"none ({reason}): set transport.tls.{missing}")
    names = _own_certificate(tls)
    if "unknown_ca" in low:
        return Finding("tls", f"the TLS listener does not trust this peer's certificate{names}: it is not signed by "
                              f"the CA of the listener's transport.tls.root_ca (unknown CA, {reason}); give "
                              f"transport.tls.certificate a certificate of that CA")
    if "expired" in low or "revoked" in low:
        return Finding("tls", f"the TLS listener refused this peer's certificate{names} ({reason}): renew "
                              f"transport.tls.certificate")
    return Finding("tls", f"the TLS listener refused this peer's certificate{names} ({reason}): it takes an X.509 "
                          f"v3 certificate signed by the CA of its transport.tls.root_ca")


def _tls_probe(endpoint: str, host: str, port: int, tls, timeout: float) -> Finding | None:
    """A TLS handshake as this process would make it; None when it succeeds."""
    ctx = ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT)
    ctx.check_hostname = False
    if tls.root_ca and Path(tls.root_ca).is_file():
        ctx.load_verify_locations(tls.root_ca)
    if tls.mutual and tls.certificate and tls.private_key:
        ctx.load_cert_chain(tls.certificate, tls.private_key)
    try:
        with socket.create_connection((host, port), timeout=timeout) as raw, \
                ctx.wrap_socket(raw, server_hostname=host) as s:
            s.settimeout(timeout)
            try:
                s.recv(1)            # TLS 1.3: a refused client certificate is only reported after the handshake
            except (TimeoutError, ssl.SSLWantReadError):
                pass
        return None
    except ssl.SSLCertVerificationError as e:
        names = _cert_names(_peer_certificate(host, port, timeout))
        ca = tls.root_ca or "the system's CAs (transport.tls.root_ca is not set)"
        return Finding("tls", f"certificate not trusted: the listener's certificate{names} is not signed by {ca} "
                              f"({e.verify_message})")
    except ssl.SSLError as e:
        reason = str(e.reason or e)
        low = reason.lower()
        if "certificate" in low or "unknown_ca" in low or "decrypt" in low:
            return _refused_certificate(tls, reason)
        if "wrong version" in low or "record layer" in low or "packet length" in low:
            return Finding("not_zenoh", f"the listener does not speak TLS ({reason}): a plain TCP listener? "
                                        f"(then the endpoint is tcp/{endpoint.split('/', 1)[1]})")
        if "handshake failure" in low or "alert" in low:
            return _refused_certificate(tls, reason)
        return Finding("tls", f"the TLS handshake failed: {reason}")
    except TimeoutError:                 # a plain Zenoh TCP listener waits for the rest of a frame that never comes
        return Finding("not_tls", f"the listener does not answer a TLS handshake within {timeout:g} s: it does not "
                                  f"speak TLS (a plain TCP Zenoh listener: the endpoint is "
                                  f"tcp/{endpoint.split('/', 1)[1]})")
    except OSError:
        return None


def probe_endpoint(endpoint: str, tls=None, timeout: float = PROBE_TIMEOUT_S) -> Finding:
    """Probe ``endpoint`` (module docstring). ``tls``: the ``transport.tls`` section (``tls/`` endpoints)."""
    try:
        proto, host, port = split_endpoint(endpoint)
    except ValueError as e:
        return Finding("bad_endpoint", str(e))
    if proto not in ("tcp", "tls"):
        return Finding("silent", f"{proto} endpoints are not probed")
    try:
        sock = socket.create_connection((host, port), timeout=timeout)
    except ConnectionRefusedError:
        return Finding("nothing", "nothing listens there (connection refused)")
    except OSError as e:
        return Finding("nothing", f"not reachable ({e.strerror or e})")
    if proto == "tls" and tls is not None:
        sock.close()
        found = _tls_probe(endpoint, host, port, tls, timeout)
        if found is not None:
            return found
        return Finding("silent", "the TLS handshake succeeds, so the listener refused this peer at the Zenoh "
                                 "level: most likely a wrong transport.auth user/password, or it is not a teleop side")
    with sock:
        data = _listen_talk(sock, timeout)
    record = _TLS_RECORDS.get(data[:1]) if data and data[1:2] == b"\x03" else None
    if record is not None:
        return Finding("tls_port", f"the port speaks TLS (it answered plain TCP with a TLS {record}): the endpoint is "
                                   f"tls/{endpoint.split('/', 1)[1]}, with transport.tls.root_ca (and the certificate "
                                   "of a mutual TLS listener)")
    if data:
        return Finding("not_zenoh", f"the listener is not a Zenoh peer: it answered {_first_line(data)!r}")
    return Finding("silent", "the listener accepted the connection but no Zenoh session came up: it refused this "
                             "peer (wrong transport.auth user/password) or it is not a teleop side")


def no_peer_reason(endpoints, tls, waited: float, timeout: float = PROBE_TIMEOUT_S) -> tuple[str, bool]:
    """The one line a connecting side prints when no peer appeared within ``waited`` [s], and whether
    waiting longer may still help (only when nothing listens at any endpoint yet)."""
    findings = [(ep, probe_endpoint(ep, tls, timeout)) for ep in endpoints]
    if not findings:
        return f"no Zenoh peer within {waited:g} s and no endpoint to connect to", False
    if len(findings) == 1:
        head, parts = f" at {findings[0][0]}", findings[0][1].text
    else:
        head, parts = "", "; ".join(f"{ep}: {f.text}" for ep, f in findings)
    may_come = all(f.kind == "nothing" for _, f in findings)
    return f"no Zenoh peer answered{head} within {waited:g} s: {parts}", may_come
