"""Jaw torque from the load level read off the spindle's friction band (the centre map).

On the MRD da Vinci runs (docs/results/mrd.md), across the runs of one tool the jaw torque at a given
spindle angle and direction follows the run's *band centre* (the middle of the spindle torque's
hysteresis band, a proximal reading) to
0.008 FS, while the instantaneous spindle torque on the band edge follows it only to 0.020 FS: inside
a stroke the spindle torque drifts with friction that never reaches the jaw. The capstan law on the
load-carrying cable with tension-independent friction (docs/concepts/effects.md E1, E8) puts the band edges at
c(theta) +- F0 + r e^(+-K) tau_d, so the centre moves as r cosh(K) tau_d: the load level is read from
the centre and the shape along the stroke from the angle. The estimate::

    C_hat(t)  = centre of the band from the last completed stroke of each direction (SC1)
    z(t)      = angle_lag(tanh(omega_p / OMEGA_S), theta_p, theta_z)           direction state (E2)
    tau_d     = sum_k d^k (a_k + b_k C_hat + z (c_k + e_k C_hat)),   d = theta_p - theta_ref    (SC2)

(SC1) per stroke (between two reversals of the spindle): the running mean spindle torque over the
samples in full motion (|omega_p| > MIN_RATE) inside the angle window [lo, hi], used once it holds
MIN_SAMPLES samples (until then the previous stroke of that direction); the centre is the mean of the
latest falling-angle (high edge) and rising-angle (low edge) means. While only one direction has been
seen, the centre is that edge minus (high edge) or plus (low edge) the half-width w0 + w1 C of the
calibration (solved for C); before any completed stroke it is the calibration's mean centre. The
estimate is in its initialisation until the reading holds both edges (:func:`centre_ready`): fits and
scores start there (docs/results/mrd.md: the one-edge reading right after the first stroke from
rest is the centre map's largest error).
Inputs: spindle torque tau_p [N m] and angle theta_p [rad] only.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from estimator.online.spindle import OMEGA_S, angle_lag, spindle_rate

__all__ = ["CentreParams", "MIN_RATE", "MIN_SAMPLES", "stroke_starts", "stroke_centre", "centre_ready",
           "direction_state", "centre_features", "predict_centre_map"]

#: Spindle speed above which a sample is in full motion (on a band edge) [rad/s].
MIN_RATE = 0.05
#: Samples in full motion inside the window before a stroke's running mean replaces the last edge.
MIN_SAMPLES = 200


@dataclass(frozen=True)
class CentreParams:
    """Centre-map parameters (module docstring; SI units).

    coef: (4, deg + 1) rows a, b, c, e of (SC2) [N m, -, N m, -] per power of d [rad^-k];
    theta_ref [rad]; theta_z [rad] direction-state travel; window (lo, hi) [rad] of (SC1);
    half_width (w0 [N m], w1 [-]); centre0 [N m] the fallback centre; edge_slope (high, low) [N m/rad].
    """

    coef: np.ndarray
    theta_ref: float
    theta_z: float
    window: tuple[float, float]
    half_width: tuple[float, float]
    centre0: float
    edge_slope: tuple[float, float] = (0.0, 0.0)
    notes: dict = field(default_factory=dict)

    def as_dict(self) -> dict:
        return {"coef_a_b_c_e": [[float(v) for v in row] for row in self.coef], "theta_ref": self.theta_ref,
                "theta_z": self.theta_z, "window": list(self.window), "half_width": list(self.half_width),
                "centre0": self.centre0, "edge_slope": list(self.edge_slope), **self.notes}


def stroke_starts(omega: np.ndarray) -> np.ndarray:
    """Indices where the sign of the (nonzero) spindle rate changes; the first index of each new stroke."""
    nz = np.flatnonzero(omega != 0.0)
    if nz.size < 2:
        return np.zeros(0, dtype=int)
    s = np.sign(omega[nz])
    return nz[np.flatnonzero(s[1:] != s[:-1]) + 1]


def stroke_centre(tau_p: np.ndarray, theta_p: np.ndarray, dt: float, window: tuple[float, float],
                  half_width: tuple[float, float], centre0: float, edge_slope: tuple[float, float] = (0.0, 0.0),
                  theta_ref: float = 0.0) -> np.ndarray:
    """(SC1) causal band centre [N m], shape (n,), of one run (tau_p [N m], theta_p [rad], spacing dt [s]).

    ``edge_slope`` (high, low) [N m/rad]: the edges' slope along the stroke, taken out before averaging
    (tau_p - slope (theta_p - theta_ref)) so that part of a stroke reads the same centre as all of it.
    Causal up to the +-25 ms of the rate's central difference. Raises ValueError for shapes that differ
    or a half-width slope |w1| >= 1."""
    tau, th = np.asarray(tau_p, dtype=float), np.asarray(theta_p, dtype=float)
    if tau.shape != th.shape or tau.ndim != 1:
        raise ValueError(f"stroke_centre: tau_p {tau.shape} and theta_p {th.shape} must be equal 1-d shapes")
    w0, w1 = half_width
    if abs(w1) >= 1.0:
        raise ValueError(f"stroke_centre: half-width slope w1 = {w1} must be below 1 in magnitude")
    om = spindle_rate(th, dt)
    cuts = np.concatenate([[0], stroke_starts(om), [th.size]])
    inside = (th >= window[0]) & (th <= window[1]) & (np.abs(om) > MIN_RATE)
    edge = np.full((2, th.size), np.nan)            # row 0: high edge (falling angle), row 1: low edge
    last = [np.nan, np.nan]
    flat = [tau - edge_slope[0] * (th - theta_ref), tau - edge_slope[1] * (th - theta_ref)]
    for a, b in zip(cuts[:-1], cuts[1:], strict=False):
        m = inside[a:b]
        j = 0 if np.mean(om[a:b]) < 0 else 1
        edge[:, a:b] = np.array(last)[:, None]
        n = np.cumsum(m)
        if n[-1] >= MIN_SAMPLES:
            part = np.cumsum(np.where(m, flat[j][a:b], 0.0)) / np.maximum(n, 1)
            ok = n >= MIN_SAMPLES                   # the stroke under way, once it has crossed enough window
            edge[j, a:b][ok] = part[ok]
            last[j] = float(part[-1])
    hi, lo = edge
    out = np.where(np.isnan(hi), (lo + w0) / (1.0 - w1),
                   np.where(np.isnan(lo), (hi - w0) / (1.0 + w1), 0.5 * (hi + lo)))
    return np.where(np.isnan(out), float(centre0), out)


def centre_ready(theta_p: np.ndarray, dt: float, window: tuple[float, float]) -> int:
    """First sample index at which (SC1) reads both band edges, each from a stroke with MIN_SAMPLES samples
    in full motion inside ``window`` [rad] (theta_p [rad], shape (n,); spacing dt [s]); n when it never does.

    Before it the centre rests on one edge and the calibration's half-width (or on centre0): the estimator
    is still initialising, the way the first stroke initialises the pair model. Spindle angle only."""
    th = np.asarray(theta_p, dtype=float)
    om = spindle_rate(th, dt)
    cuts = np.concatenate([[0], stroke_starts(om), [th.size]])
    inside = (th >= window[0]) & (th <= window[1]) & (np.abs(om) > MIN_RATE)
    seen = [th.size, th.size]
    for a, b in zip(cuts[:-1], cuts[1:], strict=False):
        j = 0 if np.mean(om[a:b]) < 0 else 1
        n = np.cumsum(inside[a:b])
        if seen[j] == th.size and n.size and n[-1] >= MIN_SAMPLES:
            seen[j] = int(a + np.argmax(n >= MIN_SAMPLES))
    return max(seen)


def direction_state(theta_p: np.ndarray, dt: float, theta_z: float) -> np.ndarray:
    """z in [-1, 1], shape (n,): the direction of motion lagged over a spindle travel theta_z [rad] (E2)."""
    th = np.asarray(theta_p, dtype=float)
    z = np.tanh(spindle_rate(th, dt) / OMEGA_S)
    return angle_lag(z, th, np.array([0, th.size], dtype=np.int64), max(float(theta_z), 1e-4))


def centre_features(theta_p: np.ndarray, centre: np.ndarray, z: np.ndarray, theta_ref: float, deg: int) -> np.ndarray:
    """Design matrix (n, 4 (deg + 1)) of (SC2): columns d^k, C d^k, z d^k, z C d^k."""
    d = np.asarray(theta_p, dtype=float) - theta_ref
    P = np.column_stack([d ** k for k in range(deg + 1)])
    return np.hstack([P, centre[:, None] * P, z[:, None] * P, (z * centre)[:, None] * P])


def predict_centre_map(p: CentreParams, tau_p: np.ndarray, theta_p: np.ndarray, dt: float) -> np.ndarray:
    """Jaw torque [N m], shape (n,), of one run from its spindle torque [N m] and angle [rad] (SC1, SC2)."""
    c = stroke_centre(tau_p, theta_p, dt, p.window, p.half_width, p.centre0, p.edge_slope, p.theta_ref)
    z = direction_state(theta_p, dt, p.theta_z)
    X = centre_features(theta_p, c, z, p.theta_ref, p.coef.shape[1] - 1)
    return X @ np.asarray(p.coef, dtype=float).ravel()
