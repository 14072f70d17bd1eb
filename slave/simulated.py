"""Simulated slave rig: distributed tendon-sheath physics, proximal motor, distal load and sensors.

The reference simulator (docs/concepts/model.md, the simulators) (quasi-static distributed Coulomb model), with
the distal load solved exactly at every step. The compiled kernels live in
:mod:`estimator.kernels` (shared with the estimator); this module owns the state, the motor, the sensors and validation.
"""
from __future__ import annotations

import math

import numpy as np

from estimator.geometry import Run, SheathGeometry
from estimator.kernels import advance_proximal, load_inverse, settle_distal
from slave.drive import Drive
from slave.rig import RigInputError, RigState, RigTruth
from slave.simulated_effects import EffectSwitches, elongation_general
from teleop.config.effects import EffectsConfig
from teleop.config.schema import Config, LoadConfig, SheathConfig, SimulatedRigConfig
from teleop.errors import ConfigError

__all__ = ["SimulatedRig"]

_SIM = "rig.simulated"     # where the simulator's settings live in the config



class SimulatedRig(EffectSwitches):
    r"""One tendon in a rigid sheath, driven by a position-controlled motor, with a distal load.

    Model (quasi-static distributed Coulomb friction; Phee et al. 2009 eq. (1) in differential form)

    * Tendon: ``n`` elements, ``n + 1`` nodes at s_i = i L / n (proximal i = 0 to distal i = n), node
      wrap angle theta_i = int_0^{s_i} kappa from the route (any curvature), g_i = mu theta_i,
      K = g_n. The node tensions T_i [N] are the state (the tension-profile memory). No tendon
      inertia: the axial wave time is far below a control period (docs/concepts/model.md, the simulators).
    * Friction bound: |ln T_{i+1} - ln T_i| <= g_{i+1} - g_i, with equality where the tendon slides.
    * Kinematics (rigid, inextensible sheath): x_in - x_out = e, e = sum_i w_i T_i, trapezoid weights
      w_i = L / (n EA) (halved at both ends).
    * Distal load (x_out >= 0 [m], + toward the actuator), a monotone graph T_d = F(x_out):
      F(x) = f + k_j x + [tissue] k_t max(0, x - x_c) + k_lim max(0, x - x_lim) for x > 0, and at
      the lower stop x_out = 0 any T_d in [0, F(0+)] (a torque-controlled distal actuator with set
      force f keeps the joint on its stop until the tendon pulls harder than f). T_d >= 0 always.
    * Proximal step (new motor position x_in, load law unchanged): slip spreads from the proximal end
      only. With the proximal tension T_p as unknown, every node follows the envelope rule
      T_i <- min(max(T_i, T_p e^{-g_i}), T_p e^{+g_i}). While the distal node keeps its tension it
      sticks and x_out stays; once the update reaches it the whole tendon slides,
      T_i = T_p e^{-g_i} (pull) or T_p e^{+g_i} (release), and (x_out, T_d) is the point of the
      load graph with x_out + e(T_d) = x_in. The equation x_in - x_out(T_p) = e(T_p) is monotone and
      piecewise linear in T_p and is solved exactly by a scan over the sorted breakpoints.
    * Load change at fixed x_in (:meth:`set_load`): slip spreads from the distal end,
      T_i <- min(max(T_i, T_d e^{-(K - g_i)}), T_d e^{+(K - g_i)}), with T_d and x_out on the new
      load graph and x_out + e = x_in (bisection to machine precision).
    * Slack: the tendon cannot push. When x_in falls below what zero tension needs, T = 0 everywhere,
      x_out rests at the lower stop and x_in - x_out < e = 0.
    * Pretension P = ``sheath.pretension``: the tendon starts at T_i = P everywhere (as if tensioned
      with the friction relieved, then the motor locked), the distal end at the smallest x_out with
      F(x_out) = P (0 if P <= f), and x_in = x_out + P L / EA; the motor starts there.
    * Motor: first-order position loop toward the command with time constant 1 / (2 pi bandwidth_hz),
      discretised exactly, x <- x + (1 - e^{-2 pi f_bw dt}) (x_cmd - x), with the step clipped to
      max_speed * dt. The motor is stiff: the tendon's proximal end follows it.
    * Sensors: load cell T_in + N(0, load_cell_noise^2) (numpy Generator seeded with
      ``sensors.seed``); encoder quantised to q = 2 pi pulley_radius / encoder_lines_per_rev,
      x_enc = q round(x_in / q).

    Assumptions: rigid sheath (no axial compression), Coulomb friction with equal static and dynamic
    mu, no bending stiffness or clearance, massless tendon and distal joint - unless an effect of
    ``rig.simulated.effects`` is switched on (each is off by default; the catalogue entries of
    estimator/offline/effects/catalogue.py declare them and fit them back; the kernels are here):

    * velocity_friction: mu(v) = mu (1 + viscous |v|) with v the motor speed [m/s] of this step.
    * pretension: the start profile is sheath.pretension + tension [N] (see the pretension bullet).
    * curvature_drift: K(t) = K + rate t [1/s] (all node gains scaled, route shape kept).
    * friction_step: K(t) = K + change from ``time`` [s] on (the sheath reshaped at one instant).
    * tendon_stiffening: element strain phi(T)/EA, phi(T) = T + softening T_c (1 - e^{-T/T_c}).
    * stiction: whenever the tendon does not slide it is stuck and the bound is mu (1 +
      static_ratio); when the slip front reaches the distal end it breaks away and slides with
      mu (1 + static_ratio e^{-(t - t_b)/slip_time}) (T_in drops, x_out and T_out jump); below
      0.2 mm/s it sticks again at once, which gives stick-slip on slow ramps.
    * friction_offset: dT/dtheta = -mu (T + a) sgn(v), a = tension_offset [N] (bending stiffness,
      clearance): the envelope rule on T + a, T >= 0.
    * presliding (the catalogue's lumped form): the distal tension the load cell sees is T_in - F, the
      friction F lagging the profile's T_0 - T_n in proximal travel, dF/ds = (T_0 - T_n - F) / distance
      (:meth:`~slave.simulated_effects.EffectSwitches._advance_distal`); the profile and the tendon end follow
      the memory model.
    * distal_backlash: the distal position (``truth.x_out``) sits behind a play of total ``width`` [m] from the
      tendon end, which carries the load: it stays until the end has crossed the gap, then follows it.
    * sensor_offset: the load cell reads T_in + offset [N]; sensor_gain: (1 + gain) T_in; sensor_drift:
      T_in + rate t [N/s], t from the start; sensor_delay: T_in(t - delay) (linear interpolation of the
      history). encoder_offset: the encoder reads x_in + offset [m] (its count of the rest reads offset).

    With the tendon effects (all but pretension and the sensor ones) a step is one of two: while
    the whole tendon slides and the motor keeps going that way (faster than 0.2 mm/s) the profile
    is the full-slip profile at the present friction (:func:`slave.simulated_effects.full_slip`,
    so it follows a change of speed or K at once); otherwise slip spreads from the proximal end
    (:func:`slave.simulated_effects.advance_general`, a bracketed root search instead of the exact
    scan) and the whole tendon starts sliding when it reaches the distal end.
    :meth:`set_load` re-balances with the plain Coulomb bounds of the moment.

    Parameters
    ----------
    sheath : SheathConfig
        The instrument's transmission: EA [N], route (runs of length [m] and radius [m]), pretension [N].
    rig : SimulatedRigConfig
        ``rig.simulated``: ``n_elements``, friction ``mu`` [-], ``motor``, ``load``, ``sensors``,
        ``effects`` (configs/default.yaml for units).

    Raises
    ------
    ConfigError
        A setting out of range (message names the dotted key, e.g. ``sheath.runs[1].length``).
    """

    def __init__(self, sheath: SheathConfig, rig: SimulatedRigConfig):
        _validate(sheath, rig)
        self._sheath_cfg = sheath
        self._rig_cfg = rig
        self.geometry = SheathGeometry([Run(r.length, r.radius) for r in sheath.runs])
        n = int(rig.n_elements)
        L = self.geometry.length
        self.s = np.linspace(0.0, L, n + 1)
        self.log_gain = rig.mu * np.asarray(self.geometry.wrap_angle(self.s), dtype=np.float64)
        self._lo = np.exp(-self.log_gain)
        self._hi = np.exp(self.log_gain)
        w = np.full(n + 1, L / (n * sheath.EA))
        w[0] *= 0.5
        w[-1] *= 0.5
        self._w = w
        self._c_pull = float(w @ self._lo) / self._lo[-1]  # e = c_pull T_d in full pull slip
        self._c_rel = float(w @ self._hi) / self._hi[-1]   # e = c_rel T_d in full release slip

        self._tissue = bool(rig.load.tissue)
        self._force = float(rig.load.force)
        self._graph = _load_graph(rig.load, self._tissue, self._force)

        self._init_effects(getattr(rig, "effects", None) or EffectsConfig(), n)
        P = float(sheath.pretension) + self._pretension
        self._T = np.full(n + 1, P)
        self._x_out = float(load_inverse(P, *self._graph)[0])
        self._x_in = self._x_out + elongation_general(self._T, self._w, self._beta, self._Tc)
        self._start_distal()

        self.drive = Drive(rig)                 # motor loop, encoder, load cell (shared by every simulated rig)
        self.encoder_resolution = self.drive.encoder_resolution
        self._t = 0.0
        self._closed = False
        self._state = self._read(self._x_in)

    @classmethod
    def from_config(cls, cfg: Config) -> SimulatedRig:
        """Build from a full :class:`teleop.config.load.Config`: the instrument's ``sheath`` and ``rig.simulated``."""
        return cls(cfg.sheath, cfg.rig.simulated)

    # ---- model constants -------------------------------------------------------------------------
    @property
    def n_elements(self) -> int:
        """Number of sheath elements n (n + 1 profile nodes)."""
        return self._T.shape[0] - 1

    @property
    def K(self) -> float:
        """Friction exponent mu * total wrap angle [-] (Phee et al. 2009, eq. (2))."""
        return float(self.log_gain[-1])

    @property
    def M_e(self) -> float:
        """Elongation per proximal tension in full pull slip [m/N]: sum_i w_i e^{-g_i}
        (the discrete form of (1/EA) int_0^L e^{-mu theta(s)} ds, Phee et al. 2009 eq. (12))."""
        return float(self._w @ self._lo)

    @property
    def tissue(self) -> bool:
        """Tissue contact enabled."""
        return self._tissue

    @property
    def force(self) -> float:
        """Set force of the distal torque-controlled actuator [N]."""
        return self._force

    # ---- Rig protocol -----------------------------------------------------------------------------
    @property
    def state(self) -> RigState:
        """The last state returned by :meth:`step` (the initial state before any step)."""
        return self._state

    def step(self, x_in_cmd: float, dt: float) -> RigState:
        """Advance the motor toward ``x_in_cmd`` [m] for ``dt`` [s], update the tendon, read sensors.

        Raises
        ------
        RigInputError (ValueError)
            ``x_in_cmd`` is not finite, or ``dt`` is not a finite number > 0.
        """
        try:
            cmd = float(x_in_cmd)
            h = float(dt)
        except (TypeError, ValueError):
            raise RigInputError(f"x_in_cmd and dt must be numbers, got x_in_cmd={x_in_cmd!r}, dt={dt!r}") from None
        if not math.isfinite(cmd):
            raise RigInputError(f"x_in_cmd must be a finite displacement in metres, got {x_in_cmd!r}")
        if not (math.isfinite(h) and h > 0.0):
            raise RigInputError(f"dt must be a finite time step > 0 s, got {dt!r}")
        # motor: exact first-order step toward the command, speed-limited
        dx = self.drive.move(self._x_in, cmd, h)
        self._x_in += dx
        if self._general:
            self._advance_effects(dx / h, self._t + h)
        else:
            self._x_out = advance_proximal(self._T, self._lo, self._hi, self._w, self._c_pull, self._c_rel,
                                           self._x_in, self._x_out, *self._graph)
        self._advance_distal(dx)
        self._t += h
        self._state = self._read(cmd)
        return self._state

    def set_load(self, *, tissue: bool | None = None, force: float | None = None) -> None:
        """Switch tissue contact and/or the distal set force [N] at the present motor position.

        The distal end re-balances with slip spreading from the distal end (see the class
        docstring); :attr:`state` is refreshed (new truth and a new sensor sample, same time).

        Raises
        ------
        RigInputError (ValueError)
            ``force`` is not a finite number >= 0, or ``tissue`` is not a bool.
        """
        if tissue is not None:
            if not isinstance(tissue, (bool, np.bool_)):
                raise RigInputError(f"tissue must be True or False, got {tissue!r}")
            self._tissue = bool(tissue)
        if force is not None:
            f = float(force)
            if not (math.isfinite(f) and f >= 0.0):
                raise RigInputError(f"force must be a finite distal set force >= 0 N, got {force!r}")
            self._force = f
        self._graph = _load_graph(self._rig_cfg.load, self._tissue, self._force)
        self._x_out = settle_distal(self._T, self._lo, self._hi, self._w, self._x_in, self._x_out, *self._graph)
        self._advance_distal(0.0)
        self._state = self._read(self._state.x_in_cmd)

    def close(self) -> None:
        """Nothing to release in simulation; idempotent. Stepping afterwards is allowed."""
        self._closed = True

    # ---- internals ----------------------------------------------------------------------------------
    def _read(self, cmd: float) -> RigState:
        T = self._T
        profile = T.copy()
        profile.flags.writeable = False
        e = elongation_general(T, self._w, self._beta, self._Tc)
        T_out, x_out = self._distal()
        truth = RigTruth(T_in=float(T[0]), T_out=T_out, x_in=self._x_in, x_out=x_out, elongation=e, profile=profile)
        T_meas = self._load_cell(float(T[0])) + self.drive.load_cell_noise()
        return RigState(t=self._t, x_in=self.drive.encoder(self._x_in) + self._encoder_offset, T_in=T_meas,
                        x_in_cmd=cmd, truth=truth)


