"""The rig registry: ``rig.type`` names the factory that builds the slave's rig (as lerobot does).

A factory takes the config and the slave's transport session (None where there is none) and returns
a :class:`slave.rig.Rig` (one protocol over arrays of tendons: a single tendon, or the pairs of a
joint instrument). Registered here:

=============  ==============================================================================
``simulated``  the in-process simulators (:class:`slave.simulated.SimulatedRig`, one tendon;
               :class:`slave.pair_rig.SimulatedInstrument`, ``instrument.joints`` given;
               :class:`slave.spindle_rig.SpindleInstrument`, joints with a ``spindle_radius``)
``zenoh``      set-points out, samples in over Zenoh (:class:`slave.zenoh_rig.ZenohRig`, one tendon;
               :class:`slave.zenoh_rig.ZenohInstrument`, joints): a motor controller running
               zenoh-pico, or ``teleop bridge``
=============  ==============================================================================

Another rig is one :func:`register_rig` call; nothing else chooses by type.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

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
    if cfg.instrument.joints and cfg.instrument.joints[0].spindle_radius > 0:
        from slave.spindle_rig import SpindleInstrument
        return SpindleInstrument.from_config(cfg)
    if cfg.instrument.joints:
        from slave.pair_rig import SimulatedInstrument
        return SimulatedInstrument.from_config(cfg)
    from slave.simulated import SimulatedRig
    return SimulatedRig.from_config(cfg)


@register_rig("zenoh")
def _zenoh(cfg: Config, session: Any):
    if session is None:
        raise ConfigError("rig.type zenoh needs the slave's transport session")
    if cfg.instrument.joints and cfg.instrument.joints[0].spindle_radius > 0:
        raise ConfigError("rig.type zenoh drives a motor per tendon; a spindle-driven instrument "
                          "(instrument.joints[].spindle_radius > 0) runs on rig.type simulated")
    from slave.zenoh_rig import ZenohInstrument, ZenohRig
    return ZenohInstrument(session, cfg) if cfg.instrument.joints else ZenohRig(session, cfg)
