"""The instrument's kind, read from its config in one place: every floor's registry of kinds is keyed by it.

* ``tendon``: a single tendon (``instrument.joints`` empty);
* ``pair``: 1 to 16 antagonistic pairs, a motor per tendon (``instrument.joints`` given);
* ``spindle``: 1 to 16 spindle-driven cable pairs, one motor and two cables each (every joint's
  ``spindle_radius`` > 0).

A bimanual instrument is a composition of arms (:mod:`teleop.arms`), each arm of one of these kinds. The
registries keyed by the kind: :mod:`slave.kinds` (the slave's axis, simulated and networked rigs),
:mod:`master.kinds` (the master's axes and operator protocols), :mod:`live.kinds` (the demo, the replay, the
Rerun view's extras).
"""
from __future__ import annotations

from typing import TYPE_CHECKING

from teleop.errors import ConfigError

if TYPE_CHECKING:
    from teleop.config.schema import Config

__all__ = ["KINDS", "instrument_kind", "unknown_kind"]

#: The kinds of instrument, each with the words a message uses for it.
KINDS = {"tendon": "single tendon", "pair": "antagonistic pair", "spindle": "spindle-driven pair"}


def instrument_kind(cfg: Config) -> str:
    """The kind of the instrument of ``cfg``: one of :data:`KINDS`.

    Raises
    ------
    ConfigError
        Some joints have a ``spindle_radius`` and others not (all axes of an instrument are of one kind).
    """
    joints = cfg.instrument.joints
    if not joints:
        return "tendon"
    spindles = [j.spindle_radius > 0 for j in joints]
    if any(spindles) and not all(spindles):
        raise ConfigError("instrument.joints[].spindle_radius: every joint of an instrument is spindle-driven "
                          "(> 0) or none is (0)")
    return "spindle" if spindles[0] else "pair"


def unknown_kind(kind: str, registry: str) -> LookupError:
    """The one error of a registry asked for a kind it does not hold: names the kind, the registry and the kinds."""
    return LookupError(f"{registry}: no instrument kind {kind!r} (kinds: {', '.join(KINDS)})")
