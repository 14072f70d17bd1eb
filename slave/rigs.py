"""The rig registry: ``rig.type`` names the factory that builds the slave's rig (as lerobot does).

A factory takes the config and the slave's transport session (None where there is none) and returns
a :class:`slave.rig.Rig` (one protocol over arrays of tendons: a single tendon, or the pairs of a
joint instrument). Registered here:

=============  ==============================================================================
``simulated``  the in-process simulator of the instrument's kind (:mod:`slave.kinds`)
``zenoh``      set-points out, samples in over Zenoh (the kind's networked rig, :mod:`slave.kinds`):
               a motor controller running zenoh-pico, or ``teleop bridge``
``recording``  a measured recording played as the hardware (:mod:`slave.recording.rig`; the recording's
               format chooses the rig)
=============  ==============================================================================

Another rig is one :func:`register_rig` call; nothing else chooses by type.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

from slave.kinds import slave_kind
from teleop.config.kinds import instrument_kind
from teleop.config.schema import Config
from teleop.errors import ConfigError

__all__ = ["RIG_TYPES", "register_rig", "make_rig"]

#: rig type -> factory(cfg, session) -> rig
RIG_TYPES: dict[str, Callable[[Config, Any], Any]] = {}


def register_rig(name: str):
    """Decorator: register ``factory(cfg, session)`` under ``rig.type`` ``name``."""
    def deco(factory):
        RIG_TYPES[name] = factory
        return factory
    return deco


def make_rig(cfg: Config, session: Any = None):
    """The rig of ``cfg.rig.type``.

    Raises
    ------
    ConfigError
        An unregistered type, or one that cannot drive this instrument (the message says which).
    """
    factory = RIG_TYPES.get(cfg.rig.type)
    if factory is None:
        raise ConfigError(f"rig.type: {cfg.rig.type!r} is not a registered rig (known: {', '.join(sorted(RIG_TYPES))})")
    return factory(cfg, session)


@register_rig("simulated")
def _simulated(cfg: Config, session: Any):
    return slave_kind(instrument_kind(cfg)).simulated(cfg)


@register_rig("zenoh")
def _zenoh(cfg: Config, session: Any):
    if session is None:
        raise ConfigError("rig.type zenoh needs the slave's transport session")
    return slave_kind(instrument_kind(cfg)).networked(session, cfg)


@register_rig("recording")
def _recording(cfg: Config, session: Any):
    from slave.recording.rig import recording_rig
    return recording_rig(cfg)
