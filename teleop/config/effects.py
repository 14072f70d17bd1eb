"""``rig.simulated.effects``: the simulated rig's effect switches, derived from the effect catalogue.

Each catalogue entry with a rig switch (:mod:`estimator.offline.effects.catalogue`, ``Effect.switch``) is one
block ``rig.simulated.effects.<key>`` holding ``enabled`` (default false) and its settings (defaults,
SI units and valid ranges from the entry). This module turns those entries into the config: the
immutable :class:`EffectsConfig` the schema holds, its strict loading (:func:`merge_effects`), the
range table of its settings (:func:`effect_ranges`) and the commented YAML block of
configs/default.yaml (:func:`effects_block`). Nothing here names an effect: adding an entry to the
catalogue adds its block.
"""
from __future__ import annotations

import difflib
import math
from collections.abc import Callable, Mapping
from typing import Any

from teleop.errors import ConfigError

__all__ = ["EffectSwitch", "EffectsConfig", "merge_effects", "effect_ranges", "effects_block", "in_range",
           "switch_entries"]

PREFIX = "rig.simulated.effects"


def switch_entries() -> dict:
    """Switch key -> catalogue entry, in catalogue order (the live catalogue, registered entries included)."""
    from estimator.offline.effects.catalogue import rig_switches
    return rig_switches()


def in_range(v: float, rule: str) -> bool:
    """``v`` within a range rule: ``"any"``, ``"> x"``, ``">= x"`` or ``"lo..hi"`` (bounds included)."""
    if rule == "any":
        return True
    if ".." in rule:
        lo, hi = (float(x) for x in rule.split(".."))
        return lo <= v <= hi
    op, bound = rule.split()
    return v > float(bound) if op == ">" else v >= float(bound)


class EffectSwitch:
    """One effect switch: ``enabled`` and the values of its settings (SI units), read as attributes.

    ``EffectSwitch(True, viscous=20.0)``; settings not given take the catalogue default when the
    switch is placed in an :class:`EffectsConfig`.
    """

    __slots__ = ("enabled", "values")
    enabled: bool
    values: dict[str, float]

    def __init__(self, enabled: bool = False, **values: float):
        object.__setattr__(self, "enabled", enabled)
        object.__setattr__(self, "values", dict(values))

    def __getattr__(self, name: str) -> float:
        if name.startswith("__"):
            raise AttributeError(name)
        try:
            return self.values[name]
        except KeyError:
            raise AttributeError(f"effect switch has no setting {name!r} (has: {', '.join(self.values)})") from None

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError("EffectSwitch is immutable")

    def __reduce__(self) -> tuple:
        return (_switch, (self.enabled, self.values))

    def _key(self) -> tuple:
        return (self.enabled, tuple(sorted(self.values.items())))

    def __eq__(self, other: object) -> bool:
        return isinstance(other, EffectSwitch) and self._key() == other._key()

    def __hash__(self) -> int:
        return hash(self._key())

    def __repr__(self) -> str:
        return f"EffectSwitch({self.enabled!r}, " + ", ".join(f"{k}={v!r}" for k, v in self.values.items()) + ")"


class EffectsConfig:
    """The effect switches of the simulated rig: every catalogue switch, off at its defaults unless given.

    ``EffectsConfig(stiction=EffectSwitch(True, static_ratio=0.4))``; a switch reads as an attribute or
    item (``fx.stiction.static_ratio``, ``fx["stiction"]``). The catalogue is read when an instance
    is made, so an entry registered later appears in instances made after it.

    Raises
    ------
    ConfigError
        A switch key or setting the catalogue does not have.
    """

    __slots__ = ("switches",)
    switches: dict[str, EffectSwitch]

    def __init__(self, **switches: EffectSwitch):
        entries = switch_entries()
        for key in switches:
            if key not in entries:
                raise ConfigError(f"{PREFIX}.{key}: no such effect switch (known: {', '.join(entries)})")
        out = {}
        for key, e in entries.items():
            given = switches.get(key, EffectSwitch())
            values = e.switch.defaults()
            for name in given.values:
                if name not in values:
                    raise ConfigError(f"{PREFIX}.{key}.{name}: no such setting (known: enabled, {', '.join(values)})")
            values.update(given.values)
            out[key] = EffectSwitch(given.enabled, **values)
        object.__setattr__(self, "switches", out)

    def __getattr__(self, key: str) -> EffectSwitch:
        if key.startswith("__"):
            raise AttributeError(key)
        try:
            return self.switches[key]
        except KeyError:
            raise AttributeError(f"{PREFIX} has no switch {key!r}") from None

    def __getitem__(self, key: str) -> EffectSwitch:
        return self.switches[key]

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError("EffectsConfig is immutable")

    def __reduce__(self) -> tuple:
        return (_effects, (self.switches,))

    def enabled(self) -> tuple[str, ...]:
        """Keys of the switches that are on, catalogue order."""
        return tuple(k for k, s in self.switches.items() if s.enabled)

    def replace(self, **switches: EffectSwitch) -> EffectsConfig:
        """A copy with the given switches replaced."""
        return EffectsConfig(**{**self.switches, **switches})

    def as_dict(self) -> dict[str, dict[str, Any]]:
        """Plain YAML-ready data: ``{key: {"enabled": bool, setting: value, ...}}``."""
        return {k: {"enabled": s.enabled, **s.values} for k, s in self.switches.items()}

    def __eq__(self, other: object) -> bool:
        return isinstance(other, EffectsConfig) and self.switches == other.switches

    def __hash__(self) -> int:
        return hash(tuple(self.switches.items()))

    def __repr__(self) -> str:
        on = {k: s for k, s in self.switches.items() if s.enabled}
        return f"EffectsConfig({', '.join(f'{k}={s!r}' for k, s in on.items())})"


