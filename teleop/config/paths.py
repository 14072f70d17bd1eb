"""The kind of every path a configuration or a command line names: a file where a file is read, a directory
where files are written.

:func:`check_paths` runs when a config is loaded (:func:`teleop.config.load.load_config`), so a wrong kind is refused
with one line naming the key before any process starts, not when a side first opens the path (inside its loop,
or after a calibration). :func:`path_problem` is the same check for one path, for the command line's arguments
(:mod:`live.cli`). A path that does not exist is left to its user: an output directory is made, a missing input
file is named by its reader.
"""
from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any, Literal

from teleop.errors import ConfigError

__all__ = ["FILE_KEYS", "DIR_KEYS", "path_problem", "check_paths"]

#: Config keys naming a file that is read (None: not set; ``instrument.tool`` is checked by
#: :func:`teleop.config.files.check_tool_file`, a bare name being a shipped tool).
FILE_KEYS: tuple[str, ...] = (
    "rig.recording.path", "master.device.file", "transport.tls.root_ca", "transport.tls.certificate",
    "transport.tls.private_key", "transport.auth.password_file", "transport.auth.dictionary_file",
    "estimator.model")
#: Config keys naming a directory that files are written into (made when missing).
DIR_KEYS: tuple[str, ...] = ("recording.dir", "calibration.dir")
#: Keys whose users expand a leading ``~`` (the others take the path as written).
_EXPANDED = frozenset({"rig.recording.path", "estimator.model"})


def path_problem(path: str | Path, want: Literal["file", "dir"]) -> str | None:
    """What is wrong with ``path`` as a ``want`` ("file": read; "dir": written into, made when missing), or None.

    A file is wrong when the path is a directory; a directory is wrong when the path exists and is not one, or
    when the nearest existing folder above it is not a directory (nothing can be made under a file). A path the
    system cannot look at (an embedded NUL, a name too long, no permission) is wrong too.
    """
    p = Path(path)
    try:
        if want == "file":
            return "is a directory; expected a file" if p.is_dir() else None
        if p.exists():
            return None if p.is_dir() else "is a file, not a directory; expected a directory"
        for parent in p.parents:
            if parent.exists():
                return None if parent.is_dir() else f"cannot be made: {str(parent)!r} is a file; expected a directory"
    except (OSError, ValueError) as e:
        return f"is not a usable path ({e})"
    return None


def check_paths(cfg: Any, error: Callable[[str, str], ConfigError]) -> None:
    """Every key of :data:`FILE_KEYS` and :data:`DIR_KEYS` that ``cfg`` sets names a path of its kind.

    Raises
    ------
    ConfigError
        Built by ``error(key, message)`` (the config file and the key's line): a directory where a file is
        read, a file where a directory is written, a path that cannot be used.
    """
    for keys, want in ((FILE_KEYS, "file"), (DIR_KEYS, "dir")):
        for key in keys:
            value: Any = cfg
            for part in key.split("."):
                value = getattr(value, part)
            if value is None:
                continue
            path = Path(value).expanduser() if key in _EXPANDED else Path(value)
            problem = path_problem(path, "file" if want == "file" else "dir")
            if problem is not None:
                raise error(key, f"{key}: {value!r} {problem}")
