"""The instrument-side rig interface: one protocol over arrays of tendons, for every instrument.

A rig drives the tendons of an instrument, each with its own proximal motor (position command,
encoder ``x_in``) and load cell (``T_in``). Every array of a rig has the rig's *tendon shape*:

* ``()`` - a single tendon (a one-axis instrument): plain floats;
* ``(n_joints, 2)`` - an instrument of 1 to 16 antagonistic pairs (config ``instrument.joints``),
  indexed ``[joint, tendon]`` with tendon 0 = a (pulling it turns the joint to + angles) and 1 = b.

Each step takes a command per tendon and returns what the proximal sensors read. A simulated rig
also returns the ground truth (:class:`RigTruth` for a single tendon, :class:`InstrumentTruth` for a
pair instrument) for evaluation; estimators and controllers must never read it.

Sign convention (docs/concepts/architecture.md): + = tendon drawn toward the actuator; x_in - x_out = elongation.
At a distal pulley of radius r: x_out,a = + r theta, x_out,b = - r theta.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np

from teleop.errors import TeleopError

__all__ = ["TENDONS", "RigTruth", "InstrumentTruth", "RigState", "sensor_fault", "Rig", "RigInputError"]

#: Tendon labels of a pair, in array order.
TENDONS = ("a", "b")


class RigInputError(TeleopError, ValueError):
    """A rig was given a bad run-time input (non-finite command, non-positive time step, ...).

    The message names the argument. (Kept here until teleop/errors.py grows a rig error.)
    """


@dataclass(frozen=True)
class RigTruth:
    """Ground truth of a simulated single tendon at one instant (for evaluation only).

    Attributes
    ----------
    T_in : float
        True proximal tension [N], >= 0.
    T_out : float
        True distal tension [N], >= 0 (with the simulated rig's presliding switch: T_in less the lagged friction).
    x_in : float
        True proximal tendon displacement [m] (motor position).
    x_out : float
        True distal displacement [m], >= 0 (0 = joint against its lower stop): the tendon's distal end, or with the
        simulated rig's distal_backlash switch the position behind its play.
    elongation : float
        Tendon elongation (1/EA) int_0^L T(s) ds [m]. Equals ``x_in - x_out`` while the tendon is
        taut (without a distal play); larger when it is slack (the proximal end pushed past the point of zero
        tension).
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
class InstrumentTruth:
    """Ground truth of a simulated instrument of antagonistic pairs at one instant (evaluation only).

    Attributes
    ----------
    theta : ndarray, shape (n_joints,)
        Joint angles [rad].
    torque : ndarray, shape (n_joints,)
        Distal joint torque r (T_out,a - T_out,b) [N m].
    T_in, T_out : ndarray, shape (n_joints, 2)
        True proximal and distal tensions [N].
    x_in, x_out : ndarray, shape (n_joints, 2)
        True proximal (motor) and distal tendon displacements [m].
    elongation : ndarray, shape (n_joints, 2)
        Tendon elongations (1/EA) int T ds [m].
    profiles : tuple of ndarray
        ``2 * n_joints`` node-tension snapshots [N] (joint 0 a, joint 0 b, joint 1 a, ...), proximal
        to distal, read-only.
    """

    theta: np.ndarray
    torque: np.ndarray
    T_in: np.ndarray
    T_out: np.ndarray
    x_in: np.ndarray
    x_out: np.ndarray
    elongation: np.ndarray
    profiles: tuple[np.ndarray, ...] = field(repr=False, default=())


#: A value per tendon: a float for a single tendon, an ndarray of shape (n_joints, 2) for pairs.
Tendons = float | np.ndarray


@dataclass(frozen=True)
class RigState:
    """What a rig reports after a step; every array has the rig's tendon shape (module docstring).

    Attributes
    ----------
    t : float
        Rig time [s], the sum of the time steps since construction.
    x_in : float or ndarray
        Proximal displacement from each motor encoder [m] (quantised on real and simulated rigs).
    T_in : float or ndarray
        Proximal tension from each load cell [N] (noisy; may read slightly negative).
    x_in_cmd : float or ndarray
        The displacement commands applied in this step [m].
    truth : RigTruth, InstrumentTruth or None
        Ground truth of a simulated rig; ``None`` on hardware.
    fault : str or None
        Why the rig itself does not vouch for this sample (e.g. a sample over Zenoh older than its timeout),
        or ``None``. The slave treats a flagged sample as a sensor fault (:func:`sensor_fault`).
    """

    t: float
    x_in: Any
    T_in: Any
    x_in_cmd: Any
    truth: RigTruth | InstrumentTruth | None = None
    fault: str | None = None


def sensor_fault(state: RigState) -> str | None:
    """Why the slave must not estimate or control on ``state``, or ``None`` when it may: the rig's own
    ``fault``, or an encoder or load-cell reading that is not finite (a failed sensor or a broken cable).

    The slave holds its motor commands, sends no estimate (so the master's force fades out on the stale
    estimate) and stays SAFE until the readings are good and the operator lets go (docs/concepts/safety.md).
    """
    if state.fault is not None:
        return state.fault
    for name, value in (("x_in", state.x_in), ("T_in", state.T_in)):
        v = np.asarray(value, dtype=float)
        if not np.all(np.isfinite(v)):
            return f"rig reading {name} not finite ({np.count_nonzero(~np.isfinite(v))} of {v.size})"
    return None


@runtime_checkable
class Rig(Protocol):
    """The tendons of an instrument: a proximal motor with encoder and load cell per tendon.

    A pair instrument also has ``joint_names`` (tuple of str, one per joint, config order).
    """

    def step(self, x_in_cmd: Any, dt: float) -> RigState:
        """Command every motor (``x_in_cmd`` [m], the rig's tendon shape), advance ``dt`` [s] > 0,
        read the sensors.

        Raises
        ------
        ValueError
            (:class:`RigInputError`) a command not finite or of the wrong shape, ``dt`` not a finite
            positive number.
        """
        ...

    @property
    def state(self) -> RigState:
        """The last state returned by :meth:`step` (the initial state before any step)."""
        ...

    def set_load(self, *, tissue: bool | None = None, force: float | None = None) -> None:
        """Switch the distal load at run time: tissue contact on/off (every joint of a pair
        instrument), a single tendon's distal set force [N] >= 0 (pair instruments take ``tissue``
        only). ``None`` leaves a setting unchanged."""
        ...

    def close(self) -> None:
        """Release the hardware (idempotent)."""
        ...
