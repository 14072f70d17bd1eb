"""A bimanual instrument: two arms, each an ordinary instrument, each driven by one hand of the console.

A bimanual config file (``configs/notes-bimanual.yaml``) is an ordinary config (the *base*: every
setting the arms share: rate, estimator, calibration, watchdogs, transport, recording) with a top-level
``arms:`` list. Each entry names the arm (``name``), the hand that drives it (``hand``: ``left`` or
``right``) and overlays the base with its own sections: ``instrument`` (its own ``id``, so its own
Zenoh keys ``teleop/<id>/...`` and its own CRTK arm name), ``rig`` (its simulated physics),
``pair_control`` and ``master`` (that hand's device and mapping). Loading gives one ordinary
:class:`~teleop.config.load.Config` per arm, checked as any config is (:func:`teleop.config.load.load_config`),
so every tool of a single instrument (calibration, recorder, evaluation) works on each arm as it is.

Both sides run both arms in one loop (one process per side), so the arms share the loop rate
(``rig.rate_hz``, ``master.rate_hz``), the transport and the heartbeat rate: an arm may not
override them. Errors name the file and the line of the offending key, as every config error does.
"""
from __future__ import annotations

import copy
import dataclasses
from pathlib import Path
from typing import Any

from teleop.config.load import ErrorContext, check_config, merge_dataclass
from teleop.config.reader import read_yaml
from teleop.config.schema import Config
from teleop.errors import ConfigError

__all__ = ["HANDS", "ARM_SECTIONS", "Arm", "Bimanual", "is_bimanual", "load_arms", "repeated_joints"]

#: The hands of the console, each driving exactly one arm.
HANDS = ("left", "right")
#: The sections an arm entry may overlay on the base config.
ARM_SECTIONS = ("instrument", "rig", "pair_control", "master")
#: Settings both arms share because one loop per side runs them: an arm may not override them.
SHARED = ("rig.rate_hz", "rig.type", "master.rate_hz")


@dataclasses.dataclass(frozen=True)
class Arm:
    """One arm of a bimanual instrument.

    Attributes
    ----------
    name : str
        The arm's name in the bimanual file (``arms[].name``).
    hand : str
        The console's hand that drives it, one of :data:`HANDS`.
    cfg : Config
        The arm's whole config (base overlaid with the arm's sections).
    """

    name: str
    hand: str
    cfg: Config

    @property
    def ident(self) -> str:
        """The arm's instrument id (its key-expression segment)."""
        return self.cfg.instrument.id


@dataclasses.dataclass(frozen=True)
class Bimanual:
    """The arms of a bimanual config, in file order, and the file they came from."""

    arms: tuple[Arm, ...]
    source: str

    def by_hand(self, hand: str) -> Arm:
        """The arm driven by ``hand`` (``left`` or ``right``)."""
        return next(a for a in self.arms if a.hand == hand)


def is_bimanual(path: str | Path | None) -> bool:
    """Whether the YAML file at ``path`` has a top-level ``arms:`` list (cheap: no schema check).

    A missing or unreadable file is not bimanual (the ordinary loader then says what is wrong with it)."""
    if path is None:
        return False
    try:
        data, _ = read_yaml(Path(path))
    except ConfigError:
        return False
    return isinstance(data, dict) and "arms" in data


def _deep_merge(base: dict, over: dict) -> dict:
    """``base`` with ``over`` merged in, mappings deeply, every other value (lists too) replaced."""
    out = copy.deepcopy(base)
    for k, v in over.items():
        out[k] = _deep_merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else copy.deepcopy(v)
    return out


def _has(data: dict, dotted: str) -> bool:
    d: Any = data
    for part in dotted.split("."):
        if not isinstance(d, dict) or part not in d:
            return False
        d = d[part]
    return True


def _arm_entry(i: int, entry: Any, ctx: Any) -> tuple[str, str, dict]:
    """(name, hand, overlay) of ``arms[i]``; unknown keys, a bad name or hand, a shared setting overridden: errors."""
    where = f"arms[{i}]"
    if not isinstance(entry, dict):
        raise ctx.error(where, f"{where}: expected a mapping with name, hand and {', '.join(ARM_SECTIONS)}")
    for key in entry:
        if key not in ("name", "hand") + ARM_SECTIONS:
            raise ctx.error(f"{where}.{key}", f"unknown key '{where}.{key}' (an arm has name, hand and "
                                              f"{', '.join(ARM_SECTIONS)})")
    name, hand = entry.get("name"), entry.get("hand")
    if not isinstance(name, str) or not name:
        raise ctx.error(where, f"{where}.name: expected the arm's name (a non-empty string), got {name!r}")
    if hand not in HANDS:
        raise ctx.error(f"{where}.hand" if "hand" in entry else where,
                        f"{where}.hand ({name}): expected one of {', '.join(HANDS)}, got {hand!r}")
    overlay = {k: v for k, v in entry.items() if k in ARM_SECTIONS}
    for key in SHARED:
        if _has(overlay, key):
            raise ctx.error(f"{where}.{key}", f"{where}.{key} ({name}): both arms run in one loop per side; "
                                              f"set {key} once, outside arms")
    return name, hand, overlay


