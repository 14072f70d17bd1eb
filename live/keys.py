"""``teleop keys``: the installation's credentials (teleop/session/credentials.py): where they are, made if missing,
renewed on request, copied for another machine.

The sides, the recorder, the bridge and the router make the credentials on first use; this command shows
them. A second machine of the same session needs the same folder: ``teleop keys --export DIR`` writes a copy
(mode 0700, files 0600) to carry over (by ``scp``, a USB stick, never a shared or world-readable folder), and
``TSM_TELEOP_KEYS=DIR`` (or the copy put at the default place) points that machine's processes at it.
"""
from __future__ import annotations

import argparse
import json
import shutil
import sys
from pathlib import Path

__all__ = ["add_arguments", "main_keys"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``teleop keys``."""
    p.add_argument("--renew", action="store_true",
                   help="replace every role's password (running processes keep their links until they reconnect)")
    p.add_argument("--export", metavar="DIR", default=None,
                   help="write a copy of the credentials to DIR (must not exist) for another machine")
    p.add_argument("--zenoh-config", metavar="ROLE", default=None, choices=("master", "slave", "rig", "observer"),
                   help="print the Zenoh config entries of ROLE (user, password, dictionary, access control) as JSON, "
                        "to merge into another Zenoh program's config (rmw_zenoh's router and nodes: "
                        "docs/how-to/ros2.md)")


def main_keys(args: argparse.Namespace) -> int:
    """``teleop keys``: print the folder and its roles; ``--renew`` first renews them, ``--export DIR`` copies them,
    ``--zenoh-config ROLE`` prints that role's Zenoh settings as JSON instead.

    Raises
    ------
    ConfigError
        The folder cannot be made or read, is open to other users, or ``--export`` names an existing path.
    """
    from teleop.errors import ConfigError
    from teleop.session.credentials import ROLES, ensure_credentials, keys_dir, renew_credentials
    folder = keys_dir()
    if args.renew:
        renew_credentials(folder)
    creds = [ensure_credentials(role, folder) for role in ROLES]
    if args.zenoh_config:
        print(json.dumps(_nested(ensure_credentials(args.zenoh_config, folder).zenoh_settings()), indent=2))
        return 0
    print(f"installation credentials: {folder}")
    for c in creds:
        print(f"  {c.role:<9} user {c.role!r}, password in {c.password_file.name}")
    print(f"  listeners check {creds[0].dictionary_file.name} (every role's user:password, mode 0600)")
    if args.export:
        out = Path(args.export)
        if out.exists():
            raise ConfigError(f"--export {out}: already exists; name a new folder")
        shutil.copytree(folder, out)
        out.chmod(0o700)
        print(f"copied to {out}: on the other machine set TSM_TELEOP_KEYS={out} (or move it to {folder})")
    sys.stdout.flush()
    return 0


def _nested(settings: dict[str, object]) -> dict[str, object]:
    """``{"transport/auth/usrpwd/user": u}`` -> ``{"transport": {"auth": {"usrpwd": {"user": u}}}}``."""
    out: dict[str, object] = {}
    for path, value in settings.items():
        *parents, last = path.split("/")
        node = out
        for p in parents:
            node = node.setdefault(p, {})      # type: ignore[assignment]
        node[last] = value
    return out