def _load_graph(load: LoadConfig, tissue: bool, force: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The distal load law F(x), x > 0, as segments (start bx [m], F at start bF [N], slope bs [N/m]).

    F(x) = force + k_j x + [tissue] k_t max(0, x - x_c) + k_lim max(0, x - x_lim).
    """
    kt = load.tissue_stiffness if tissue else 0.0
    springs = [(0.0, load.joint_stiffness), (load.tissue_contact, kt), (load.joint_limit, load.limit_stiffness)]

    def F(x: float) -> float:
        return force + sum(k * max(0.0, x - x0) for x0, k in springs)

    def slope(x: float) -> float:  # slope just right of x
        return sum(k for x0, k in springs if x >= x0)

    starts = sorted({0.0} | {x0 for x0, k in springs if x0 > 0.0 and k > 0.0})
    bx = np.array(starts, dtype=np.float64)
    bF = np.array([F(x) for x in starts], dtype=np.float64)
    bs = np.array([slope(x) for x in starts], dtype=np.float64)
    return bx, bF, bs


def check_setting(ok: bool, key: str, expected: str, value: object) -> None:
    """Raise ConfigError "<key> must be <expected>, got <value>" unless ``ok``."""
    if not ok:
        raise ConfigError(f"{key} must be {expected}, got {value!r}")


def is_finite(v: object) -> bool:
    """A real finite number (bools are not numbers here)."""
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)



def validate_runs(runs, key: str) -> None:
    """A sheath route: non-empty, every run of finite length > 0 m and bend radius > 0 m (inf: straight)."""
    check_setting(len(runs) > 0, key, "a non-empty list of runs", runs)
    for i, r in enumerate(runs):
        check_setting(is_finite(r.length) and r.length > 0, f"{key}[{i}].length", "a finite length > 0 m", r.length)
        check_setting(isinstance(r.radius, (int, float)) and not math.isnan(r.radius) and r.radius > 0,
               f"{key}[{i}].radius", "a bend radius > 0 m (inf for straight)", r.radius)


def validate_drive(rig: SimulatedRigConfig) -> None:
    """What every simulated rig uses of ``rig.simulated``: element count, proximal motor, load-cell sensors."""
    n = rig.n_elements
    check_setting(isinstance(n, int) and not isinstance(n, bool) and n >= 1, f"{_SIM}.n_elements", "an integer >= 1", n)
    m = rig.motor
    check_setting(is_finite(m.bandwidth_hz) and m.bandwidth_hz > 0, f"{_SIM}.motor.bandwidth_hz",
                  "a finite number > 0 Hz", m.bandwidth_hz)
    check_setting(is_finite(m.max_speed) and m.max_speed > 0, f"{_SIM}.motor.max_speed", "a finite speed > 0 m/s",
                  m.max_speed)
    check_setting(is_finite(m.pulley_radius) and m.pulley_radius > 0, f"{_SIM}.motor.pulley_radius",
                  "a finite radius > 0 m", m.pulley_radius)
    lines = m.encoder_lines_per_rev
    check_setting(isinstance(lines, int) and not isinstance(lines, bool) and lines >= 1,
                  f"{_SIM}.motor.encoder_lines_per_rev", "an integer >= 1", lines)
    s = rig.sensors
    check_setting(is_finite(s.load_cell_noise) and s.load_cell_noise >= 0, f"{_SIM}.sensors.load_cell_noise",
           "a finite standard deviation >= 0 N", s.load_cell_noise)
    check_setting(isinstance(s.seed, int) and not isinstance(s.seed, bool), f"{_SIM}.sensors.seed", "an integer",
                  s.seed)


def _validate(sheath: SheathConfig, rig: SimulatedRigConfig) -> None:
    """Range checks of every setting the simulator uses; ConfigError names the dotted key."""
    check_setting(is_finite(rig.mu) and rig.mu >= 0, f"{_SIM}.mu", "a finite number >= 0", rig.mu)
    check_setting(is_finite(sheath.EA) and sheath.EA > 0, "sheath.EA", "a finite number > 0 N", sheath.EA)
    check_setting(is_finite(sheath.pretension) and sheath.pretension >= 0, "sheath.pretension",
                  "a finite number >= 0 N", sheath.pretension)
    validate_runs(sheath.runs, "sheath.runs")
    validate_drive(rig)
    ld = rig.load
    for key in ("joint_stiffness", "tissue_stiffness", "force", "joint_limit"):
        v = getattr(ld, key)
        check_setting(is_finite(v) and v >= 0, f"{_SIM}.load.{key}", "a finite number >= 0", v)
    check_setting(is_finite(ld.limit_stiffness) and ld.limit_stiffness > 0, f"{_SIM}.load.limit_stiffness",
           "a finite stiffness > 0 N/m", ld.limit_stiffness)
    check_setting(is_finite(ld.tissue_contact), f"{_SIM}.load.tissue_contact", "a finite position in m",
                  ld.tissue_contact)
    check_setting(isinstance(ld.tissue, (bool, np.bool_)), f"{_SIM}.load.tissue", "true or false", ld.tissue)
