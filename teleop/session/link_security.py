"""Who may talk on the link: TLS and user/password on the Zenoh transport, and the slave's master lock.

Two layers, both from the config (``transport.tls``, ``transport.auth``, ``transport.lock_master``):

* **Link authentication** (zenoh's own): every link of the session is opened only with a peer that
  presents the right user/password (``transport/auth/usrpwd``: the connector sends ``user`` and
  ``password``, the listener checks them against ``dictionary_file``, one ``user:password`` per
  line) and, on ``tls/host:port`` endpoints, a certificate signed by ``tls.root_ca``
  (``transport/link/tls``). A peer without them connects nowhere: it can neither publish commands
  nor read estimates.
* **Session lock** (:class:`SourceLock`): every :class:`teleop.session.transport.Publisher` stamps its puts
  with its zenoh entity id (``source_info``); the slave's command and master-heartbeat subscribers
  share one lock that admits only the session of the first master heard from, until that master's
  liveliness token disappears. A second copy of the operator's own program publishing commands is
  counted (``foreign_source``) and ignored. The id is written by the sender and can be copied: the lock
  is no authentication. Who may put commands at all is decided by the installation's credentials and
  Zenoh's access control (:mod:`teleop.session.credentials`).
"""
from __future__ import annotations

import threading
from collections.abc import Callable
from pathlib import Path

from teleop.errors import ConfigError

__all__ = ["SourceLock", "link_security_settings", "read_password"]


def read_password(auth, where: str = "transport.auth") -> str | None:
    """The password of ``auth`` (``password``, else the first line of ``password_file``), or None.

    Raises
    ------
    ConfigError
        Both or neither of ``password``/``password_file`` with a ``user``; an unreadable file.
    """
    if auth.user is None:
        return None
    if (auth.password is None) == (auth.password_file is None):
        raise ConfigError(f"{where}: with a user, give exactly one of password and password_file")
    if auth.password is not None:
        return auth.password
    try:
        return Path(auth.password_file).read_text(encoding="utf-8").splitlines()[0].strip()
    except (OSError, IndexError) as e:
        raise ConfigError(f"{where}.password_file: cannot read a password from {auth.password_file!r} ({e})") from None


def _pem(path: str | None, where: str) -> str | None:
    if path is None:
        return None
    if not Path(path).is_file():
        raise ConfigError(f"{where}: file {path!r} not found")
    return str(Path(path).resolve())


def link_security_settings(transport) -> dict[str, object]:
    """Zenoh config entries (``key path -> JSON value``) for ``transport.auth`` and ``transport.tls``.

    Parameters
    ----------
    transport : TransportConfig

    Returns
    -------
    dict
        Empty when neither is configured.

    Raises
    ------
    ConfigError
        A missing PEM or dictionary file, a certificate without its key, a password without a user.
    """
    out: dict[str, object] = {}
    auth, tls = transport.auth, transport.tls
    if auth.user is None and (auth.password is not None or auth.password_file is not None):
        raise ConfigError("transport.auth: a password needs a user")
    password = read_password(auth)
    if auth.user is not None:
        out["transport/auth/usrpwd/user"] = auth.user
        out["transport/auth/usrpwd/password"] = password
    if auth.dictionary_file is not None:
        out["transport/auth/usrpwd/dictionary_file"] = _pem(auth.dictionary_file, "transport.auth.dictionary_file")
    if (tls.certificate is None) != (tls.private_key is None):
        raise ConfigError("transport.tls: give both certificate and private_key, or neither")
    ca = _pem(tls.root_ca, "transport.tls.root_ca")
    cert = _pem(tls.certificate, "transport.tls.certificate")
    key = _pem(tls.private_key, "transport.tls.private_key")
    if ca is not None:
        out["transport/link/tls/root_ca_certificate"] = ca
    if cert is not None:
        out["transport/link/tls/listen_certificate"] = cert
        out["transport/link/tls/listen_private_key"] = key
        if tls.mutual:
            out["transport/link/tls/connect_certificate"] = cert
            out["transport/link/tls/connect_private_key"] = key
    if tls.mutual:
        out["transport/link/tls/enable_mtls"] = True
    return out


def _zid(sample) -> str | None:
    info = sample.source_info
    return None if info is None else str(info.source_id.zid)


class SourceLock:
    """Admit samples from one zenoh session only: the first one seen, until :meth:`release`.

    Thread-safe (zenoh calls subscriber callbacks on its own threads). Shared by the subscribers
    that must hear one and the same peer (the slave's commands and master heartbeats).

    Attributes
    ----------
    owner : str or None
        Zenoh id of the admitted session.
    foreign : int
        Samples refused (another session, or no source id at all).
    """

    def __init__(self, on_refuse: Callable[[str | None], None] | None = None):
        self.owner: str | None = None
        self.foreign = 0
        self.on_refuse = on_refuse
        self._lock = threading.Lock()

    def admit(self, sample) -> bool:
        """Whether ``sample`` (a zenoh.Sample) comes from the locked session (locking on the first)."""
        zid = _zid(sample)
        with self._lock:
            if zid is not None and self.owner is None:
                self.owner = zid
            if zid is not None and zid == self.owner:
                return True
            self.foreign += 1
        if self.on_refuse is not None:
            self.on_refuse(zid)
        return False

    def release(self) -> None:
        """Forget the owner (its liveliness token is gone): the next session heard from is admitted."""
        with self._lock:
            self.owner = None

    def on_liveliness(self, key: str, alive: bool) -> None:
        """A :class:`~teleop.session.liveliness.LivelinessWatcher` callback: release when the token goes."""
        if not alive:
            self.release()

    def __repr__(self) -> str:
        return f"SourceLock(owner={self.owner!r}, foreign={self.foreign})"
