"""Distal (jaw) torque and angle of a cable pair driven by one input spindle, from the spindle alone.

The spindle pair model (the seed paper's capstan law with profile memory, Phee et al. 2009, applied
to the two cables of a pull-pull pair; docs/concepts/effects.md E1, E5, E13). All tensions are written in
torque units at the spindle (tension times the spindle radius r_p, N m), so only ratios of the
pulley radii appear::

    d       = theta_p - theta_ref
    u       = tau_p - k_p d - c_v omega_p - f_s lag(tanh(omega_p / omega_s), theta_s)
                                                                 spindle torque on the cables [N m]
    T_a,p   = (Q + u) / 2,   T_b,p = (Q - u) / 2                 the two proximal cable tensions     (S1)
    T_j,d   = profile memory of cable j, friction exponent K_j   (estimator.sheath envelope rule)    (S2)
    tau_d   = rho (1 + rho_1 d + rho_2 d^2) (T_a,d - T_b,d) + b + k_d d - f tanh(omega_p / omega_s)  (S3)
    (E2)    tau_d <- angle_lag(tau_d, theta_p, theta_c)          when theta_c > 0
    theta_d = n_k (theta_p - lam (E_a - E_b)) + theta_0,   E_j = mean_s T_j(s)                       (S4)
    (E12)   theta_d <- play(theta_d, beta)

Parameters (SI): rho = r_d / r_p scaled by the sensors [-] (distal torque per unit of cable torque
difference), rho_1 [1/rad], rho_2 [1/rad^2] its change with the angle (the cable's lever arm at the
jaw, E7), theta_c [rad] the travel of the E2 lag, Q = (T_a + T_b) r_p the pretension torque [N m] (>= max |u|,
else a cable goes slack), K_a, K_b the friction exponents of the two cables' paths over the shaft pulleys [-]
(equal for a symmetric routing; K_a != K_b makes the band grow with the load, E13), b the distal
torque at zero cable torque difference [N m] (internal preload, sensor zero), k_p [N m/rad] an
elastic torque inside the proximal end (seal, spring, or the two cables' wrap angles changing in
opposite senses with the angle; it loads the spindle, not the jaw), f_s [N m] friction at the
spindle itself, ahead of the cables (bearings, seals; tension-independent, E8), whose direction
term reverses over a spindle travel theta_s [rad] (default SPINDLE_TRAVEL; ``angle_lag``: pre-sliding, E2), k_d
[N m/rad] an angle-dependent torque at the jaw side, f [N m] Coulomb friction beyond the jaw pulley
(jaw pivot, and on this rig the load motor; E11), c_v [N m s/rad] viscous torque at the spindle
(E3), n_k = r_p / r_d the kinematic ratio [-], lam [rad/(N m)] cable compliance seen at the
spindle, theta_0 [rad] the jaw zero, beta [rad] jaw-side backlash half-width (E12).

Inputs are the spindle torque tau_p [N m] and angle theta_p [rad] only; omega_p is their smoothed
derivative. Initial state: at rest each cable lies in full slip on the branch it last moved on,
taken from the sign of (tau_p(0) - centre) with ``centre`` the middle of the calibration's
proximal torque band (:func:`initial_side`).
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace

import numpy as np
from numba import njit

from estimator.sheath import envelope_clip

__all__ = ["SPINDLE_TRAVEL", "SpindleParams", "Batch", "make_batch", "pair_kernel", "predict_torque", "predict_angle",
           "play_batch", "angle_lag", "elongation_difference", "spindle_rate", "initial_side", "first_reversal",
           "OMEGA_S", "N_NODES"]

#: Speed scale of the smoothed direction of motion, tanh(omega / OMEGA_S) [rad/s].
OMEGA_S = 0.05
#: Spindle travel over which the spindle's own friction reverses (E2 at the proximal end) [rad]: after
#: a reversal the MRD spindle torque creeps over 2-3 deg while the jaw stands still (docs/results/mrd.md).
SPINDLE_TRAVEL = 0.05
#: Profile elements per cable (the distal tension changes by < 1e-4 relative from 16 to 64).
N_NODES = 16


@dataclass(frozen=True)
class SpindleParams:
    """Spindle pair model parameters (module docstring, SI units)."""

    rho: float = 1.0
    rho_1: float = 0.0
    rho_2: float = 0.0
    Q: float = 0.3
    K_a: float = 0.3
    K_b: float = 0.3
    b: float = 0.0
    k_p: float = 0.0
    k_d: float = 0.0
    f: float = 0.0
    f_s: float = 0.0
    theta_s: float = 0.05
    c_v: float = 0.0
    theta_c: float = 0.0
    n_k: float = 1.0
    lam: float = 0.0
    theta0: float = 0.0
    beta: float = 0.0

    def as_dict(self) -> dict[str, float]:
        return {k: float(v) for k, v in asdict(self).items()}

    def with_values(self, **kw) -> SpindleParams:
        return replace(self, **{k: float(v) for k, v in kw.items()})


@dataclass(frozen=True)
class Batch:
    """Runs concatenated for the kernel; arrays of shape (n,) unless noted.

    tau_p [N m], theta_p [rad], omega_p [rad/s]; starts int64 (m + 1,) run boundaries;
    side float64 (m,) initial branch of each run (+1 / -1, :func:`initial_side`);
    theta_ref [rad], the spindle angle the elastic terms are measured from.
    """

    tau_p: np.ndarray
    theta_p: np.ndarray
    omega_p: np.ndarray
    starts: np.ndarray
    side: np.ndarray
    theta_ref: float


def spindle_rate(theta: np.ndarray, dt: float, half_window: int = 25) -> np.ndarray:
    """Smoothed derivative [rad/s], shape of ``theta`` [rad]: central difference over
    2 ``half_window`` samples of spacing ``dt`` [s] (one-sided at the ends)."""
    th = np.asarray(theta, dtype=float)
    n, h = th.size, int(half_window)
    if n < 2:
        return np.zeros(n)
    if n <= 2 * h:
        i = np.arange(n)
        lo, hi = np.clip(i - h, 0, n - 1), np.clip(i + h, 0, n - 1)
        return (th[hi] - th[lo]) / ((hi - lo) * dt)
    out = np.empty(n)
    out[h:n - h] = (th[2 * h:] - th[:n - 2 * h]) / ((2 * h) * dt)       # the interior: slices, no index arrays
    e = np.arange(h)
    out[:h] = (th[e + h] - th[0]) / ((e + h) * dt)                      # one-sided at the ends
    out[n - h:] = (th[n - 1] - th[n - 2 * h + e]) / ((2 * h - 1 - e) * dt)
    return out


def first_reversal(theta: np.ndarray, dt: float, after: float = 0.5) -> int:
    """Index of the first reversal of the spindle angle ``theta`` [rad] after ``after`` [s] (samples of
    spacing ``dt`` [s]): where the smoothed rate (:func:`spindle_rate`) changes sign. The stroke
    before it is the estimator's initialisation (the cables reach full slip on a known branch, as the
    paper's calibration pull does); ``len(theta)`` when the spindle never reverses."""
    om = spindle_rate(theta, dt)
    k = int(round(after / dt))
    nz = np.flatnonzero(om[k:] != 0.0)          # the angle may stand still at a turning point
    s = np.sign(om[k:][nz])
    i = np.flatnonzero(s[1:] != s[:-1])
    return int(k + nz[i[0] + 1]) if i.size else int(len(theta))


