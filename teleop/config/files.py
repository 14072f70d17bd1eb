"""Where the configuration files that come with the project are: ``configs/`` of a source checkout, or
the copy installed with the package (``teleop/configs/``, made when the wheel is built: setup.py).

``configs/`` at the top of a checkout is the folder users edit; an installed package carries the same
files read-only, so that ``teleop demo`` and its ``--config configs/<name>.yaml`` work from any directory
after a plain (non-editable) install.
"""
from __future__ import annotations

import re
from collections.abc import Callable
from importlib import resources
from pathlib import Path

from teleop.errors import ConfigError

__all__ = ["configs_dir", "shipped_config", "resolve_config", "tool_file", "check_tool_file"]


def configs_dir() -> Path:
    """The project's configs: the copy installed with the package when there is one, else the checkout's
    ``configs/`` (an editable install or a source tree, where the files are edited in place)."""
    installed = Path(str(resources.files("teleop") / "configs"))
    if installed.is_dir():
        return installed
    return Path(__file__).resolve().parents[2] / "configs"


def shipped_config(name: str) -> Path:
    """``configs/<name>`` of the project (:func:`configs_dir`), e.g. ``shipped_config("sim.yaml")``; the
    path is returned whether or not the file exists (reading it names the missing file)."""
    return configs_dir() / name


def resolve_config(path: str | Path) -> Path:
    """``path`` itself when it is a file; otherwise a path written as ``configs/<name>`` (the form the
    documentation uses) names the project's own file when it exists; else ``path`` unchanged."""
    p = Path(path)
    if p.is_file() or not p.parts or p.parts[0] != "configs":
        return p
    own = configs_dir().joinpath(*p.parts[1:])
    return own if own.is_file() else p


def tool_file(name_or_path: str | Path) -> Path:
    """The file of a tool (:mod:`teleop.config.tools`): ``configs/tools/<NAME>.yaml`` for a bare name (letters, digits,
    ``_``, ``-``), else the path itself. Raises ConfigError when neither exists, listing the shipped tools."""
    s = str(name_or_path)
    tools = configs_dir() / "tools"
    p = tools / f"{s}.yaml" if re.fullmatch(r"[A-Za-z0-9_-]+", s) else Path(s)
    if p.is_dir():
        raise ConfigError(f"tool {s!r}: is a directory; expected a tool file (configs/tools/<NAME>.yaml)")
    if not p.is_file():
        shipped = ", ".join(sorted(f.stem for f in tools.glob("*.yaml"))) or "none"
        raise ConfigError(f"tool {s!r}: no such tool file ({p}); shipped tools: {shipped}")
    return p


def check_tool_file(name: str | None, key: str, error: Callable[[str, str], ConfigError]) -> None:
    """A config's tool (``key``, None: no tool) must name a tool file (:func:`tool_file`); ``error(key, message)``
    builds the ConfigError raised (naming the config file and line). The file itself is read by its user."""
    if name is None:
        return
    try:
        tool_file(name)
    except ConfigError as e:
        raise error(key, f"{key}: {e}") from None