def _switch(enabled: bool, values: dict) -> EffectSwitch:
    return EffectSwitch(enabled, **values)


def _effects(switches: dict) -> EffectsConfig:
    return EffectsConfig(**switches)


def effect_ranges() -> dict[str, tuple[str, str]]:
    """Valid range and unit of every setting, ``{"rig.simulated.effects.<key>.<name>": (rule, unit)}``."""
    return {f"{PREFIX}.{k}.{s.name}": (s.valid, s.unit) for k, e in switch_entries().items() for s in e.switch.settings}


def _show(v: Any) -> str:
    kind = {dict: "a mapping", list: "a list", type(None): "nothing (null)"}.get(type(v))
    return kind or f"{v!r} ({type(v).__name__})"


def merge_effects(base: EffectsConfig | None, data: Any, path: str,
                  error: Callable[[str, str], ConfigError]) -> EffectsConfig:
    """``base`` (None: all off) with the switches of the YAML mapping ``data`` merged in, checked
    against the catalogue; ``error(dotted key, message)`` makes the ConfigError (file and line).

    Raises
    ------
    ConfigError
        Not a mapping; unknown switch or setting (with the closest known one); ``enabled`` not a bool;
        a setting that is not a finite number, or out of its range (rule and unit in the message).
    """
    base = base or EffectsConfig()
    if data is None:
        return base
    if not isinstance(data, Mapping):
        raise error(path, f"{path}: expected a mapping of effect switches, got {_show(data)}")
    entries = switch_entries()
    changes = {}
    for key, sub in data.items():
        p = f"{path}.{key}"
        if key not in entries:
            near = difflib.get_close_matches(str(key), list(entries), 1, 0.6)
            hint = f"did you mean '{path}.{near[0]}'?" if near else f"expected one of: {', '.join(entries)}"
            raise error(p, f"unknown key '{p}' ({hint}; effects are the catalogue's, "
                           "estimator/offline/effects/catalogue.py)")
        if sub is None:
            sub = {}
        if not isinstance(sub, Mapping):
            raise error(p, f"{p}: expected a mapping (enabled and settings), got {_show(sub)}")
        settings = {s.name: s for s in entries[key].switch.settings}
        old = base[key]
        enabled, values = old.enabled, dict(old.values)
        for name, v in sub.items():
            q = f"{p}.{name}"
            if name == "enabled":
                if not isinstance(v, bool):
                    raise error(q, f"{q}: expected true or false, got {_show(v)}")
                enabled = v
                continue
            if name not in settings:
                raise error(q, f"unknown key '{q}' (expected one of: enabled, {', '.join(settings)})")
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                raise error(q, f"{q}: expected a number, got {_show(v)}")
            v = float(v)
            if not math.isfinite(v):
                raise error(q, f"{q}: expected a finite number, got {v!r}")
            s = settings[name]
            if not in_range(v, s.valid):
                raise error(q, f"{q}: {v!r} is out of range: expected {s.valid} [{s.unit}]")
            values[name] = v
        changes[key] = EffectSwitch(enabled, **values)
    return base.replace(**changes)


def _number(v: float) -> str:
    return repr(v) if abs(v) >= 1e-3 or v == 0 else f"{v:g}"


def effects_block(indent: int = 4, column: int = 32) -> str:
    """The commented YAML of ``rig.simulated.effects`` in configs/default.yaml (every switch off at its
    defaults, one comment per line from the catalogue), ``indent`` spaces before each switch key."""
    pad = " " * indent
    lines = []

    def line(text: str, comment: str) -> None:
        lines.append(f"{text:<{column - 2}}  # {comment}" if len(text) < column - 2 else f"{text}  # {comment}")

    for key, e in switch_entries().items():
        line(f"{pad}{key}:", e.switch.summary)
        lines.append(f"{pad}  enabled: false")
        for s in e.switch.settings:
            line(f"{pad}  {s.name}: {_number(s.default)}",
                 f"{s.meaning} [{s.unit}]" + ("" if s.valid == "any" else f", {s.valid}"))
    return "\n".join(lines) + "\n"