def initial_side(tau_p0: float, centre: float) -> float:
    """+1 when the first spindle torque [N m] lies above ``centre`` [N m] (cable a last pulled), else -1."""
    return 1.0 if tau_p0 >= centre else -1.0


def make_batch(runs, centre: float, theta_ref: float, dt: float, step: int = 1) -> Batch:
    """Concatenate runs given as (tau_p [N m], theta_p [rad]) pairs, each decimated by ``step``.

    ``centre`` [N m] decides each run's initial branch (:func:`initial_side`); ``dt`` [s] is the
    sample spacing before decimation. Raises ValueError for an empty list or a run shorter than
    2 samples after decimation.
    """
    taus: list[np.ndarray] = []
    ths: list[np.ndarray] = []
    oms: list[np.ndarray] = []
    starts, side = [0], []
    for tau, th in runs:
        tau, th = np.asarray(tau, dtype=float), np.asarray(th, dtype=float)
        om = spindle_rate(th, dt)
        tau, th, om = tau[::step], th[::step], om[::step]
        if tau.size < 2:
            raise ValueError("every run needs at least 2 samples after decimation")
        taus.append(tau)
        ths.append(th)
        oms.append(om)
        starts.append(starts[-1] + tau.size)
        side.append(initial_side(float(tau[0]), centre))
    if not taus:
        raise ValueError("no runs to concatenate")
    return Batch(np.concatenate(taus), np.concatenate(ths), np.concatenate(oms),
                 np.asarray(starts, dtype=np.int64), np.asarray(side), float(theta_ref))


