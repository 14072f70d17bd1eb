"""Power-up calibration of a spindle-driven jaw from its proximal signals only (spindle angle and torque).

The routine strokes every spindle at ``calibration.speed`` (as cable travel, [m/s]) over the open side
of its jaw: rest -> A -> B -> A -> rest, with the jaw angles A = 0.1 and B = 0.9 of the jaw's lower angle
limit (``limits[0]``) turned into spindle angles by the kinematic ratio n_k = r_p / r_d. The stroke stays
inside the jaw's range: nothing is pulled against a stop and there is no knee to find, unlike the
joint-limit calibration of a tendon. On the way B -> A cable a pulls, on A -> B cable b; both cables
are in full slip at the stroke's middle M = (A + B) / 2. There the spindle torque of the two passes
differs by the capstan band only: with the pair's pretension torque Q = 2 P r_p (the sum of the
proximal cable torques) and equal friction exponents K on both cables,

    tau_up(M) - tau_down(M) = 2 Q tanh K                         (the jaw's load cancels at the same angle)

(from T_a,p = T_a,d e^{K}, T_b,p = T_b,d e^{-K}, T_a,p + T_b,p = Q on one branch and the mirror on the
other; Phee et al. 2009, eq. (1) per cable), so K = artanh(h / Q) with h half the difference. The
two passes are compared at the same jaw angle, not the same spindle angle: the cables' stretch puts
the jaw behind the spindle by lam tau_p (lam of (S4)), and a load that grows with the jaw angle would
otherwise enter the band. Each pass's torque is a straight line fitted over +-15 % of the stroke. The
pull-slip elongation per tension M_e follows from K, the route's wrap shape and L/EA.
"""
from __future__ import annotations

import datetime as _dt
import math

import numpy as np

from estimator.errors import CalibrationError
from slave.calibration_file import InstrumentCalibration, TendonCalibration
from slave.pair_calibrate import tendon_wrap_shape
from slave.rig import TENDONS, Rig, RigState
from teleop.config.schema import Config, JointConfig

__all__ = ["METHOD_SPINDLE", "SpindleCalibration", "stroke_points", "band_to_K", "pull_slip_M_e"]

METHOD_SPINDLE = "spindle stroke over the open jaw; K = artanh(half torque band / Q), M_e from K and the route"
#: Jaw angles of the stroke as fractions of the jaw's lower angle limit: rest -> A -> B -> A -> rest.
STROKE = (0.1, 0.9)


def stroke_points(joint: JointConfig) -> np.ndarray:
    """Spindle angles [rad] of the stroke's corners (rest, A, B, A, rest), relative to rest."""
    n_k = joint.spindle_radius / joint.pulley_radius
    a, b = (f * joint.limits[0] / n_k for f in STROKE)
    return np.array([0.0, a, b, a, 0.0])


def band_to_K(half_band: float, Q: float) -> float:
    """K = artanh(h / Q) (module docstring); ``half_band`` h and ``Q`` [N m].

    Raises
    ------
    CalibrationError
        h <= 0 (no friction band measured) or h >= Q (a cable went slack: more pretension needed).
    """
    if not (0.0 < half_band < Q):
        raise CalibrationError(f"spindle calibration: half torque band {half_band:.4g} N m must lie in (0, Q = {Q:.4g} "
                               f"N m); 0: no friction measured, >= Q: a cable went slack")
    return float(math.atanh(half_band / Q))


def pull_slip_M_e(joint: JointConfig, cable: str, K: float, n_points: int = 257) -> float:
    """Elongation per proximal tension in full pull slip [m/N]: (L/EA) mean_s exp(-K theta(s)/theta_total)."""
    tendon = getattr(joint.tendons, cable)
    c = tendon.geometry().length / tendon.EA
    shape = tendon_wrap_shape(tendon, n_points)
    s = np.linspace(0.0, 1.0, n_points) if shape is None else shape
    g = np.exp(-K * s)
    return float(c * (g.sum() - 0.5 * (g[0] + g[-1])) / (n_points - 1))


