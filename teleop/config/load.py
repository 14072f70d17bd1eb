"""Strict YAML loading of the configuration (the schema and the range table are :mod:`teleop.config.schema`).

Loading reads a file with :func:`teleop.config.reader.read_yaml` (YAML 1.2 core scalars, limits on size,
nesting and aliases), merges it over the defaults and rejects unknown keys, wrong types, out-of-range
values and paths of the wrong kind (:mod:`teleop.config.paths`) with a :class:`ConfigError` that names the
file and the dotted key. The section classes (``Config``, ``RigConfig``, ...) are in
:mod:`teleop.config.schema`.
"""
from __future__ import annotations

import dataclasses
import difflib
import math
import re
import types
from pathlib import Path
from typing import Any, Literal, Union, get_args, get_origin, get_type_hints

import yaml

from teleop.config.checks import check_joints, check_rerun_serve
from teleop.config.effects import EffectsConfig, in_range, merge_effects
from teleop.config.ranges import MOVED, RANGES
from teleop.config.reader import read_yaml
from teleop.config.schema import (
    Config,
    RunConfig,
)
from teleop.errors import ConfigError

__all__ = [
    "merge_dataclass", "ErrorContext", "load_config", "config_from_dict", "config_to_dict", "write_config",
]


# ---- loading: strict YAML -> Config ------------------------------------------------------------

_INF_OK = {"sheath.runs[].radius", "instrument.joints[].tendons.a.runs[].radius",
           "instrument.joints[].tendons.b.runs[].radius"}
_NON_SI = ("_mm", "_deg", "_ms", "_hz")


class _Ctx:
    """Where values come from (a file, or "overrides") and the line of each dotted key in it."""

    def __init__(self, source: str, lines: dict[str, int] | None = None):
        self.source, self.lines = source, lines or {}

    def error(self, path: str, msg: str) -> ConfigError:
        line = self.lines.get(path)
        return ConfigError(f"{self.source}:{line}: {msg}" if line else f"{self.source}: {msg}")


def _show(v: Any) -> str:
    kind = {dict: "a mapping", list: "a list", type(None): "nothing (null)"}.get(type(v))
    return kind or f"{v!r} ({type(v).__name__})"


def _schema_keys(cls: Any, prefix: str = "") -> list[str]:
    out = []
    for name, tp in get_type_hints(cls).items():
        p = f"{prefix}.{name}" if prefix else name
        out.append(p)
        if dataclasses.is_dataclass(tp):
            out += _schema_keys(tp, p)
        elif get_origin(tp) is tuple and dataclasses.is_dataclass(get_args(tp)[0]):
            out += _schema_keys(get_args(tp)[0], p + "[]")
    return out


def _unknown(ctx: _Ctx, path: str, name: str, siblings: list[str]) -> ConfigError:
    key = re.sub(r"\[\d+\]", "[]", path)
    if key in MOVED:
        return ctx.error(path, f"'{path}' has moved to '{MOVED[key]}' (a rig's config holds only that rig's "
                               f"settings; the simulator's live under rig.simulated): rename the key")
    for suf in _NON_SI:
        if name.endswith(suf) and name[: -len(suf)] in siblings:
            return ctx.error(path, f"unknown key '{path}': non-SI '{suf}' keys are accepted only where the "
                                   f"schema names them; give '{name[: -len(suf)]}' in SI units")
    prefix = path[: len(path) - len(name)]
    near = difflib.get_close_matches(path, [prefix + s for s in siblings] + _schema_keys(Config), 1, 0.6)
    hint = f" (did you mean '{near[0]}'?)" if near else f" (expected one of: {', '.join(siblings)})"
    return ctx.error(path, f"unknown key '{path}'{hint}")


