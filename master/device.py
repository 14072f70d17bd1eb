"""The haptic device seen by the master: a small protocol and the state it reports.

A device is anything that can report where the operator's hand is and render a force along the
same axis. The master node reads it once per cycle and writes one force per cycle; it never asks a
device for anything else. Axis convention (one tendon, one axis): + device displacement draws the
tendon toward the actuator (a pull); the rendered force that resists a pull is therefore negative.

Devices that stand in for a human (:mod:`master.simulated`) may also implement
:class:`OperatorView`: the master node then shows them what a surgeon would see on the endoscope,
namely the latest proximal tension and whether teleoperation is engaged.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

__all__ = ["DeviceState", "MultiAxisState", "HapticDevice", "OperatorView"]


@dataclass(frozen=True)
class DeviceState:
    """One reading of a haptic device.

    Attributes
    ----------
    t : float
        Time of the reading [s], on the master's clock.
    position : float
        Handle position along the device axis [m], + = pull.
    buttons : int
        Button bit mask (bit 0 = first button); 0 when none are pressed.
    operator_present : bool
        The operator holds the handle (deadman switch). A device without such a sensor reports True.
    """

    t: float
    position: float
    buttons: int = 0
    operator_present: bool = True


@dataclass(frozen=True)
class MultiAxisState:
    """One reading of a device with several axes (one per axis of a joint instrument).

    Attributes
    ----------
    t : float, time of the reading [s].
    positions : tuple of float, handle position per device axis [m], + pulls tendon a of its joint.
    buttons : int, button bit mask.
    operator_present : bool, deadman.
    """

    t: float
    positions: tuple[float, ...]
    buttons: int = 0
    operator_present: bool = True


@runtime_checkable
class HapticDevice(Protocol):
    """What the master node needs from a haptic device."""

    def read(self, t: float) -> DeviceState:
        """Return the device state at time ``t`` [s] (master clock).

        Raises
        ------
        DeviceError
            The device cannot be read (unplugged, I/O error).
        """
        ...

    def set_force(self, force: float, t: float) -> None:
        """Render ``force`` [N] along the device axis from time ``t`` [s] on.

        The caller has already clamped, ramped and rate-limited it (:mod:`master.mapping`); a device
        may still apply its own hardware limit.
        """
        ...

    def close(self) -> None:
        """Render zero force and release the device; safe to call more than once."""
        ...


@runtime_checkable
class OperatorView(Protocol):
    """Optional: a simulated operator watches the instrument like a surgeon on the endoscope."""

    def watch(self, T_in: Any, engaged: bool) -> None:
        """Latest proximal tensions [N] - per instrument axis a tuple, one per tendon (a single tendon:
        ``[(T_in,)]``; :meth:`master.axes.InstrumentAxes.view`), None: nothing received yet - and
        whether control is engaged."""
        ...
