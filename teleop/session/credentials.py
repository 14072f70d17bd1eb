"""The installation's credentials: one Zenoh user per role, and the access control that lets each role put only
its own keys.

Every process of a live session authenticates its links with Zenoh's own user/password
(``transport/auth/usrpwd``): a connector proves the password of its role's user, a listener checks it
against the installation's dictionary. A process without the installation's files links to none of the
session's processes: it can neither publish commands nor read estimates. On every link whose peer
authenticated to this process, Zenoh's access control (``access_control``) then refuses, at ingress,
what the peer's role does not own:

==========  ===========================================================================================
role        owns (may put, declare a liveliness token or a queryable on)
==========  ===========================================================================================
master      ``teleop/*/master/**`` (commands, heartbeat, liveliness), ``teleop/*/run/master``, and the ROS 2
            command topics (``*/**/servo_jp/**``, ``*/**/state_command/**``): a ROS 2 driver is the operator
slave       ``teleop/*/slave/**``, ``teleop/*/rig/setpoint``, ``teleop/*/run/slave``
rig         ``teleop/*/rig/sample`` (``teleop bridge``, a motor controller)
observer    none of these (``teleop record``, viewers, replays: they subscribe)
==========  ===========================================================================================

Everything else (the run id, the recorder's own keys, the ROS 2 graph's tokens and topics) stays open to
every authenticated peer. Zenoh's user/password authenticates the connector to the listener, not the
reverse: a link this process opened carries no user, and the rules above do not apply to it (the security
page, docs/concepts/security.md, says what follows and how TLS closes it).

Files, created on first use (:func:`ensure_credentials`; ``teleop keys`` shows, creates or renews them): a
folder (``$TSM_TELEOP_KEYS``, else ``$XDG_CONFIG_HOME/tsm-teleop/keys``, else ``~/.config/tsm-teleop/keys``;
mode 0700) with ``<role>.password`` for each role and ``dictionary`` (``user:password`` lines), each 0600.
Two processes starting at once create it once: the folder is written under a temporary name and renamed.
"""
from __future__ import annotations

import os
import secrets
import stat
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from teleop.errors import ConfigError

__all__ = ["ROLES", "KEYS_ENV", "Credentials", "keys_dir", "ensure_credentials", "renew_credentials", "access_control",
           "installation_settings"]

#: The roles of a live session, each a Zenoh user of the installation's dictionary.
ROLES = ("master", "slave", "rig", "observer")
#: Environment variable naming the credentials folder (tests and several installations on one account).
KEYS_ENV = "TSM_TELEOP_KEYS"
_PASSWORD_BYTES = 32        # secrets.token_urlsafe(32): 256 bits per password

#: The key expressions each role owns (module docstring); every other role's put, delete, liveliness token
#: and queryable on them is refused at ingress.
OWNED: dict[str, tuple[str, ...]] = {
    "master": ("teleop/*/master/**", "teleop/*/run/master", "*/**/servo_jp/**", "*/**/state_command/**"),
    "slave": ("teleop/*/slave/**", "teleop/*/rig/setpoint", "teleop/*/run/slave"),
    "rig": ("teleop/*/rig/sample",),
}
_DENIED_MESSAGES = ("put", "delete", "liveliness_token", "declare_queryable")


@dataclass(frozen=True)
class Credentials:
    """One role's credentials in the installation's folder.

    Attributes
    ----------
    role : str, one of :data:`ROLES` (the Zenoh user name).
    password_file : Path, the role's password (first line).
    dictionary_file : Path, every role's ``user:password`` line (what a listener checks).
    """

    role: str
    password_file: Path
    dictionary_file: Path

    def zenoh_settings(self) -> dict[str, object]:
        """Zenoh config entries (``key path -> JSON value``): the role's user and password, the dictionary
        and :func:`access_control`."""
        return {"transport/auth/usrpwd/user": self.role,
                "transport/auth/usrpwd/password": _read_secret(self.password_file),
                "transport/auth/usrpwd/dictionary_file": str(self.dictionary_file),
                "access_control": access_control()}


def keys_dir() -> Path:
    """The installation's credentials folder (module docstring); it may not exist yet."""
    env = os.environ.get(KEYS_ENV)
    if env:
        return Path(env)
    base = os.environ.get("XDG_CONFIG_HOME") or str(Path.home() / ".config")
    return Path(base) / "tsm-teleop" / "keys"


def _read_secret(path: Path) -> str:
    try:
        text = path.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as e:
        raise ConfigError(f"{path}: cannot read the installation's credentials ({e}); `teleop keys --renew` "
                          "writes new ones") from None
    if not text or not text[0].strip():
        raise ConfigError(f"{path}: empty credentials file; `teleop keys --renew` writes new ones")
    return text[0].strip()