def _convert(v: Any, tp: Any, path: str, ctx: _Ctx) -> Any:
    """Check ``v`` against the schema type ``tp`` and return it as that type."""
    rule_key = re.sub(r"\[\d+\]", "[]", path)
    if dataclasses.is_dataclass(tp):
        return _merge(tp, None, v, path, ctx)
    origin = get_origin(tp)
    if origin in (Union, types.UnionType) and type(None) in get_args(tp):   # X | None: null or an X
        if v is None:
            return None
        tp = next(a for a in get_args(tp) if a is not type(None))
        origin = get_origin(tp)
    if origin is Literal:
        if v not in get_args(tp) or isinstance(v, bool):
            choices = ", ".join(repr(c) for c in get_args(tp))
            raise ctx.error(path, f"{path}: expected one of {choices}, got {_show(v)}")
        return v
    if origin is tuple:
        if not isinstance(v, (list, tuple)):
            raise ctx.error(path, f"{path}: expected a list, got {_show(v)}")
        return tuple(_convert(x, get_args(tp)[0], f"{path}[{i}]", ctx) for i, x in enumerate(v))
    if tp is bool:
        if not isinstance(v, bool):
            raise ctx.error(path, f"{path}: expected true or false, got {_show(v)}")
        return v
    if tp is str:
        if not isinstance(v, str) or not v:
            raise ctx.error(path, f"{path}: expected a non-empty string, got {_show(v)}")
        return v
    if tp is int:
        if isinstance(v, bool) or not isinstance(v, int):
            raise ctx.error(path, f"{path}: expected an integer, got {_show(v)}")
    elif tp is float:
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise ctx.error(path, f"{path}: expected a number, got {_show(v)}")
        v = float(v)
        if math.isnan(v) or (math.isinf(v) and rule_key not in _INF_OK):
            raise ctx.error(path, f"{path}: expected a finite number, got {v!r}")
    else:  # pragma: no cover - a schema type this loader does not know
        raise TypeError(f"config schema type {tp!r} of {path} is not supported")
    rule, unit = RANGES.get(rule_key, ("any", ""))
    if not in_range(v, rule):
        raise ctx.error(path, f"{path}: {v!r} is out of range: expected {rule} [{unit}]")
    return v


def _merge(cls: Any, base: Any, data: Any, path: str, ctx: _Ctx) -> Any:
    """A ``cls`` instance: ``base`` (None: the field defaults) with the keys of ``data`` replaced."""
    if data is None:                     # an empty section: nothing overridden
        data = {}
    if not isinstance(data, dict):
        raise ctx.error(path, f"{path or 'top level'}: expected a mapping of settings, got {_show(data)}")
    hints = get_type_hints(cls)
    changes = {}
    for name, v in data.items():
        p = f"{path}.{name}" if path else str(name)
        if name not in hints:
            raise _unknown(ctx, p, str(name), list(hints))
        tp = hints[name]
        if tp is EffectsConfig:
            changes[name] = merge_effects(None if base is None else getattr(base, name), v, p, ctx.error)
        elif dataclasses.is_dataclass(tp):
            changes[name] = _merge(tp, None if base is None else getattr(base, name), v, p, ctx)
        else:
            changes[name] = _convert(v, tp, p, ctx)
    if base is not None:
        return dataclasses.replace(base, **changes)
    for f in dataclasses.fields(cls):
        if f.name not in changes and f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            raise ctx.error(path, f"{path}: missing key '{f.name}'")
    return cls(**changes)


def _check(cfg: Config, ctx: _Ctx, bounds: bool = True) -> Config:
    """Checks beyond one value's type and range; with ``bounds`` the hard bounds (teleop/config/bounds.py)."""
    from teleop.config.bounds import check_bounds
    from teleop.config.files import check_tool_file
    from teleop.config.paths import check_paths
    from teleop.wire.keys import validate_instrument_id
    try:
        validate_instrument_id(cfg.instrument.id)
    except ConfigError as e:
        raise ctx.error("instrument.id", str(e)) from None
    check_tool_file(cfg.instrument.tool, "instrument.tool", ctx.error)
    check_paths(cfg, ctx.error)
    for name in ("listen", "connect"):
        for i, ep in enumerate(getattr(cfg.transport, name)):
            if not re.fullmatch(r"[a-z0-9]+/\S+", ep):
                raise ctx.error(f"transport.{name}[{i}]", f"transport.{name}[{i}]: {ep!r} is not a zenoh "
                                                         f"endpoint (expected e.g. 'tcp/127.0.0.1:7447')")
    if not cfg.sheath.runs:
        raise ctx.error("sheath.runs", "sheath.runs: expected at least one run")
    if cfg.master.device.type == "hid" and not cfg.master.device.file:
        raise ctx.error("master.device.type", "master.device.file: a device file (configs/devices/*.yaml) "
                                              "is required when master.device.type is 'hid'")
    if not cfg.slave.x_in_min < cfg.slave.x_in_max:
        raise ctx.error("slave.x_in_max", f"slave.x_in_max ({cfg.slave.x_in_max!r} m) must be above "
                                          f"slave.x_in_min ({cfg.slave.x_in_min!r} m)")
    check_joints(cfg, ctx.error)
    check_rerun_serve(cfg, ctx.error)
    if bounds:
        check_bounds(cfg, ctx.error)
    return cfg


