"""The instrument-side rig interface: what a slave node needs from real or simulated hardware.

A rig takes a proximal displacement command each cycle and returns what the proximal sensors read:
the motor encoder (``x_in``) and the load cell (``T_in``). A simulated rig also returns the ground
truth (:class:`RigTruth`) for evaluation; estimators must never read it.

Sign convention (ARCHITECTURE.md): + = tendon drawn toward the actuator; x_in - x_out = elongation.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np

from teleop.errors import TeleopError

__all__ = ["RigTruth", "RigState", "Rig", "RigInputError"]


class RigInputError(TeleopError, ValueError):
    """A rig was given a bad run-time input (non-finite command, non-positive time step, ...).

    The message names the argument. (Kept here until teleop/errors.py grows a rig error.)
    """


@dataclass(frozen=True)
class RigTruth:
    """Ground truth of a simulated rig at one instant (for evaluation only).

    Attributes
    ----------
    T_in : float
        True proximal tension [N], >= 0.
    T_out : float
        True distal tension [N], >= 0.
    x_in : float
        True proximal tendon displacement [m] (motor position).
    x_out : float
        True distal tendon displacement [m], >= 0 (0 = joint against its lower stop).
    elongation : float
        Tendon elongation (1/EA) int_0^L T(s) ds [m]. Equals ``x_in - x_out`` while the tendon is
        taut; larger when it is slack (the proximal end pushed past the point of zero tension).
    profile : ndarray, shape (n_elements + 1,)
        Node tensions from the proximal to the distal end [N], equally spaced in arc length;
        read-only snapshot.
    """

    T_in: float
    T_out: float
    x_in: float
    x_out: float
    elongation: float
    profile: np.ndarray = field(repr=False)


@dataclass(frozen=True)
class RigState:
    """What the rig reports after a step.

    Attributes
    ----------
    t : float
        Rig time [s], the sum of the time steps since construction.
    x_in : float
        Proximal displacement from the motor encoder [m] (quantised on real and simulated rigs).
    T_in : float
        Proximal tension from the load cell [N] (noisy; may read slightly negative).
    x_in_cmd : float
        The displacement command applied in this step [m].
    truth : RigTruth or None
        Ground truth for simulated rigs; ``None`` on hardware.
    """

    t: float
    x_in: float
    T_in: float
    x_in_cmd: float
    truth: RigTruth | None = None


@runtime_checkable
class Rig(Protocol):
    """A tendon rig: one proximal motor with encoder and load cell driving one tendon."""

    def step(self, x_in_cmd: float, dt: float) -> RigState:
        """Command the proximal displacement ``x_in_cmd`` [m], advance ``dt`` [s] > 0, read sensors.

        Raises
        ------
        ValueError
            (:class:`RigInputError`) ``x_in_cmd`` not finite or ``dt`` not a finite positive number.
        """
        ...

    @property
    def state(self) -> RigState:
        """The last state returned by :meth:`step` (the initial state before any step)."""
        ...

    def set_load(self, *, tissue: bool | None = None, force: float | None = None) -> None:
        """Switch the distal load at run time: tissue contact on/off, distal set force [N] >= 0.

        ``None`` leaves a setting unchanged.
        """
        ...

    def close(self) -> None:
        """Release the hardware (idempotent)."""
        ...
