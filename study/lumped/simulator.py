r"""Dynamic lumped-mass tendon-sheath simulator: a second, independent formulation of the physics.

The quasi-static rig (:mod:`slave.simulated`) solves the capstan envelope of a massless tendon with
Coulomb friction exactly. This one integrates Newton's law for a chain of tendon masses instead,
with a bristle friction state per node, so that it can serve as an independent second opinion:

* Tendon: ``n`` elements of length ds = L / n between the proximal tendon point (behind the
  sheath spring) and nodes i = 0..n-1 at s_i = (i + 1) ds. Node mass m_i = rho ds (half at the
  distal node, plus the distal load mass). Element tension from its stretch e_i [m]:
  phi(T_i) = (EA / ds) e_i with phi(T) = T + beta T_c (1 - e^{-T/T_c}) (beta = 0: linear); a
  tendon cannot push, T_i = 0 for e_i <= 0.
* Route: straight runs and arcs (:class:`estimator.geometry.SheathGeometry`, geometry only); node i
  carries the wrap angle dtheta_i of the route over [s_i - ds/2, s_i + ds/2] (node 0 also the
  first half element, the distal node the last half).
* Friction of node i: normal force N_i = Tbar_i dtheta_i + (q + rho g) ds_i (Tbar_i the mean tension
  of its two elements, q a tension-independent normal load per length for E8, rho g the tendon's
  weight: ~0.013 N/m, 2 mN of friction over 1.5 m, below any load cell's noise).
  Each node carries a bristle friction state F_i (elasto-plastic single-state model, the
  LuGre family with a sharp pre-sliding limit; Dupont et al. 2002) whose bound scales with the
  normal force:
      |F_i| <= Fc_i = N_i g(v_i),   dF_i/dt = (Fc_i / z_ss) v_i while |F_i| < Fc_i (stick),
      F_i = sgn(v_i) Fc_i while sliding,
      g(v) = mu(t) (1 + c_v |v|) (1 + r_s exp(-(v / v_s)^2)),   mu(t) = mu + mu_rate t,
  plus a viscous c ds v_i. A node pre-slides elastically over z_ss = d_p / 2 [m] before it slides:
  its friction reverses from -Fc to +Fc over the travel d_p (the ``presliding`` distance; 10 nm by
  default, far below any encoder quantum; a Dahl law dF/dx = (Fc / d_p)(1 - sgn(v) F / Fc) has the
  same stiffness 2 Fc / d_p right after a reversal); when Fc_i drops
  below |F_i| (tension falls, Stribeck decay) F_i is clipped to the bound at once. A Stribeck
  peak r_s > 0 gives breakaway and stick-slip. F_i does not jump when N_i changes, so a rising
  tension cannot pump energy into a stuck node.
* Sheath: a series spring k_s between the motor and the proximal tendon point,
  x_p = x_motor - T_in / k_s (inf: rigid sheath).
* Distal load on the last node: a piecewise-linear force law F(x) (:class:`Load`: spring,
  preloaded spring on a lower stop, constant force on a lower stop, joint spring with a hard
  limit, fixed end) with its mass and viscous damping. The distal load cell reads
  T_out = F(x) + b v + m_load a. The joint (x_out) follows the tendon end through a play operator
  of total width ``backlash``.
* Motor: first-order position loop of bandwidth f_bw toward the command (linear between samples),
  speed-limited to v_max. Load cell T_in = T_0; encoder = motor position.
* Integration: backward Euler on the velocities, the element tangent stiffness and friction
  bounds frozen per substep, the stick/slip status of every node, the taut/slack state of every
  element and the piece of the load law at the end of the substep found by an active-set
  iteration (each pass one tridiagonal solve, :mod:`study.lumped.kernel`); stable for any
  substep (default 10 kHz; 5 and 160 kHz agree within 0.01 N on a 40 mm/s pull), a slack tendon
  included (contact taken at the start of a substep instead overflows when a slack tendon snaps taut).
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from estimator.geometry import SheathGeometry
from study.lumped.kernel import simulate

__all__ = ["Load", "LumpedTendon", "LOAD_KINDS"]

LOAD_KINDS = ("spring", "preloaded", "constant", "joint", "fixed", "tissue", "contact")
_TISSUE_KNOTS = 9          # breakpoints of the piecewise-linear exponential tissue law, 0 to 4 stiffening lengths
_GRAVITY = 9.81  # m/s^2


def _check(ok: bool, name: str, expected: str, value: object) -> None:
    if not ok:
        raise ValueError(f"{name} must be {expected}, got {value!r}")


def _pos(x: object) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) and x > 0


def _nonneg(x: object) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) and x >= 0


@dataclass(frozen=True)
class Load:
    """Distal load law, x [m] the distal displacement (+ toward the actuator), force [N] distal.

    kind : "spring" F = k x; "preloaded" F = P + k x on a lower stop at 0; "constant" F = P on a
    lower stop at 0; "joint" F = k x up to ``limit`` [m], then a hard stop; "fixed" a hard stop
    at 0 (stiffness ``stop``); "tissue" nonlinear (stiffening) tissue F = k l (e^{x/l} - 1), l = ``limit``,
    piecewise linear through 9 points from 0 to 4 l, on a lower stop at 0; "contact" free space on a spring
    F = k x up to the contact at ``limit`` [m], then tissue of ``contact_stiffness`` [N/m] in parallel.
    mass [kg] and damping [N s/m] of the load.
    """

    kind: str = "fixed"
    stiffness: float = 0.0
    preload: float = 0.0
    limit: float = 0.0
    stop: float = 2e6
    mass: float = 0.005
    damping: float = 2.0
    contact_stiffness: float = 0.0

    def __post_init__(self) -> None:
        _check(self.kind in LOAD_KINDS, "load.kind", f"one of {LOAD_KINDS}", self.kind)
        _check(_nonneg(self.stiffness), "load.stiffness", "a number >= 0 N/m", self.stiffness)
        _check(_nonneg(self.preload), "load.preload", "a number >= 0 N", self.preload)
        _check(_nonneg(self.limit), "load.limit", "a number >= 0 m", self.limit)
        _check(_pos(self.stop), "load.stop", "a number > 0 N/m", self.stop)
        _check(_nonneg(self.mass), "load.mass", "a number >= 0 kg", self.mass)
        _check(_nonneg(self.damping), "load.damping", "a number >= 0 N s/m", self.damping)
        _check(_nonneg(self.contact_stiffness), "load.contact_stiffness", "a number >= 0 N/m", self.contact_stiffness)
        if self.kind in ("spring", "joint", "tissue", "contact"):
            _check(self.stiffness > 0, "load.stiffness", f"> 0 N/m for a {self.kind} load", self.stiffness)
        if self.kind in ("tissue", "contact"):
            _check(self.limit > 0, "load.limit", f"> 0 m for a {self.kind} load", self.limit)

    def graph(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Breakpoints lx [m], forces lF [N] and slopes ls [N/m] (len(lx) + 1) of the force law."""
        k, P, S = self.stiffness, self.preload, self.stop
        if self.kind == "spring":
            pts, sl = [(0.0, 0.0)], [k, k]
        elif self.kind == "preloaded":
            pts, sl = [(0.0, P)], [S, k]
        elif self.kind == "constant":
            pts, sl = [(0.0, P)], [S, 0.0]
        elif self.kind == "joint":
            pts, sl = [(0.0, 0.0), (self.limit, k * self.limit)], [S, k, S]
        elif self.kind == "tissue":
            knots = np.linspace(0.0, 4.0 * self.limit, _TISSUE_KNOTS)
            forces = k * self.limit * np.expm1(knots / self.limit)
            pts = list(zip(knots.tolist(), forces.tolist(), strict=True))
            sl = [S, *(np.diff(forces) / np.diff(knots)).tolist(), k * math.exp(4.0)]
        elif self.kind == "contact":
            pts, sl = [(0.0, 0.0), (self.limit, k * self.limit)], [S, k, k + self.contact_stiffness]
        else:
            pts, sl = [(0.0, 0.0)], [S, S]
        lx, lF = (np.array(c, dtype=float) for c in zip(*pts, strict=False))
        return lx, lF, np.array(sl, dtype=float)

    def position_at(self, force: float) -> float:
        """Smallest displacement x [m] where the law gives ``force`` [N] (inverse of the graph)."""
        lx, lF, ls = self.graph()
        if force <= lF[0]:
            return float(lx[0] + (force - lF[0]) / ls[0])
        for j in range(1, len(lx)):
            if force <= lF[j]:
                return float(lx[j - 1] + (force - lF[j - 1]) / ls[j])
        if ls[-1] <= 0:
            return float(lx[-1])
        return float(lx[-1] + (force - lF[-1]) / ls[-1])

    def describe(self) -> dict:
        return asdict(self)


