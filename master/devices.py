"""The haptic-device registry: ``master.device.type`` names the factory of the master's device.

A factory takes the config and the operator protocol name (scripted operators) and returns a
device for the configured instrument (one axis for a single tendon, one per joint otherwise).
Registered here:

=============  ==============================================================================
``simulated``  a scripted operator: :class:`master.simulated.ScriptedOperator`, one hand axis per
               instrument axis (a single tendon: one; a joint instrument: one per joint)
``hid``        a USB HID device described by ``master.device.file`` (:class:`master.hid.HidDevice`;
               a joint instrument needs one position axis and one force report map per joint)
``evdev``      a force-feedback joystick or wheel through Linux kernel force feedback
               (:class:`master.evdev_device.EvdevDevice`, extra ``evdev``; ``master.device.file``
               optional); a single-tendon instrument
``forcedimension``  a Force Dimension device (:mod:`master.vendor_devices`, extra ``forcedimension``
               and the vendor's DHD library); a single-tendon instrument
``touch``      a 3D Systems Touch (:mod:`master.vendor_devices`, extra ``touch`` and the OpenHaptics
               HD library); a single-tendon instrument
=============  ==============================================================================

An extra that is not installed, or a vendor library that is missing, raises :class:`DeviceError` with
one line naming what to install.

Another device is one :func:`register_device` call; nothing else chooses by type.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

from teleop.config.kinds import instrument_kind
from teleop.config.schema import Config
from teleop.errors import ConfigError, DeviceError

__all__ = ["DEVICE_TYPES", "register_device", "make_device", "device_axes_needed"]

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
    from master.arm import ArmParameters
    clutch = cfg.master.mapping.clutch_button
    arm = ArmParameters.from_config(cfg.master.device.arm)
    from master.kinds import operator_protocols
    from master.simulated import ScriptedOperator
    return ScriptedOperator(operator_protocols(cfg, protocol), clutch_bit=clutch, arm=arm)


def device_axes_needed(cfg: Config) -> int:
    """How many device axes the instrument needs: 1 for a tendon, else the highest ``pair_control.axes``
    entry + 1 (default one per joint)."""
    from master.kinds import master_kind
    return master_kind(instrument_kind(cfg)).device_axes(cfg)


@register_device("hid")
def _hid(cfg: Config, protocol: str):
    from master.hid import HidDevice, load_device_file
    path = cfg.master.device.file
    if not path:    # teleop.config.load checks this on load; a Config built in code may skip that check
        raise ConfigError("master.device.file: a device file (configs/devices/*.yaml) is required when "
                          "master.device.type is 'hid'")
    dev = load_device_file(path)
    have, need = len(dev.input.position_axes), device_axes_needed(cfg)
    if have < need:
        raise DeviceError(f"{path}: the device has {have} position axis(es), the instrument needs "
                          f"{need} (input.position_axes, with one force report map per axis)")
    # opens, resets and enables the actuators; raises DeviceError naming the device when absent
    return HidDevice(dev)


def _one_axis(cfg: Config, kind: str) -> None:
    if device_axes_needed(cfg) != 1:
        raise DeviceError(f"master.device.type {kind}: drives one axis, the instrument needs "
                          f"{device_axes_needed(cfg)} (use hid with one position axis per joint)")


@register_device("evdev")
def _evdev(cfg: Config, protocol: str):
    from master.evdev_device import EvdevDevice, evdev_module, load_evdev_file
    _one_axis(cfg, "evdev")
    ev = evdev_module()                    # one line naming the extra when python-evdev is missing
    return EvdevDevice(load_evdev_file(cfg.master.device.file), ev)


def _vendor(cfg: Config, kind: str):
    from master.vendor_devices import DhdAdapter, TouchAdapter, VendorDevice, load_vendor_file, sdk_module
    _one_axis(cfg, kind)
    sdk = sdk_module(kind)                 # one line naming the package or the vendor library when missing
    vcfg = load_vendor_file(kind, cfg.master.device.file)
    return VendorDevice(vcfg, DhdAdapter(sdk) if kind == "forcedimension" else TouchAdapter(sdk))


@register_device("forcedimension")
def _forcedimension(cfg: Config, protocol: str):
    return _vendor(cfg, "forcedimension")


@register_device("touch")
def _touch(cfg: Config, protocol: str):
    return _vendor(cfg, "touch")
