"""Simulated spindle instrument: one input spindle per jaw pulling a cable pair over the shaft's pulleys.

A da Vinci-type forceps jaw (docs/how-to/spindle-instrument.md): the instrument's input disc (the
spindle, radius r_p) winds cable a on and cable b off as it turns by phi, so the cables' proximal ends
move by x_in,a = x_a0 + r_p phi and x_in,b = x_b0 - r_p phi; the cables run along the shaft and over its
pulleys (their routes in ``instrument.joints[].tendons``, friction mu in ``rig.simulated.joints``) to the
jaw pulley of radius r_d, where a grasped object loads the jaw (``rig.simulated.joints[].load``: the
tissue contact). The cable physics are the house's: :class:`slave.pair_rig.SimulatedInstrument`
(distributed Coulomb friction with the capstan law in each cable, pretension, jaw torque balance),
driven here through the spindle's kinematics.

Sensors (the proximal signals, what the slave reads): the spindle angle phi [rad] from the drive's
encoder (quantised to 2 pi / ``rig.simulated.motor.encoder_lines_per_rev``) and the spindle torque
r_p (T_in,a - T_in,b) [N m] from the cables' load-cell samples (their noise,
``rig.simulated.sensors.load_cell_noise``, carries into the torque). The rig's arrays have shape
``(n_joints,)``: x_in = phi [rad], T_in = the spindle torque [N m], x_in_cmd = the commanded angle
[rad]. The truth is the inner simulator's :class:`~slave.rig.InstrumentTruth` (jaw angle and torque,
every cable tension).
"""
from __future__ import annotations

import math

import numpy as np

from slave.pair_rig import SimulatedInstrument
from slave.rig import RigInputError, RigState
from slave.simulated import check_setting, is_finite
from teleop.config.schema import Config, SimulatedRigConfig

__all__ = ["SpindleInstrument"]


class SpindleInstrument:
    """An instrument of 1..16 spindle-driven jaws (module docstring), a :class:`slave.rig.Rig`.

    Parameters
    ----------
    joints : sequence of JointConfig
        Each with ``spindle_radius`` > 0 and ``pretension`` > 0 (a pull-pull pair needs it).
    rig : SimulatedRigConfig
        ``rig.simulated`` (as :class:`~slave.pair_rig.SimulatedInstrument`).

    Raises
    ------
    ConfigError
        A joint without a spindle radius or pretension, or a setting the inner simulator refuses.
    """

    def __init__(self, joints, rig: SimulatedRigConfig):
        joints = tuple(joints)
        for i, j in enumerate(joints):
            p = f"instrument.joints[{i}] ({j.name})"
            check_setting(is_finite(j.spindle_radius) and j.spindle_radius > 0, f"{p}.spindle_radius",
                          "a spindle radius > 0 m", j.spindle_radius)
            check_setting(is_finite(j.pretension) and j.pretension > 0, f"{p}.pretension",
                          "a pretension > 0 N (a spindle's cable pair is preloaded)", j.pretension)
        self.inner = SimulatedInstrument(joints, rig)
        self.joints = joints
        self.joint_names = self.inner.joint_names
        self.r_p = np.array([j.spindle_radius for j in joints])
        truth = self.inner.state.truth
        assert truth is not None
        self._x0 = np.array(truth.x_in, dtype=float)
        self.angle_resolution = 2.0 * math.pi / float(rig.motor.encoder_lines_per_rev)
        self._state = self._read(np.zeros(len(joints)))

    @classmethod
    def from_config(cls, cfg: Config) -> SpindleInstrument:
        """Build from a full config (``instrument.joints`` and ``rig.simulated``)."""
        return cls(cfg.instrument.joints, cfg.rig.simulated)

    @property
    def n_joints(self) -> int:
        return len(self.joints)

    @property
    def K(self) -> np.ndarray:
        """The cables' friction exponents [-], shape (n_joints, 2)."""
        return self.inner.K

    @property
    def M_e(self) -> np.ndarray:
        """The cables' pull-slip elongation per proximal tension [m/N], shape (n_joints, 2)."""
        return self.inner.M_e

    @property
    def state(self) -> RigState:
        return self._state

    def spindle_angle(self) -> np.ndarray:
        """True spindle angles [rad], shape (n_joints,), from the cables' proximal ends."""
        truth = self.inner.state.truth
        assert truth is not None
        dx = np.asarray(truth.x_in) - self._x0
        return (dx[:, 0] - dx[:, 1]) / (2.0 * self.r_p)

    def step(self, angle_cmd, dt: float) -> RigState:
        """Turn every spindle toward ``angle_cmd`` [rad], shape (n_joints,), for ``dt`` [s]; read sensors.

        Raises
        ------
        RigInputError (ValueError)
            ``angle_cmd`` of another shape or not finite; ``dt`` not a finite number > 0.
        """
        try:
            cmd = np.array(angle_cmd, dtype=np.float64).reshape(-1)
        except (TypeError, ValueError):
            raise RigInputError(f"angle_cmd must be {self.n_joints} spindle angles in rad, got {angle_cmd!r}") from None
        if cmd.shape != (self.n_joints,) or not np.isfinite(cmd).all():
            raise RigInputError(f"angle_cmd must be {self.n_joints} finite spindle angles in rad, got {cmd.tolist()}")
        x = self._x0 + np.stack([self.r_p * cmd, -self.r_p * cmd], axis=1)
        self.inner.step(x, dt)
        self._state = self._read(cmd)
        return self._state

    def set_load(self, *, tissue: bool | None = None, force: float | None = None) -> None:
        """Grasp (``tissue=True``) or release the object on every jaw (:meth:`SimulatedInstrument.set_load`)."""
        self.inner.set_load(tissue=tissue, force=force)
        self._state = self._read(self._state.x_in_cmd)

    def close(self) -> None:
        """Nothing to release in simulation; idempotent."""

    def _read(self, cmd: np.ndarray) -> RigState:
        st = self.inner.state
        q = self.angle_resolution
        phi = np.round(self.spindle_angle() / q) * q
        T = np.asarray(st.T_in)
        torque = self.r_p * (T[:, 0] - T[:, 1])
        return RigState(t=st.t, x_in=phi, T_in=torque, x_in_cmd=np.array(cmd, dtype=float), truth=st.truth)
