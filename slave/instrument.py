"""The multi-joint instrument interface: what a slave node needs from real or simulated hardware.

An instrument has 1 to 4 joints (config ``instrument.joints``), each driven by an antagonistic pair of
tendons ``a`` (pulling it turns the joint to + angles) and ``b`` (to - angles), each tendon with its
own proximal motor (position command, encoder ``x_in``) and load cell (``T_in``). Arrays are
indexed ``[joint, tendon]`` with tendon 0 = a, 1 = b. A simulated instrument also returns the ground
truth (:class:`InstrumentTruth`) for evaluation; estimators and controllers must never read it.

Sign convention (ARCHITECTURE.md): + = tendon drawn toward the actuator; x_in - x_out = elongation.
At the distal pulley of radius r: x_out,a = + r theta, x_out,b = - r theta.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np

__all__ = ["TENDONS", "InstrumentTruth", "InstrumentState", "Instrument"]

#: Tendon labels in array order.
TENDONS = ("a", "b")


@dataclass(frozen=True)
class InstrumentTruth:
    """Ground truth of a simulated instrument at one instant (evaluation only).

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


@dataclass(frozen=True)
class InstrumentState:
    """What the instrument reports after a step.

    Attributes
    ----------
    t : float
        Instrument time [s], the sum of the time steps since construction.
    x_in : ndarray, shape (n_joints, 2)
        Motor encoders [m] (quantised).
    T_in : ndarray, shape (n_joints, 2)
        Load cells [N] (noisy; may read slightly negative).
    x_in_cmd : ndarray, shape (n_joints, 2)
        The motor commands applied in this step [m].
    truth : InstrumentTruth or None
        Ground truth for simulated instruments; ``None`` on hardware.
    """

    t: float
    x_in: np.ndarray
    T_in: np.ndarray
    x_in_cmd: np.ndarray
    truth: InstrumentTruth | None = None


@runtime_checkable
class Instrument(Protocol):
    """An instrument of ``n_joints`` antagonistic pairs, two motors with encoder and load cell per joint."""

    joint_names: tuple[str, ...]

    def step(self, x_in_cmd: np.ndarray, dt: float) -> InstrumentState:
        """Command every motor (``x_in_cmd`` [m], shape (n_joints, 2)), advance ``dt`` [s] > 0, read sensors.

        Raises
        ------
        ValueError
            (:class:`slave.rig.RigInputError`) a command not finite or of the wrong shape, ``dt``
            not a finite positive number.
        """
        ...

    @property
    def state(self) -> InstrumentState:
        """The last state returned by :meth:`step` (the initial state before any step)."""
        ...

    def set_load(self, *, tissue: bool | None = None) -> None:
        """Switch tissue contact on/off on every joint at run time (``None``: unchanged)."""
        ...

    def close(self) -> None:
        """Release the hardware (idempotent)."""
        ...