def load_arms(path: str | Path) -> Bimanual:
    """Load a bimanual config (module docstring) into one checked :class:`Config` per arm.

    Parameters
    ----------
    path : str or Path
        A YAML file with a top-level ``arms:`` list of two entries.

    Returns
    -------
    Bimanual

    Raises
    ------
    ConfigError
        Everything :func:`teleop.config.load.load_config` refuses (in the base or in an arm), and: no ``arms``
        list or not two arms; an unknown key in an arm; duplicate arm names or instrument ids; a hand
        driving two arms or a hand driving none; an arm overriding a shared setting (:data:`SHARED`).
        The message starts with ``<file>:<line>:``.
    """
    data, lines = read_yaml(Path(path))
    source = str(path)
    ctx = ErrorContext(source, lines)
    if not isinstance(data, dict) or not isinstance(data.get("arms"), list):
        raise ctx.error("arms", "arms: expected a list of the two arms (name, hand, instrument, ...)")
    entries = data["arms"]
    if len(entries) != len(HANDS):
        raise ctx.error("arms", f"arms: expected {len(HANDS)} arms (one per hand), got {len(entries)}")
    base = {k: v for k, v in data.items() if k != "arms"}
    arms: list[Arm] = []
    for i, entry in enumerate(entries):
        name, hand, overlay = _arm_entry(i, entry, ctx)
        prefix = f"arms[{i}]."
        arm_lines = {**lines, **{k[len(prefix):]: v for k, v in lines.items() if k.startswith(prefix)}}
        actx = ErrorContext(source, arm_lines)
        merged = _deep_merge(base, overlay)
        cfg = check_config(merge_dataclass(Config, Config(), merged, "", actx), actx)
        for other in arms:
            if other.name == name:
                raise ctx.error(f"arms[{i}].name", f"arms[{i}].name: {name!r} is already the name of another arm")
            if other.hand == hand:
                free = next(h for h in HANDS if h != hand)
                raise ctx.error(f"arms[{i}].hand", f"arms[{i}].hand ({name}): the {hand} hand already drives "
                                                   f"arm {other.name!r} and the {free} hand drives no arm; "
                                                   f"each hand drives one arm")
            if other.cfg.instrument.id == cfg.instrument.id:
                raise ctx.error(f"arms[{i}].instrument.id", f"arms[{i}].instrument.id ({name}): "
                                f"{cfg.instrument.id!r} is also arm {other.name!r}'s; each arm has its own id")
        arms.append(Arm(name, hand, cfg))
    return Bimanual(tuple(arms), source)


def repeated_joints(cfg: Config, n: int, ident: str) -> Config:
    """``cfg``'s joint instrument with its joints (and their simulated physics) repeated to ``n`` joints, named
    ``<joint><k>``, instrument id ``ident``, the pair controller on every joint (device axis k for joint k): an
    instrument of any size from one that is checked, for the scaling benchmark and the many-axis tests.

    Parameters
    ----------
    cfg : Config
        A joint instrument (``instrument.joints`` and ``rig.simulated.joints`` of equal length >= 1).
    n : int
        Joints of the result, 1..:data:`teleop.config.checks.MAX_JOINTS` (not checked here: the loader checks).
    ident : str
        The result's ``instrument.id``.

    Raises
    ------
    ConfigError
        ``cfg`` has no joints.
    """
    inst, sim = cfg.instrument.joints, cfg.rig.simulated.joints
    if not inst or len(sim) != len(inst):
        raise ConfigError(f"repeated_joints: {cfg.instrument.id!r} is not a joint instrument with simulated joints")
    m = len(inst)
    joints = tuple(dataclasses.replace(inst[k % m], name=f"{inst[k % m].name}{k}") for k in range(n))
    sims = tuple(dataclasses.replace(sim[k % m], name=f"{sim[k % m].name}{k}") for k in range(n))
    return dataclasses.replace(
        cfg, instrument=dataclasses.replace(cfg.instrument, id=ident, joints=joints),
        rig=dataclasses.replace(cfg.rig, simulated=dataclasses.replace(cfg.rig.simulated, joints=sims)),
        pair_control=dataclasses.replace(cfg.pair_control, axes=tuple(range(n))))
