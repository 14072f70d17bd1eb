"""The spindle pair model of :mod:`estimator.online.spindle`, one sample at a time (the slave's rate).

The same equations (S1)-(S4) with the E2 lag, E8 spindle friction and E12 play as the batch model,
carried forward one cycle with the state kept between calls: both cables' tension profiles (the
memory), the smoothed spindle rate, the lagged direction term and the play output. Inputs are the
spindle's torque tau_p [N m] and angle theta_p [rad] only (the proximal signals); out come the jaw
torque [N m] and angle [rad], and per cable the proximal and distal tension [N], the elongation [m] and
the readable phase (:mod:`estimator.phase`: which branch of the capstan law the cable is on).

Tensions inside are in torque units at the spindle (tension times the spindle radius r_p, N m), as in
:mod:`estimator.online.spindle`; the sample gives them in N.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from estimator.online.spindle import N_NODES, OMEGA_S, SpindleParams
from estimator.phase import Phase
from estimator.readable_phase import new_phase_state, readable_step
from estimator.sheath import envelope_clip

__all__ = ["SpindleSample", "SpindleEstimator"]


@dataclass(frozen=True)
class SpindleSample:
    """One estimate: jaw ``torque`` [N m] and ``angle`` [rad]; per cable (a, b) ``T_in`` the proximal
    tension [N], ``T_out`` the distal tension [N], ``elongation`` [m], ``phase``."""

    torque: float
    angle: float
    T_in: tuple[float, float]
    T_out: tuple[float, float]
    elongation: tuple[float, float]
    phase: tuple[Phase, Phase]


@njit(cache=True, nogil=True)
def _move_distal(T, lo, hi, t_p, v):  # pragma: no cover - compiled
    """Move a profile's distal end to tension ``v`` by sliding its distal end: raised, node j >= v hi_j /
    hi_n (release slip from the tip); lowered, node j <= v lo_j / lo_n (pull slip from the tip); both
    within the envelope [t_p lo_j, t_p hi_j] of the proximal tension t_p."""
    n = T.shape[0]
    for j in range(n):
        if v > T[n - 1]:
            T[j] = max(T[j], min(v * hi[j] / hi[n - 1], t_p * hi[j]))
        else:
            T[j] = min(T[j], max(v * lo[j] / lo[n - 1], t_p * lo[j]))


@njit(cache=True, nogil=True)
def _cables(Ta, Tb, lo_a, hi_a, lo_b, hi_b, w, ta, tb):  # pragma: no cover - compiled
    """Both profiles' envelope update (Phee et al. 2009, eq. (1) per node) for proximal tensions ta, tb,
    then the pair coupling (E13): when one cable's distal end slips (its distal tension changes on its
    envelope) while the other's is stuck, the jaw turns and moves the stuck cable's distal end with it;
    the jaw's load changes little over that motion, so the stuck cable's distal tension changes by as
    much as the slipping one's (within its own envelope). Returns (T_a,d, T_b,d, E_a, E_b), E the
    mean profile tension."""
    n = Ta.shape[0]
    a0, b0 = Ta[n - 1], Tb[n - 1]
    for j in range(n):
        Ta[j] = envelope_clip(Ta[j], ta * lo_a[j], ta * hi_a[j])
        Tb[j] = envelope_clip(Tb[j], tb * lo_b[j], tb * hi_b[j])
    da, db = Ta[n - 1] - a0, Tb[n - 1] - b0
    if da != 0.0 and db == 0.0:
        _move_distal(Tb, lo_b, hi_b, tb, b0 + da)
    elif db != 0.0 and da == 0.0:
        _move_distal(Ta, lo_a, hi_a, ta, a0 + db)
    ea = 0.0
    eb = 0.0
    for j in range(n):
        ea += w[j] * Ta[j]
        eb += w[j] * Tb[j]
    return Ta[n - 1], Tb[n - 1], ea, eb


class SpindleEstimator:
    """Online spindle pair model (module docstring).

    Parameters
    ----------
    params : SpindleParams
        The model's constants (:mod:`estimator.online.spindle`, SI units; Q > 0, K_a, K_b >= 0).
    r_p : float
        Spindle radius [m] > 0 (turns the torque-unit tensions into N).
    compliance : tuple of float
        L/EA of cable a and b [m/N] > 0 (their elongations).
    theta_ref : float
        Spindle angle at rest [rad] (where the elastic terms and the jaw zero are measured from).
    n_nodes : int
        Profile elements per cable (>= 2).
    rate_time_constant : float
        Time constant of the smoothed spindle rate [s] > 0.
    phase_band, hold_rate : float
        The readable phase's noise band [N] > 0 and hold rate [N/s] > 0 (:mod:`estimator.phase`).
    shapes : tuple of (ndarray or None)
        Each cable's wrap angle along its length, theta(s) / theta_total at the n_nodes + 1 nodes
        (:func:`slave.pair_calibrate.tendon_wrap_shape`); None: the wrap spread evenly (the batch model's).

    Raises
    ------
    ValueError
        Q <= 0, a negative K, r_p or a compliance <= 0, n_nodes < 2 or a time constant <= 0.
    """

    def __init__(self, params: SpindleParams, r_p: float, compliance: tuple[float, float], theta_ref: float = 0.0,
                 n_nodes: int = N_NODES, rate_time_constant: float = 0.02, phase_band: float = 0.2,
                 hold_rate: float = 0.5, shapes: tuple[np.ndarray | None, np.ndarray | None] = (None, None)):
        p = params
        if not (p.Q > 0 and p.K_a >= 0 and p.K_b >= 0 and math.isfinite(p.Q + p.K_a + p.K_b)):
            raise ValueError(f"spindle model: Q must be > 0 and K_a, K_b >= 0, got Q={p.Q!r}, K={p.K_a!r}, {p.K_b!r}")
        if not (r_p > 0 and min(compliance) > 0 and n_nodes >= 2 and rate_time_constant > 0):
            raise ValueError(f"spindle model: r_p={r_p!r} m, compliance={compliance!r} m/N must be > 0, "
                             f"n_nodes={n_nodes!r} >= 2, rate_time_constant={rate_time_constant!r} s > 0")
        self.params, self.r_p, self.compliance = p, float(r_p), (float(compliance[0]), float(compliance[1]))
        self.theta_ref = float(theta_ref)
        self.tc, self.band, self.hold_rate = float(rate_time_constant), float(phase_band), float(hold_rate)
        even = np.arange(n_nodes + 1) / n_nodes
        sa, sb = (even if sh is None else np.asarray(sh, dtype=float) for sh in shapes)
        if sa.shape != even.shape or sb.shape != even.shape:
            raise ValueError(f"spindle model: a wrap shape needs n_nodes + 1 = {n_nodes + 1} values")
        self.lo_a, self.hi_a = np.exp(-p.K_a * sa), np.exp(p.K_a * sa)
        self.lo_b, self.hi_b = np.exp(-p.K_b * sb), np.exp(p.K_b * sb)
        self.w = np.full(n_nodes + 1, 1.0 / n_nodes)
        self.w[0] *= 0.5
        self.w[-1] *= 0.5
        self.Ta = np.full(n_nodes + 1, 0.5 * p.Q)      # at rest: both cables uniform at the pretension
        self.Tb = np.full(n_nodes + 1, 0.5 * p.Q)
        self._t: float | None = None
        self._theta = self.theta_ref
        self.omega = 0.0
        self._dir = 0.0             # the lagged direction term of the spindle friction (E8 with E2)
        self._lag: float | None = None
        self._play: float | None = None
        self._phase = (new_phase_state(0.5 * p.Q / r_p), new_phase_state(0.5 * p.Q / r_p))

    @property
    def profiles(self) -> tuple[np.ndarray, np.ndarray]:
        """Both cables' node tensions [N], proximal to distal, shape (n_nodes + 1,) each (copies)."""
        return self.Ta / self.r_p, self.Tb / self.r_p

    def step(self, tau_p: float, theta_p: float, t: float) -> SpindleSample:
        """One sample: spindle torque ``tau_p`` [N m] and angle ``theta_p`` [rad] at time ``t`` [s]."""
        p, r = self.params, self.r_p
        dt = 0.0 if self._t is None else t - self._t
        if dt > 0.0:
            raw = (theta_p - self._theta) / dt
            self.omega += (raw - self.omega) * (1.0 - math.exp(-dt / self.tc))
        travel = abs(theta_p - self._theta)
        self._t, self._theta = t, theta_p
        d = theta_p - self.theta_ref
        u = tau_p - p.k_p * d - p.c_v * self.omega
        if p.f_s != 0.0:
            blend = 1.0 - math.exp(-travel / max(p.theta_s, 1e-4))
            self._dir += (math.tanh(self.omega / OMEGA_S) - self._dir) * blend
            u -= p.f_s * self._dir
        ta, tb = max(0.5 * (p.Q + u), 0.0), max(0.5 * (p.Q - u), 0.0)
        Tad, Tbd, ea, eb = _cables(self.Ta, self.Tb, self.lo_a, self.hi_a, self.lo_b, self.hi_b, self.w, ta, tb)
        tau = p.rho * (1.0 + (p.rho_1 + p.rho_2 * d) * d) * (Tad - Tbd) + p.b + p.k_d * d
        tau -= p.f * math.tanh(self.omega / OMEGA_S)
        if p.theta_c > 1e-6:
            self._lag = (tau if self._lag is None
                         else self._lag + (tau - self._lag) * (1.0 - math.exp(-travel / p.theta_c)))
            tau = self._lag
        ang = p.n_k * (theta_p - p.lam * (ea - eb)) + p.theta0
        if p.beta > 0:
            y = ang if self._play is None else self._play
            self._play = ang = min(max(y, ang - p.beta), ang + p.beta)
        ph = (Phase(readable_step(self._phase[0], ta / r, Tad / r, t, p.K_a, self.band, self.hold_rate)),
              Phase(readable_step(self._phase[1], tb / r, Tbd / r, t, p.K_b, self.band, self.hold_rate)))
        return SpindleSample(float(tau), float(ang), (ta / r, tb / r), (Tad / r, Tbd / r),
                             (self.compliance[0] * ea / r, self.compliance[1] * eb / r), ph)