def _check_folder(folder: Path) -> None:
    """Refuse a credentials folder other users can read or write (the passwords would not be secret)."""
    if not folder.is_dir():
        raise ConfigError(f"{folder}: the installation's credentials folder is not a directory")
    mode = stat.S_IMODE(folder.stat().st_mode)
    if mode & 0o077:
        raise ConfigError(f"{folder}: the credentials folder is open to other users (mode {mode:o}); "
                          f"run `chmod 700 {folder}`")
    for role in ROLES:
        p = folder / f"{role}.password"
        if not p.is_file():
            raise ConfigError(f"{p}: missing from the installation's credentials; `teleop keys --renew` writes "
                              "new ones")
        if stat.S_IMODE(p.stat().st_mode) & 0o077:
            raise ConfigError(f"{p}: readable by other users; run `chmod 600 {p}`")


def _write_folder(target: Path) -> None:
    """Write a complete credentials folder at ``target`` (which must not exist) through a temporary folder."""
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=".keys-", dir=target.parent))     # mode 0700
    lines = []
    for role in ROLES:
        password = secrets.token_urlsafe(_PASSWORD_BYTES)
        _write_private(tmp / f"{role}.password", password + "\n")
        lines.append(f"{role}:{password}\n")
    _write_private(tmp / "dictionary", "".join(lines))
    try:
        os.rename(tmp, target)               # atomic; fails when another process made the folder first
    except OSError:
        for f in tmp.iterdir():
            f.unlink()
        tmp.rmdir()
        if not target.is_dir():
            raise


def _write_private(path: Path, text: str) -> None:
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(fd, "w", encoding="utf-8") as f:
        f.write(text)


def ensure_credentials(role: str, folder: Path | None = None) -> Credentials:
    """The credentials of ``role``, creating the installation's folder on first use (module docstring).

    Parameters
    ----------
    role : str
        One of :data:`ROLES`.
    folder : Path, optional
        Default :func:`keys_dir`.

    Raises
    ------
    ConfigError
        An unknown role; a folder that cannot be created, is not a directory, is open to other users or misses
        a file.
    """
    if role not in ROLES:
        raise ConfigError(f"credentials: unknown role {role!r} (expected one of {', '.join(ROLES)})")
    folder = keys_dir() if folder is None else Path(folder)
    if not folder.exists():
        try:
            _write_folder(folder)
        except OSError as e:
            raise ConfigError(f"{folder}: cannot create the installation's credentials ({e}); set "
                              f"{KEYS_ENV} to a folder of your own") from None
    _check_folder(folder)
    return Credentials(role, folder / f"{role}.password", folder / "dictionary")


def installation_settings(auth: Any, role: str | None) -> dict[str, object]:
    """Zenoh config entries of ``role``'s installation credentials (:meth:`Credentials.zenoh_settings`) when they
    apply: a role given (a live session's process), ``auth.installation`` on, and neither ``auth.user`` nor
    ``auth.dictionary_file`` set (explicit credentials win); else none.

    Raises
    ------
    ConfigError
        As :func:`ensure_credentials`.
    """
    if role is None or not auth.installation or auth.user is not None or auth.dictionary_file is not None:
        return {}
    return ensure_credentials(role).zenoh_settings()


def renew_credentials(folder: Path | None = None) -> Path:
    """Replace the installation's credentials with new ones (every running process keeps its links until it
    reconnects); returns the folder.

    Raises
    ------
    ConfigError
        The folder cannot be written.
    """
    folder = keys_dir() if folder is None else Path(folder)
    try:
        if folder.exists():
            old = folder.with_name(folder.name + f".old-{secrets.token_hex(4)}")
            os.rename(folder, old)
            for f in old.iterdir():
                f.unlink()
            old.rmdir()
        _write_folder(folder)
    except OSError as e:
        raise ConfigError(f"{folder}: cannot write the installation's credentials ({e})") from None
    return folder


def access_control() -> dict[str, Any]:
    """Zenoh's ``access_control`` section: every role's puts, deletes, liveliness tokens and queryables on the
    keys another role owns (:data:`OWNED`) refused at ingress; everything else allowed."""
    rules, policies = [], []
    for owner, keys in OWNED.items():
        rules.append({"id": f"{owner}_owned", "messages": list(_DENIED_MESSAGES), "flows": ["ingress"],
                      "permission": "deny", "key_exprs": list(keys)})
        policies.append({"rules": [f"{owner}_owned"], "subjects": [f"not_{owner}"]})
    subjects = [{"id": f"not_{owner}", "usernames": [r for r in ROLES if r != owner]} for owner in OWNED]
    return {"enabled": True, "default_permission": "allow", "rules": rules, "subjects": subjects,
            "policies": policies}