@njit(cache=True)
def pair_kernel(u, starts, side, Q, K_a, K_b, n_nodes, Td, dE):  # pragma: no cover - compiled
    """Both cables' profile memory over concatenated runs: Td = T_a,d - T_b,d, dE = E_a - E_b [N m]."""
    w = np.empty(n_nodes + 1)
    lo = np.empty(n_nodes + 1)
    hi = np.empty(n_nodes + 1)
    lob = np.empty(n_nodes + 1)
    hib = np.empty(n_nodes + 1)
    for j in range(n_nodes + 1):
        w[j] = 1.0 / n_nodes
        lo[j] = math.exp(-K_a * j / n_nodes)
        hi[j] = 1.0 / lo[j]
        lob[j] = math.exp(-K_b * j / n_nodes)
        hib[j] = 1.0 / lob[j]
    w[0] *= 0.5
    w[n_nodes] *= 0.5
    Ta = np.empty(n_nodes + 1)
    Tb = np.empty(n_nodes + 1)
    for r in range(starts.shape[0] - 1):
        i0 = starts[r]
        ta = max(0.5 * (Q + u[i0]), 0.0)
        tb = max(0.5 * (Q - u[i0]), 0.0)
        # full slip on the branch it last moved on: side > 0 (upper band edge) means the spindle
        # torque rose to it, cable a pulled from below and cable b released from above
        fa = lo[n_nodes] * lo[n_nodes] if side[r] > 0 else hi[n_nodes] * hi[n_nodes]
        fb = hib[n_nodes] * hib[n_nodes] if side[r] > 0 else lob[n_nodes] * lob[n_nodes]
        for j in range(n_nodes + 1):
            Ta[j] = min(max(ta * fa, ta * lo[j]), ta * hi[j])
            Tb[j] = min(max(tb * fb, tb * lob[j]), tb * hib[j])
        for i in range(i0, starts[r + 1]):
            ta = max(0.5 * (Q + u[i]), 0.0)
            tb = max(0.5 * (Q - u[i]), 0.0)
            ea = 0.0
            eb = 0.0
            for j in range(n_nodes + 1):         # each cable's profile memory (Phee et al. eq. (1) per node)
                Ta[j] = envelope_clip(Ta[j], ta * lo[j], ta * hi[j])
                ea += w[j] * Ta[j]
                Tb[j] = envelope_clip(Tb[j], tb * lob[j], tb * hib[j])
                eb += w[j] * Tb[j]
            Td[i] = Ta[n_nodes] - Tb[n_nodes]
            dE[i] = ea - eb


def _cables(p: SpindleParams, bt: Batch, n_nodes: int) -> tuple[np.ndarray, np.ndarray]:
    d = bt.theta_p - bt.theta_ref
    u = bt.tau_p - p.k_p * d - p.c_v * bt.omega_p
    if p.f_s != 0.0:
        u = u - p.f_s * angle_lag(np.tanh(bt.omega_p / OMEGA_S), bt.theta_p, bt.starts, max(p.theta_s, 1e-4))
    Td, dE = np.empty_like(u), np.empty_like(u)
    pair_kernel(np.ascontiguousarray(u), bt.starts, bt.side, float(p.Q), float(p.K_a), float(p.K_b), int(n_nodes),
                Td, dE)
    return Td, dE


