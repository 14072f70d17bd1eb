"""Simulated instrument of 1 to 16 joints, each driven by an antagonistic pair of distributed tendons.

The reference simulator (docs/concepts/model.md, the simulators) extended to a pull-pull pair (E5, E11-E13):
the compiled step is in :mod:`estimator.kernels`; this module owns the state, the motors, the
sensors and validation.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from estimator.distal_slip import distal_gains
from estimator.kernels import RIGID_STOP, load_torque, settle_joint, step_joint
from slave.drive import Drive
from slave.rig import InstrumentTruth, RigInputError, RigState
from slave.simulated import check_setting, is_finite, validate_drive, validate_runs
from teleop.config.checks import MAX_JOINTS
from teleop.config.schema import Config, JointConfig, SimulatedRigConfig, TendonConfig

__all__ = ["SimulatedInstrument", "TendonPhysics"]

_STOP_X, _STOP_F, _STOP_S = RIGID_STOP       # the rigid distal stop of step A, constants of the compiled step



class TendonPhysics:
    """Constant arrays of one simulated tendon: node gains, weights, K and M_e.

    Parameters
    ----------
    tendon : TendonConfig
        The instrument's tendon: route and EA.
    mu : float
        Its simulated friction coefficient [-] (``rig.simulated.joints[].tendons``).
    n_elements : int
        Elements n (n + 1 nodes equally spaced in arc length).
    """

    def __init__(self, tendon: TendonConfig, mu: float, n_elements: int):
        geom = tendon.geometry()
        self.L = geom.length
        s = np.linspace(0.0, self.L, n_elements + 1)
        self.log_gain = mu * np.asarray(geom.wrap_angle(s), dtype=np.float64)
        self.lo = np.exp(-self.log_gain)
        self.hi = np.exp(self.log_gain)
        self.dlo, self.dhi = distal_gains(self.log_gain)
        w = np.full(n_elements + 1, self.L / (n_elements * tendon.EA))
        w[0] *= 0.5
        w[-1] *= 0.5
        self.w = w
        self.c_pull = float(w @ self.lo) / self.lo[-1]
        self.c_rel = float(w @ self.hi) / self.hi[-1]

    @property
    def K(self) -> float:
        """Friction exponent mu * total wrap angle [-] (Phee et al. 2009, eq. (2))."""
        return float(self.log_gain[-1])

    @property
    def M_e(self) -> float:
        """Elongation per proximal tension in full pull slip [m/N], sum_i w_i e^{-g_i} (eq. (12))."""
        return float(self.w @ self.lo)


class SimulatedInstrument:
    r"""An instrument of 1..16 independent joints, each turned by two tendons through their own sheaths.

    Model of one joint (quasi-static distributed Coulomb friction in each tendon; joint per
    docs/concepts/effects.md E11 with the pair coupling E13; pretension E5):

    * Tendons a and b: the distributed model of :class:`slave.simulated.SimulatedRig` each (``n``
      elements, own route and EA from ``instrument.joints[i].tendons``, own mu from
      ``rig.simulated.joints``), both tied to a distal pulley of radius r: x_out,a = + r theta,
      x_out,b = - r theta. A tendon cannot push (slack: zero tension along it).
    * Joint: quasi-static torque balance with damping (first-order relaxation, implicit Euler)

          r (T_out,a - T_out,b) = k theta + b dtheta/dt + tau_tissue + tau_limit + tau_ext

      tau_tissue = k_t (|theta| - theta_c) sgn(theta) beyond |theta| > theta_c when tissue is on,
      tau_limit = k_lim (theta - hi) above hi and k_lim (theta - lo) below lo, tau_ext constant.
      Joint inertia is left out: with grams on millimetres its time constant is far below 1 ms.
    * One step: the motors move with the joint held (slip from the proximal ends), then the joint
      settles with the motors held (slip from the distal ends) - a first-order splitting, exact in
      the limit of small steps (:mod:`estimator.kernels`).
    * Pretension P (``pretension``): both tendons start uniform at P with theta = 0, the motors at
      x_in = P L/EA (x_out = 0); P = 0: both start at zero tension.
    * Motors: the first-order position loop of :class:`~slave.simulated.SimulatedRig`
      (``rig.simulated.motor``: bandwidth, speed limit); encoders quantised to 2 pi pulley_radius / lines.
    * Load cells: T_in + N(0, ``rig.simulated.sensors.load_cell_noise``^2), one seeded generator.

    Parameters
    ----------
    joints : sequence of JointConfig
        1 to :data:`~teleop.config.checks.MAX_JOINTS` (16) joints.
    rig : SimulatedRigConfig
        ``rig.simulated``: ``n_elements`` (per tendon), ``motor``, ``sensors``, and ``joints``: each
        joint's simulated physics (stiffness, damping, limit stiffness, load, the tendons' mu) by name.

    Raises
    ------
    ConfigError
        No joints, more than 16, or a setting out of range (the message names the joint and key).
    """

    def __init__(self, joints, rig: SimulatedRigConfig):
        joints = tuple(joints)
        _validate(joints, rig)
        self.joints = joints
        self.sims = sims = tuple(rig.joint(j.name) for j in joints)     # each joint's simulated physics
        self.joint_names = tuple(j.name for j in joints)
        n = int(rig.n_elements)
        self.tendons = [(TendonPhysics(j.tendons.a, s.tendons.a.mu, n), TendonPhysics(j.tendons.b, s.tendons.b.mu, n))
                        for j, s in zip(joints, sims, strict=False)]
        nj = len(joints)
        # every tendon's node tensions [N], (n_joints, 2 tendons, n + 1 nodes), and its constant arrays
        self._T = np.array([[np.full(n + 1, float(j.pretension))] * 2 for j in joints])
        self._gains = np.array([[(p.lo, p.hi, p.dlo, p.dhi, p.w) for p in pair] for pair in self.tendons])
        self._c = np.array([[(p.c_pull, p.c_rel) for p in pair] for pair in self.tendons])
        self._theta = np.zeros(nj)
        self._x = np.array([[float(p.w.sum() * j.pretension) for p in pair]
                            for j, pair in zip(joints, self.tendons, strict=False)])
        self._tissue = [bool(s.load.tissue) for s in sims]
        self._slope = np.array([s.stiffness + s.load.tissue_stiffness
                                + j.pulley_radius ** 2 * (1.0 / pa.M_e + 1.0 / pb.M_e)
                                for j, s, (pa, pb) in zip(joints, sims, self.tendons, strict=False)])
        self._joint_prm = self._joint_params()
        self.drive = Drive(rig, (nj, 2))        # motor loops, encoders, load cells (shared by every simulated rig)
        self.encoder_resolution = self.drive.encoder_resolution
        self._t = 0.0
        self._state = self._read(self._x.copy())

    @classmethod
    def from_config(cls, cfg: Config) -> SimulatedInstrument:
        """Build from a full config (``instrument.joints`` and ``rig.simulated``).

        Raises
        ------
        ConfigError
            ``instrument.joints`` is empty (a single-tendon config: use :class:`slave.simulated.SimulatedRig`).
        """
        return cls(cfg.instrument.joints, cfg.rig.simulated)

    # ---- model constants -------------------------------------------------------------------------
    @property
    def n_joints(self) -> int:
        return len(self.joints)

    @property
    def K(self) -> np.ndarray:
        """Friction exponents [-], shape (n_joints, 2)."""
        return np.array([[p.K for p in pair] for pair in self.tendons])

    @property
    def M_e(self) -> np.ndarray:
        """Pull-slip elongation per proximal tension [m/N], shape (n_joints, 2)."""
        return np.array([[p.M_e for p in pair] for pair in self.tendons])

    @property
    def tissue(self) -> tuple[bool, ...]:
        return tuple(self._tissue)

    # ---- Rig protocol ----------------------------------------------------------------------
    @property
    def state(self) -> RigState:
        return self._state

    def step(self, x_in_cmd, dt: float) -> RigState:
        """Move every motor toward ``x_in_cmd`` [m], shape (n_joints, 2), for ``dt`` [s]; read sensors.

        Raises
        ------
        RigInputError (ValueError)
            ``x_in_cmd`` of another shape or not finite; ``dt`` not a finite number > 0.
        """
        try:
            cmd = np.array(x_in_cmd, dtype=np.float64)
            h = float(dt)
        except (TypeError, ValueError):
            raise RigInputError(f"x_in_cmd must be numbers of shape ({self.n_joints}, 2) and dt a number, "
                                f"got x_in_cmd={x_in_cmd!r}, dt={dt!r}") from None
        if cmd.shape != self._x.shape:
            raise RigInputError(f"x_in_cmd must have shape ({self.n_joints}, 2) [joint, tendon a/b], "
                                f"got {cmd.shape}")
        if not np.isfinite(cmd).all():
            raise RigInputError(f"x_in_cmd must be finite displacements in metres, got {cmd.tolist()}")
        if not (math.isfinite(h) and h > 0.0):
            raise RigInputError(f"dt must be a finite time step > 0 s, got {dt!r}")
        # the motors' exact first-order step toward the command (speed-limited), every joint's physics, the truth
        # and the sensors in one compiled call
        gain, vmax_dt = self.drive.motor_step(h)
        snap, out, ang = np.empty_like(self._T), np.empty((7, *self._x.shape)), np.empty((2, self.n_joints))
        _step_read(self._T, self._gains, self._c, self._x, cmd, self._theta, self._joint_prm, h, gain, vmax_dt,
                   self.encoder_resolution, self.drive.load_cell_noise(), snap, out, ang)
        self._t += h
        self._state = self._state_of(snap, out, ang, cmd)
        return self._state

    def set_load(self, *, tissue: bool | None = None, force: float | None = None) -> None:
        """Switch tissue contact on every joint; the joints re-balance at once (no damping) with the
        motors held; :attr:`state` is refreshed (new truth and sensor sample, same time).

        Raises
        ------
        RigInputError (ValueError)
            ``tissue`` is not a bool; ``force`` given (a distal set force is a single tendon's load).
        """
        if force is not None:
            raise RigInputError(f"force={force!r}: a joint instrument's distal load is tissue contact only "
                                f"(a distal set force is a single tendon's)")
        if tissue is None:
            return
        if not isinstance(tissue, (bool, np.bool_)):
            raise RigInputError(f"tissue must be True or False, got {tissue!r}")
        self._tissue = [bool(tissue)] * self.n_joints
        self._joint_prm = self._joint_params()
        for i, (j, s) in enumerate(zip(self.joints, self.sims, strict=False)):
            pa, pb = self.tendons[i]
            Ta, Tb = self._T[i]
            kt = s.load.tissue_stiffness if self._tissue[i] else 0.0
            self._theta[i] = settle_joint(Ta, pa.dlo, pa.dhi, pa.w, self._x[i, 0], Tb, pb.dlo, pb.dhi, pb.w,
                                          self._x[i, 1], j.pulley_radius, self._theta[i], s.stiffness, 0.0, kt,
                                          s.load.tissue_contact, j.limits[0], j.limits[1], s.limit_stiffness,
                                          s.load.torque, self._slope[i])
        self._state = self._read(self._state.x_in_cmd)

    def close(self) -> None:
        """Nothing to release in simulation; idempotent."""

    # ---- internals ----------------------------------------------------------------------------------
    def _joint_params(self) -> np.ndarray:
        """Each joint's constants for :func:`_step_joints`, shape (n_joints, 10): r, stiffness, damping,
        tissue stiffness (0 without contact), tissue contact angle, limits lo/hi, limit stiffness, load
        torque, the torque balance's slope without damping."""
        return np.array([(j.pulley_radius, s.stiffness, s.damping, s.load.tissue_stiffness if tissue else 0.0,
                          s.load.tissue_contact, j.limits[0], j.limits[1], s.limit_stiffness, s.load.torque, slope)
                         for j, s, tissue, slope in zip(self.joints, self.sims, self._tissue, self._slope,
                                                        strict=False)],
                        dtype=np.float64)

    def _read(self, cmd: np.ndarray) -> RigState:
        """The present state (the start, or after :meth:`set_load`): truth and a new sensor sample."""
        snap, out, ang = self._T.copy(), np.empty((7, *self._x.shape)), np.empty((2, self.n_joints))
        _read_all(snap, self._gains, self._joint_prm[:, 0], self._x, self._theta, self.encoder_resolution,
                  self.drive.load_cell_noise(), out, ang)
        return self._state_of(snap, out, ang, cmd)

    def _state_of(self, snap: np.ndarray, out: np.ndarray, ang: np.ndarray, cmd: np.ndarray) -> RigState:
        """RigState of the compiled readout: profiles ``snap`` (n_joints, 2, n + 1); ``out`` (7, n_joints, 2): T_in,
        T_out, elongation, x_out, load cells, encoders, motor positions; ``ang`` (2, n_joints): theta, torque."""
        snap.flags.writeable = False
        truth = InstrumentTruth(theta=ang[0], torque=ang[1], T_in=out[0], T_out=out[1], x_in=out[6], x_out=out[3],
                                elongation=out[2], profiles=tuple(snap.reshape(-1, snap.shape[2])))
        return RigState(t=self._t, x_in=out[5], T_in=out[4], x_in_cmd=cmd, truth=truth)

    def load_torque(self, i: int, theta: float) -> float:
        """Static load torque of joint ``i`` at ``theta`` [rad] with the present tissue setting [N m]."""
        j, s = self.joints[i], self.sims[i]
        kt = s.load.tissue_stiffness if self._tissue[i] else 0.0
        return float(load_torque(theta, s.stiffness, kt, s.load.tissue_contact, j.limits[0], j.limits[1],
                                 s.limit_stiffness, s.load.torque))


@njit(cache=True, nogil=True)
# pragma: no cover - compiled
def _step_read(T, gains, c, x, cmd, theta, prm, h, gain, vmax_dt, q, noise, snap, out, ang):
    """One step of every joint, then its readout (:func:`_read_all`). T (n_joints, 2, n + 1) node tensions [N] and
    theta (n_joints,) [rad] in place; gains (n_joints, 2, 5, n + 1) lo, hi, dlo, dhi, w; c (n_joints, 2, 2) c_pull,
    c_rel; x (n_joints, 2) motor positions [m], moved in place toward cmd by the drive's exact step
    ``clip(gain (cmd - x), -vmax_dt, vmax_dt)`` (:meth:`slave.drive.Drive.move`); prm (n_joints, 10) of
    :meth:`SimulatedInstrument._joint_params`; then each joint's :func:`estimator.kernels.step_joint`, the profiles
    copied into ``snap`` and their readout into ``out`` and ``ang`` (:func:`_read_all`: q [m] the encoder resolution,
    noise (n_joints, 2) the load cells' noise [N])."""
    nj = T.shape[0]
    for i in range(nj):
        for k in range(2):
            dx = gain * (cmd[i, k] - x[i, k])
            x[i, k] += min(max(dx, -vmax_dt), vmax_dt)
    for i in range(nj):
        a, b, p = gains[i, 0], gains[i, 1], prm[i]
        damp_dt = p[2] / h
        theta[i] = step_joint(T[i, 0], a[0], a[1], a[2], a[3], a[4], c[i, 0, 0], c[i, 0, 1],
                              T[i, 1], b[0], b[1], b[2], b[3], b[4], c[i, 1, 0], c[i, 1, 1],
                              x[i, 0], x[i, 1], p[0], theta[i], p[1], damp_dt, p[3], p[4], p[5], p[6], p[7], p[8],
                              p[9] + damp_dt, _STOP_X, _STOP_F, _STOP_S)
    snap[:] = T
    _read_all(snap, gains, prm[:, 0], x, theta, q, noise, out, ang)


@njit(cache=True, nogil=True)
def _read_all(T, gains, r, x, theta, q, noise, out, ang):  # pragma: no cover - compiled
    """The readout of profiles T (n_joints, 2, n + 1): out (7, n_joints, 2) T_in, T_out, elongation w . T (numpy's dot
    product), x_out = (r theta, -r theta), the load cells T_in + noise [N], the encoders q rint(x / q) [m]
    (:meth:`slave.drive.Drive.encoder`), the motor positions x [m]; ang (2, n_joints): theta [rad] and the torque
    r (T_out,a - T_out,b) [N m]."""
    nj, n = T.shape[0], T.shape[2] - 1
    for i in range(nj):
        for k in range(2):
            out[0, i, k] = T[i, k, 0]
            out[1, i, k] = T[i, k, n]
            out[2, i, k] = np.dot(gains[i, k, 4], T[i, k])
            out[4, i, k] = T[i, k, 0] + noise[i, k]
            out[5, i, k] = q * np.rint(x[i, k] / q)
            out[6, i, k] = x[i, k]
        out[3, i, 0] = r[i] * theta[i]
        out[3, i, 1] = -r[i] * theta[i]
        ang[0, i] = theta[i]
        ang[1, i] = r[i] * (out[1, i, 0] - out[1, i, 1])


def _validate(joints: tuple[JointConfig, ...], rig: SimulatedRigConfig) -> None:
    """Range checks of what the simulator uses; ConfigError names the joint and the dotted key."""
    check_setting(1 <= len(joints) <= MAX_JOINTS, "instrument.joints", f"a list of 1 to {MAX_JOINTS} joints",
                  len(joints))
    for i, j in enumerate(joints):
        p = f"instrument.joints[{i}] ({j.name})"
        check_setting(is_finite(j.pulley_radius) and j.pulley_radius > 0, f"{p}.pulley_radius", "a radius > 0 m",
               j.pulley_radius)
        check_setting(len(j.limits) == 2 and j.limits[0] < 0.0 < j.limits[1], f"{p}.limits",
               "[lower, upper] with lower < 0 < upper [rad]", j.limits)
        check_setting(is_finite(j.pretension) and j.pretension >= 0, f"{p}.pretension", "a finite number >= 0",
                      j.pretension)
        s, q = rig.joint(j.name), f"rig.simulated.joints ({j.name})"
        for key in ("stiffness", "damping"):
            check_setting(is_finite(getattr(s, key)) and getattr(s, key) >= 0, f"{q}.{key}", "a finite number >= 0",
                   getattr(s, key))
        check_setting(is_finite(s.limit_stiffness) and s.limit_stiffness > 0, f"{q}.limit_stiffness",
               "a stiffness > 0 N m/rad", s.limit_stiffness)
        check_setting(is_finite(s.load.tissue_stiffness) and s.load.tissue_stiffness >= 0, f"{q}.load.tissue_stiffness",
               "a finite number >= 0 N m/rad", s.load.tissue_stiffness)
        check_setting(is_finite(s.load.tissue_contact) and s.load.tissue_contact >= 0, f"{q}.load.tissue_contact",
               "an angle >= 0 rad", s.load.tissue_contact)
        check_setting(is_finite(s.load.torque), f"{q}.load.torque", "a finite torque in N m", s.load.torque)
        for t in ("a", "b"):
            td, mu = getattr(j.tendons, t), getattr(s.tendons, t).mu
            check_setting(is_finite(mu) and mu >= 0, f"{q}.tendons.{t}.mu", "a finite number >= 0", mu)
            check_setting(is_finite(td.EA) and td.EA > 0, f"{p}.tendons.{t}.EA", "a finite number > 0 N", td.EA)
            validate_runs(td.runs, f"{p}.tendons.{t}.runs")
    validate_drive(rig)