def _expand_dotted(overrides: dict) -> dict:
    """``{"rig.rate_hz": 500}`` -> ``{"rig": {"rate_hz": 500}}``, deep-merged with nested entries."""
    out: dict = {}
    for k, v in overrides.items():
        *parents, last = str(k).split(".")
        d = out
        for p in parents:
            d = d.setdefault(p, {})
        if isinstance(v, dict) and isinstance(d.get(last), dict):
            d[last] = {**d[last], **_expand_dotted(v)}
        else:
            d[last] = _expand_dotted(v) if isinstance(v, dict) else v
    return out


def config_from_dict(data: dict | None, *, source: str = "<dict>", base: Config | None = None) -> Config:
    """Apply a nested mapping of settings over ``base`` (default: the schema defaults).

    Raises
    ------
    ConfigError
        Unknown key, wrong type, value out of range (message names ``source`` and the dotted key).
    """
    ctx = _Ctx(source)
    return _check(_merge(Config, base or Config(), data, "", ctx), ctx)


def with_overrides(cfg: Config, overrides: dict) -> Config:
    """``cfg`` with dotted ``overrides`` applied (``{"pair_control.backlash_compensation": True}``), checked as
    :func:`load_config` checks its overrides.

    Raises
    ------
    ConfigError
        Unknown key, wrong type, value out of range or past a hard bound without its waiver.
    """
    return config_from_dict(_expand_dotted(overrides), source="overrides", base=cfg)


def load_config(path: str | Path | None = None, overrides: dict | None = None) -> Config:
    """Load a YAML config over the defaults, then apply ``overrides``.

    The dataclass defaults are the defaults (configs/default.yaml spells them out); a file changes only
    the keys it names (sections merge deeply, lists are replaced whole).

    Parameters
    ----------
    path : str or Path, optional
        YAML file; None: defaults only.
    overrides : dict, optional
        Nested (``{"rig": {"rate_hz": 500}}``) or dotted (``{"rig.rate_hz": 500}``) settings applied
        last; errors name them as ``overrides``.

    Returns
    -------
    Config

    Raises
    ------
    ConfigError
        Missing, unreadable or oversized file, or a directory; YAML syntax error or a limit of
        :mod:`teleop.config.reader` passed (file, line, column); duplicate key; unknown key (with the closest
        known key); wrong type (key, expected type, value); value out of range (key, range, unit); invalid
        instrument id or endpoint; a path of the wrong kind (a directory for a file or a file for a
        directory). Messages start with ``<file>:<line>:``.
    """
    cfg = Config()
    if path is not None:
        data, lines = read_yaml(Path(path))
        ctx = _Ctx(str(path), lines)
        cfg = _check(_merge(Config, cfg, data, "", ctx), ctx, bounds=not overrides)  # overrides may waive
    if overrides:
        cfg = with_overrides(cfg, overrides)
    return cfg


def config_to_dict(cfg: Any) -> Any:
    """Plain YAML-ready data of a config (lists for tuples; a straight run omits its radius).

    ``config_from_dict(config_to_dict(cfg)) == cfg`` for every valid ``cfg``.
    """
    if isinstance(cfg, RunConfig):
        return {"length": cfg.length} if math.isinf(cfg.radius) else {"length": cfg.length, "radius": cfg.radius}
    if isinstance(cfg, EffectsConfig):
        return cfg.as_dict()
    if dataclasses.is_dataclass(cfg):
        return {f.name: config_to_dict(getattr(cfg, f.name)) for f in dataclasses.fields(cfg)}
    if isinstance(cfg, (tuple, list)):
        return [config_to_dict(x) for x in cfg]
    return cfg


def write_config(cfg: Config, path: str | Path) -> Path:
    """Write the resolved config as YAML (e.g. next to a recording); returns the path."""
    path = Path(path)
    text = "# resolved teleop configuration (every setting, SI units unless the key has a suffix)\n"
    path.write_text(text + yaml.safe_dump(config_to_dict(cfg), sort_keys=False), encoding="utf-8")
    return path

# for the other strict YAML files (teleop.config.tools; read_yaml: teleop.config.reader)
merge_dataclass, ErrorContext = _merge, _Ctx
check_config = _check          # the checks of one whole config, for files that hold several (teleop.arms)