class SpindleCalibration:
    """The stroke of every spindle, one cycle at a time (module docstring).

    Attributes
    ----------
    history : list of (t, x_in, T_in)
        The rig's proximal samples from the start (spindle angles [rad], torques [N m]).
    done : bool
    """

    def __init__(self, cfg: Config, rig: Rig):
        c = cfg.calibration
        if not (math.isfinite(c.speed) and c.speed > 0):
            raise CalibrationError(f"calibration.speed must be a finite speed > 0 m/s, got {c.speed!r}")
        self.cfg, self.joints = cfg, cfg.instrument.joints
        st = rig.state
        self.rest = np.array(st.x_in, dtype=float)
        self.rate = np.array([c.speed / j.spindle_radius for j in self.joints])   # [rad/s]
        self.points = [stroke_points(j) for j in self.joints]
        self.leg = np.zeros(len(self.joints), dtype=int)
        self.cmd = self.rest.copy()
        self.history: list[tuple[float, np.ndarray, np.ndarray]] = [(st.t, self.rest.copy(), np.array(st.T_in))]
        self.done = False

    def command(self, state: RigState, dt: float) -> np.ndarray:
        """The spindle angles [rad] of the next cycle; records ``state``."""
        self.history.append((state.t, np.array(state.x_in, dtype=float), np.array(state.T_in, dtype=float)))
        for i, pts in enumerate(self.points):
            k = self.leg[i]
            if k >= len(pts) - 1:
                continue
            goal = self.rest[i] + pts[k + 1]
            step = self.rate[i] * dt
            if abs(goal - self.cmd[i]) <= step:
                self.cmd[i] = goal
                self.leg[i] += 1
            else:
                self.cmd[i] += math.copysign(step, goal - self.cmd[i])
        self.done = bool((self.leg >= 4).all()) and np.allclose(np.asarray(state.x_in), self.rest, atol=1e-3)
        return self.cmd.copy()

    def calibration(self, date: str | None = None) -> InstrumentCalibration:
        """The fitted calibration of every jaw (module docstring).

        Raises
        ------
        CalibrationError
            Too few samples at the stroke's middle, or a band out of range (:func:`band_to_K`).
        """
        date = date or _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")
        x = np.array([h[1] for h in self.history])
        tau = np.array([h[2] for h in self.history])
        out = []
        for i, j in enumerate(self.joints):
            pts = self.points[i]
            mid = self.rest[i] + 0.5 * (pts[1] + pts[2])
            win = 0.15 * abs(pts[2] - pts[1])
            rate = np.gradient(x[:, i])
            comp = [t.geometry().length / t.EA for t in (j.tendons.a, j.tendons.b)]
            jaw = x[:, i] - 0.25 * (comp[0] + comp[1]) * tau[:, i] / j.spindle_radius ** 2    # the jaw's angle / n_k
            near = np.abs(jaw - mid) <= win
            up, down = near & (rate > 0), near & (rate < 0)
            if up.sum() < 5 or down.sum() < 5:
                raise CalibrationError(f"spindle calibration of {j.name}: {int(up.sum())} and {int(down.sum())} "
                                       f"samples at the stroke's middle, need 5 each")
            Q = 2.0 * j.pretension * j.spindle_radius
            fits = [np.polyfit(jaw[sel] - mid, tau[sel, i], 1) for sel in (up, down)]
            h = 0.5 * float(fits[0][1] - fits[1][1])
            K = band_to_K(h, Q)
            resid = tau[up, i] - np.polyval(fits[0], jaw[up] - mid)
            noise = float(np.std(resid)) / (math.sqrt(2.0) * j.spindle_radius)
            cables = {}
            for t in TENDONS:
                tendon = getattr(j.tendons, t)
                cables[t] = TendonCalibration(K=K, M_e=pull_slip_M_e(j, t, K),
                                              compliance=tendon.geometry().length / tendon.EA, knee_x_in=0.0,
                                              knee_T_in=0.0, residual_rms=0.0, n_samples=int(up.sum() + down.sum()),
                                              tension_noise=noise)
            out.append((j.name, cables))
        c = self.cfg.calibration
        return InstrumentCalibration(instrument=self.cfg.instrument.id, date=date, target_tension=c.target_tension,
                                     use_route=c.use_route, joints=tuple(out), method=METHOD_SPINDLE)
