"""The haptic-device registry: ``master.device.type`` names the factory of the master's device.

A factory takes the config and the operator protocol name (scripted operators) and returns a
device for the configured instrument (one axis for a single tendon, one per joint otherwise).
Registered here:

=============  ==============================================================================
``simulated``  a scripted operator: :class:`master.simulated.ScriptedOperator` on one tendon,
               :class:`master.joint_operator.MultiAxisOperator` (one axis per joint) otherwise
``hid``        a USB HID device described by ``master.device.file`` (:class:`master.hid.HidDevice`;
               one axis so far: refused for a joint instrument)
=============  ==============================================================================

Another device is one :func:`register_device` call; nothing else chooses by type.
"""
from __future__ import annotations

from typing import Any, Callable

from teleop.config import Config
from teleop.errors import ConfigError, DeviceError

__all__ = ["DEVICE_TYPES", "register_device", "make_device"]

#: device type -> factory(cfg, protocol) -> device
DEVICE_TYPES: dict[str, Callable[[Config, str], Any]] = {}


def register_device(name: str):
    """Decorator: register ``factory(cfg, protocol)`` under ``master.device.type`` ``name``."""
    def deco(factory):
        DEVICE_TYPES[name] = factory
        return factory
    return deco


def make_device(cfg: Config, protocol: str = "paper,minor"):
    """The device of ``cfg.master.device.type`` (opened: the caller closes it).

    Raises
    ------
    ConfigError
        An unregistered type, or an unknown protocol.
    DeviceError
        The device cannot drive this instrument or cannot be opened (named).
    """
    factory = DEVICE_TYPES.get(cfg.master.device.type)
    if factory is None:
        raise ConfigError(f"master.device.type: {cfg.master.device.type!r} is not a registered device "
                          f"(known: {', '.join(sorted(DEVICE_TYPES))})")
    return factory(cfg, protocol)


@register_device("simulated")
def _scripted(cfg: Config, protocol: str):
    clutch = cfg.master.mapping.clutch_button
    if cfg.instrument.joints:
        from master.joint_operator import MultiAxisOperator, joint_protocols
        return MultiAxisOperator(joint_protocols(cfg, protocol), clutch_bit=clutch)
    from master.simulated import ScriptedOperator, build_protocol
    return ScriptedOperator(build_protocol(protocol), clutch_bit=clutch)


@register_device("hid")
def _hid(cfg: Config, protocol: str):
    if cfg.instrument.joints:
        raise DeviceError("master.device.type: a HID device drives a single tendon so far (one report map per "
                          "axis is not there yet); joint instruments have the simulated multi-axis operator")
    from master.hid import HidDevice
    # opens, resets and enables the actuators; raises DeviceError naming the device when absent
    return HidDevice.from_file(cfg.master.device.file)
