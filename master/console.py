"""Surgeon-console logic of the master: deadman, clutch, alignment, engage/disengage decisions.

Every cycle :meth:`Console.update` decides whether the operator is in control, in this order:

=================================  ===============  ==================================================
condition                          status           motion / force
=================================  ===============  ==================================================
links not healthy                  ``WAIT_SLAVE``   command holds; force 0
operator absent (deadman open)     ``WAIT_OPERATOR``  command holds; force 0
clutch button held                 ``CLUTCH``       command holds, hand free; force 0
first engage, or clutch released   (re-anchor)      device-to-tendon offset set from the slave's x_in
mapped handle within tolerance     ``ENGAGED``      ``x_cmd = x_anchor + s (p - p_anchor)``; force ramps in
of the slave's x_in (or engaged)
otherwise                          ``ALIGN``        refused: command holds, force 0, prompt says how far
=================================  ===============  ==================================================

*Re-anchoring* (first engage, clutch release) sets the offset so that the present handle position
maps to the slave's present ``x_in``: the instrument does not jump and the two are aligned by
construction. After any other interruption (link loss, deadman released) the offset is kept, so
the handle must come back to where it maps onto the instrument - within
``master.mapping.align_tolerance`` of the slave's measured ``x_in`` - before control resumes. The
operator gets there by moving the handle back or by clutching (press, move freely, release). The
alignment is checked only on the way into ENGAGED; once engaged the slave lags the command a little
and that is not a misalignment.

Engage edges restart the force ramp (the caller does that with :attr:`Console.engaged_now`).
"""
from __future__ import annotations

import math
from enum import IntEnum

from master.device import DeviceState
from master.mapping import MotionMap
from teleop.errors import ConfigError

__all__ = ["ConsoleStatus", "Console"]


class ConsoleStatus(IntEnum):
    """What the console shows the operator (recorded per cycle in the master's CSV)."""

    WAIT_SLAVE = 0
    WAIT_OPERATOR = 1
    ALIGN = 2
    CLUTCH = 3
    ENGAGED = 4
    STOPPING = 5


class Console:
    """Engage decisions of one axis (see the module docstring).

    Parameters
    ----------
    motion : MotionMap
        The map whose anchor the console sets (shared with the caller).
    align_tolerance : float
        Largest |mapped handle - slave x_in| that may engage [m of tendon], > 0.
    clutch_button : int
        Bit of :attr:`DeviceState.buttons` that is the clutch; -1: no clutch.
    unit_length : float
        Tendon displacement per unit of the axis [m/unit]: 1 for a tendon (positions in m), the pulley
        radius r for a joint (positions in rad, ``align_tolerance`` then in rad); used by the prompt.

    Attributes
    ----------
    status : ConsoleStatus
    misalignment : float
        Mapped handle minus slave ``x_in`` at the last refusal [m] (0 when aligned).
    engaged_now, released_now : bool
        This update entered / left ENGAGED.
    clutches, refusals : int
        Clutch releases (re-anchors), and engage attempts refused for misalignment.
    """

    def __init__(self, motion: MotionMap, align_tolerance: float, clutch_button: int = -1, unit_length: float = 1.0):
        if not (math.isfinite(align_tolerance) and align_tolerance > 0):
            raise ConfigError(f"master.mapping.align_tolerance must be > 0 m, got {align_tolerance!r}")
        if isinstance(clutch_button, bool) or not (isinstance(clutch_button, int) and -1 <= clutch_button <= 31):
            raise ConfigError(f"master.mapping.clutch_button must be a bit 0..31 or -1, got {clutch_button!r}")
        self.motion = motion
        self.unit_length = float(unit_length)
        self.tolerance = float(align_tolerance)
        self.clutch_bit = int(clutch_button)
        self.status = ConsoleStatus.WAIT_SLAVE
        self.misalignment = 0.0
        self.engaged_now = self.released_now = False
        self.clutches = 0
        self.refusals = 0
        self._anchored_once = False
        self._clutch_was_held = False

    @property
    def engaged(self) -> bool:
        return self.status == ConsoleStatus.ENGAGED

    def clutch_held(self, dev: DeviceState) -> bool:
        """Whether the clutch button is pressed in ``dev``."""
        return self.clutch_bit >= 0 and bool((int(dev.buttons) >> self.clutch_bit) & 1)

    def update(self, dev: DeviceState, healthy: bool, x_slave: float | None) -> ConsoleStatus:
        """Decide this cycle's status from the device, the link health and the slave's ``x_in`` [m]."""
        was = self.engaged
        clutch = self.clutch_held(dev)
        if not healthy or x_slave is None or not (math.isfinite(dev.position) and math.isfinite(x_slave)):
            status = ConsoleStatus.WAIT_SLAVE
        elif not dev.operator_present:
            status = ConsoleStatus.WAIT_OPERATOR
        elif clutch:
            status = ConsoleStatus.CLUTCH
        else:
            if not self._anchored_once or self._clutch_was_held:
                # re-anchor: the present handle maps onto the slave's present x_in
                self.motion.anchor(dev.position, x_slave)
                self.motion.open_clutch()
                self.clutches += self._anchored_once
                self._anchored_once = True
            error = self.motion.target(dev.position) - x_slave
            if was or abs(error) <= self.tolerance:
                status, self.misalignment = ConsoleStatus.ENGAGED, 0.0
            else:
                status, self.misalignment = ConsoleStatus.ALIGN, error
                if self.status != ConsoleStatus.ALIGN:
                    self.refusals += 1
        if dev.operator_present and healthy:
            self._clutch_was_held = clutch
        self.status = status
        self.engaged_now = status == ConsoleStatus.ENGAGED and not was
        self.released_now = was and status != ConsoleStatus.ENGAGED
        if self.engaged_now:
            self.motion.resume()
        elif self.released_now:
            self.motion.open_clutch()
        return status

    def drop(self) -> None:
        """Leave ENGAGED without a reason of this axis's own (another axis of the instrument is not
        engaged): the next :meth:`update` checks the alignment again."""
        if self.engaged:
            self.status = ConsoleStatus.WAIT_SLAVE
            self.motion.open_clutch()

    def stop(self) -> None:
        """The session ends: STOPPING, decoupled."""
        self.released_now = self.engaged
        self.engaged_now = False
        self.status = ConsoleStatus.STOPPING
        self.motion.open_clutch()

    def prompt(self) -> str:
        """One line for the operator about the present status."""
        if self.status == ConsoleStatus.ALIGN:
            way = "release (push)" if self.misalignment > 0 else "pull"
            return (f"align: the handle maps {1e3 * abs(self.misalignment) * self.unit_length:.2f} mm of tendon "
                    f"away from the instrument; {way} back or clutch to re-anchor")
        return {ConsoleStatus.WAIT_SLAVE: "waiting for the slave", ConsoleStatus.WAIT_OPERATOR: "hold the deadman",
                ConsoleStatus.CLUTCH: "clutch: handle free, instrument held", ConsoleStatus.ENGAGED: "engaged",
                ConsoleStatus.STOPPING: "stopping"}[self.status]