class LumpedTendon:
    """One tendon in a sheath, simulated as a chain of masses (module docstring for the equations).

    Parameters (SI units; every bad value raises ValueError naming the argument)
    ----------
    route : SheathGeometry or sequence of (length [m], radius [m]) pairs, proximal to distal.
    mu : float >= 0, Coulomb (kinetic) friction coefficient; K = mu * route.total_angle.
    EA : float > 0 [N], tendon axial stiffness.
    load : Load, distal load.
    n_nodes : int >= 4, number of elements (= masses).
    line_density : float > 0 [kg/m], tendon mass per length.
    presliding : float > 0 [m], pre-sliding distance d_p: the travel over which a node's friction
        reverses (bristle stiffness 2 Fc / d_p).
    static_ratio : float >= 0, Stribeck peak r_s (mu_static / mu_kinetic - 1); stribeck_speed [m/s].
    speed_coefficient : float >= 0 [s/m], c_v in g(v) = mu (1 + c_v |v|) (E3).
    viscous : float >= 0 [N s/m^2], tension-independent viscous friction per length.
    normal_load : float >= 0 [N/m], q, tension-independent normal load per length (E8).
    softening, toe_tension : beta >= 0 [-], T_c > 0 [N] of the stiffening law (E9).
    pretension : float >= 0 [N], uniform tension at rest (E5).
    mu_rate : float [1/s], d mu / dt (E6).
    backlash : float >= 0 [m], total play between the tendon end and the joint (E12).
    sheath_stiffness : float > 0 [N/m] or inf, series sheath spring k_s.
    motor_bandwidth_hz, motor_max_speed : float > 0 [Hz], [m/s].
    substep_hz : float >= 1000 [Hz], integration rate (rounded up to a multiple of the sample rate).
    newton_iterations : int in [1, 20], most active-set passes (tridiagonal solves) per substep.
    """

    def __init__(self, route, mu: float, EA: float, load: Load | None = None, *, n_nodes: int = 48,
                 line_density: float = 1.3e-3, presliding: float = 1e-8, static_ratio: float = 0.0,
                 stribeck_speed: float = 1e-3, speed_coefficient: float = 0.0, viscous: float = 0.0,
                 normal_load: float = 0.0, softening: float = 0.0, toe_tension: float = 1.0,
                 pretension: float = 0.0, mu_rate: float = 0.0, backlash: float = 0.0,
                 sheath_stiffness: float = math.inf, motor_bandwidth_hz: float = 60.0,
                 motor_max_speed: float = 0.2, substep_hz: float = 10000.0, newton_iterations: int = 10):
        if not isinstance(route, SheathGeometry):
            try:
                route = SheathGeometry(route)
            except (TypeError, ValueError) as exc:
                raise ValueError(f"route must be a SheathGeometry or (length, radius) pairs: {exc}") from None
        load = Load() if load is None else load
        _check(isinstance(load, Load), "load", "a study.lumped.simulator.Load", load)
        _check(_nonneg(mu), "mu", "a number >= 0", mu)
        _check(_pos(EA), "EA", "a number > 0 N", EA)
        _check(isinstance(n_nodes, int) and not isinstance(n_nodes, bool) and n_nodes >= 4, "n_nodes",
               "an int >= 4", n_nodes)
        for name, val in (("line_density", line_density), ("presliding", presliding),
                          ("stribeck_speed", stribeck_speed), ("toe_tension", toe_tension),
                          ("motor_bandwidth_hz", motor_bandwidth_hz), ("motor_max_speed", motor_max_speed)):
            _check(_pos(val), name, "a number > 0", val)
        for name, val in (("static_ratio", static_ratio), ("speed_coefficient", speed_coefficient),
                          ("viscous", viscous), ("normal_load", normal_load), ("softening", softening),
                          ("pretension", pretension), ("backlash", backlash)):
            _check(_nonneg(val), name, "a number >= 0", val)
        _check(isinstance(mu_rate, (int, float)) and math.isfinite(mu_rate), "mu_rate", "a finite number", mu_rate)
        _check(isinstance(sheath_stiffness, (int, float)) and sheath_stiffness > 0, "sheath_stiffness",
               "a number > 0 N/m or inf", sheath_stiffness)
        _check(_pos(substep_hz) and substep_hz >= 1000.0, "substep_hz", "a number >= 1000 Hz", substep_hz)
        self.route, self.mu, self.EA, self.load = route, float(mu), float(EA), load
        self.L = route.length
        self.n = n = n_nodes
        self.ds = ds = self.L / n
        _check(isinstance(newton_iterations, int) and not isinstance(newton_iterations, bool)
               and 1 <= newton_iterations <= 20, "newton_iterations", "an int in [1, 20]", newton_iterations)
        self.substep_hz = float(substep_hz)
        self.n_iter = newton_iterations
        self.backlash = float(backlash)
        self.pretension = float(pretension)
        self.motor = (float(motor_bandwidth_hz), float(motor_max_speed))
        # wrap angle per node: [s_i - ds/2, s_i + ds/2], node 0 from 0, distal node to L
        s_nodes = ds * np.arange(1, n + 1)
        edges = np.concatenate(([0.0], s_nodes[:-1] + 0.5 * ds, [self.L]))
        self.dtheta = np.diff(route.wrap_angle(edges))
        self.mass = np.full(n, line_density * ds)
        self.mass[-1] = 0.5 * line_density * ds + load.mass
        seg = np.full(n, ds)
        seg[0], seg[-1] = 1.5 * ds, 0.5 * ds
        self.qds = (normal_load + _GRAVITY * line_density) * seg   # the tendon's weight presses too
        self.visc = viscous * seg
        self.k_lin = self.EA / ds
        self.beta, self.Tc = float(softening), float(toe_tension)
        self.inv_ks = 0.0 if math.isinf(sheath_stiffness) else 1.0 / float(sheath_stiffness)
        self.mu_rate = float(mu_rate)
        self.friction = (float(speed_coefficient), float(static_ratio), float(stribeck_speed))
        self.presliding = float(presliding)
        self.graph = load.graph()
        self.reset()

    @property
    def K(self) -> float:
        """Friction exponent mu * total wrap angle [-] at t = 0."""
        return self.mu * self.route.total_angle

    @property
    def compliance(self) -> float:
        """L / EA [m/N]."""
        return self.L / self.EA

    def reset(self) -> None:
        """Rest state: uniform pretension along the tendon, distal end where the load holds it,
        velocities and friction states zero, time 0."""
        P, n = self.pretension, self.n
        u_end = self.load.position_at(P) if P > 0 else min(0.0, self.load.position_at(0.0))
        y = P + self.beta * self.Tc * -math.expm1(-P / self.Tc)  # phi(P)
        e = np.full(n, y / self.k_lin)
        self.e, self.T = e, np.full(n, P)
        self.u = u_end + np.concatenate((np.cumsum(e[:0:-1])[::-1], [0.0]))
        self.v = np.zeros(n)
        self.z = np.zeros(n)
        self.status = np.zeros(n, dtype=np.int64)
        xp = self.u[0] + e[0]
        xm = xp + P * self.inv_ks
        self.state = np.array([xm, xp, u_end, 0.0, P])

    @property
    def time(self) -> float:
        return float(self.state[3])

    @property
    def elongation(self) -> float:
        """Tendon elongation sum(e_i) [m] (stretch only, without the sheath spring)."""
        return float(self.e.sum())

    def run(self, x_cmd: np.ndarray, rate_hz: float) -> dict[str, np.ndarray]:
        """Advance over motor commands ``x_cmd`` [m], shape (n,), sampled at ``rate_hz`` [Hz].

        Returns noise-free signals at the sample instants, shape (n,) each: ``x_motor`` [m] (encoder
        before quantisation), ``T_in`` [N], ``x_end`` [m] tendon distal end, ``T_out`` [N],
        ``x_joint`` [m] (behind the backlash), ``x_p`` [m] proximal tendon point.

        Raises
        ------
        ValueError
            ``x_cmd`` not a finite 1-D array or ``rate_hz`` not > 0.
        """
        x = np.ascontiguousarray(x_cmd, dtype=np.float64)
        _check(x.ndim == 1 and bool(np.all(np.isfinite(x))), "x_cmd", "a finite 1-D array of metres", x.shape)
        _check(_pos(rate_hz), "rate_hz", "a number > 0 Hz", rate_hz)
        n_sub = max(1, int(math.ceil(self.substep_hz / rate_hz - 1e-9)))
        dt = 1.0 / (rate_hz * n_sub)
        f_bw, v_max = self.motor
        out = np.empty((x.size, 6))
        cv, rs, vs = self.friction
        lx, lF, ls = self.graph
        simulate(x, n_sub, dt, -math.expm1(-2 * math.pi * f_bw * dt), v_max, self.u, self.v, self.e, self.T,
                 self.z, self.status, self.state, self.mass, self.dtheta, self.qds, self.visc, self.k_lin,
                 self.beta, self.Tc,
                 self.inv_ks, self.mu, self.mu_rate, cv, rs, vs, 2.0 / self.presliding, lx, lF, ls,
                 self.load.damping,
                 self.load.mass, 0.5 * self.backlash, self.n_iter, out)
        return {"x_motor": out[:, 0], "T_in": out[:, 1], "x_end": out[:, 2], "T_out": out[:, 3],
                "x_joint": out[:, 4], "x_p": out[:, 5]}