def predict_torque(p: SpindleParams, bt: Batch, n_nodes: int = N_NODES) -> np.ndarray:
    """Distal torque [N m], shape (n,), of the spindle pair model (S1)-(S3) over a batch."""
    if not (p.Q > 0 and p.K_a >= 0 and p.K_b >= 0 and math.isfinite(p.Q + p.K_a + p.K_b)):
        raise ValueError(f"pretension torque Q must be > 0 and K_a, K_b >= 0, got Q={p.Q!r}, K={p.K_a!r}, {p.K_b!r}")
    Td, _ = _cables(p, bt, n_nodes)
    d = bt.theta_p - bt.theta_ref
    rho = p.rho * (1.0 + (p.rho_1 + p.rho_2 * d) * d)
    out = rho * Td + p.b + p.k_d * d - p.f * np.tanh(bt.omega_p / OMEGA_S)
    return angle_lag(out, bt.theta_p, bt.starts, p.theta_c) if p.theta_c > 1e-6 else out


def elongation_difference(p: SpindleParams, bt: Batch, n_nodes: int = N_NODES) -> np.ndarray:
    """E_a - E_b [N m], shape (n,): difference of the two cables' mean profile tensions (S4)."""
    return _cables(p, bt, n_nodes)[1]


@njit(cache=True)
def _angle_lag_runs(x, theta, starts, theta_c, out):  # pragma: no cover - compiled
    for r in range(starts.shape[0] - 1):
        y = x[starts[r]]
        prev = theta[starts[r]]
        for i in range(starts[r], starts[r + 1]):
            a = abs(theta[i] - prev) / theta_c
            prev = theta[i]
            y += (x[i] - y) * (1.0 - math.exp(-a))
            out[i] = y


def angle_lag(x: np.ndarray, theta: np.ndarray, starts: np.ndarray, theta_c: float) -> np.ndarray:
    """Rate-independent first-order lag of ``x`` in the travel of ``theta`` [rad], run by run:
    y approaches x by the factor 1 - exp(-|d theta| / theta_c) per sample (a Dahl-type pre-sliding
    transition, docs/concepts/effects.md E2, with characteristic travel ``theta_c`` [rad] > 0)."""
    out = np.empty_like(np.asarray(x, dtype=float))
    _angle_lag_runs(np.ascontiguousarray(x, dtype=float), np.ascontiguousarray(theta, dtype=float), starts,
                    float(theta_c), out)
    return out


@njit(cache=True)
def _play_runs(x, starts, beta, out):  # pragma: no cover - compiled
    for r in range(starts.shape[0] - 1):
        y = x[starts[r]]
        for i in range(starts[r], starts[r + 1]):
            if y < x[i] - beta:
                y = x[i] - beta
            elif y > x[i] + beta:
                y = x[i] + beta
            out[i] = y


def play_batch(x: np.ndarray, starts: np.ndarray, beta: float) -> np.ndarray:
    """Play (backlash) operator of half-width ``beta`` applied run by run, starting centred."""
    out = np.empty_like(np.asarray(x, dtype=float))
    _play_runs(np.ascontiguousarray(x, dtype=float), starts, float(max(beta, 0.0)), out)
    return out


def predict_angle(p: SpindleParams, bt: Batch, dE: np.ndarray | None = None, n_nodes: int = N_NODES) -> np.ndarray:
    """Jaw angle [rad], shape (n,), of (S4) with the E12 play; ``dE`` from
    :func:`elongation_difference` (computed when None)."""
    if dE is None:
        dE = elongation_difference(p, bt, n_nodes)
    th = p.n_k * (bt.theta_p - p.lam * dE) + p.theta0
    return play_batch(th, bt.starts, p.beta) if p.beta > 0 else th
