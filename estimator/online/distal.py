"""Distal tension and elongation from proximal sensors: the profile-memory estimator.

State: the tension profile T(s) along the sheath, n_nodes + 1 nodes from proximal to distal. Each
proximal tension sample updates it by the envelope rule of :mod:`estimator.sheath`

    T_i <- min( max(T_i, T_in e^{-mu theta_i}), T_in e^{+mu theta_i} )

and gives

    T_out_hat      = T_n                                     distal tension [N]
    elongation_hat = (1/EA) int_0^L T(s) ds  (trapezoid)     tendon elongation [m]
    x_out_hat      = x_in - elongation_hat                   distal displacement [m]

For a single reversal from full slip this reproduces the seed paper's phase laws (Phee et al. 2009,
eqs. (1)-(25)); for any other history (minor loops, partial releases) it keeps the exact Coulomb
memory that the "tension at the last reversal" rule loses (docs/concepts/model.md, the tension-profile memory).

With ``tension_noise`` (the standard deviation of the T_in reading, > 0) the profile takes the banded update of
:func:`estimator.band.band_update` instead: a stuck profile moves only for what exceeds NOISE_BAND_SIGMAS x the
noise, and a whole-tendon slide follows T_in exactly, so the estimate no longer latches the noise's extremes. The
proximal velocity it needs is the derivative of x_in smoothed over ``rate_time_constant``.

The phase reported is the readable one of :mod:`estimator.phase` (a change needs T_in to move past
``phase_band``, default 0.2 N = 10 load-cell noise sigmas): the direction from T_in's turns past the
band, slip from the distal node sitting on the slip line of the last extreme. ``phase_band=0`` gives
the sample-to-sample classifier on the smoothed rate of T_in (:func:`classify_phase`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from estimator.band import NOISE_BAND_SIGMAS, band_batch, band_update
from estimator.phase import Phase
from estimator.readable_phase import new_phase_state, readable_step
from estimator.sheath import SheathModel, profile_batch, profile_update

__all__ = ["DistalEstimator", "DistalSample", "BatchEstimate", "estimate_batch", "classify_phase", "smoothed_velocity",
           "velocity_step"]


@dataclass(frozen=True)
class DistalSample:
    """One estimate. T_out [N], elongation [m], x_out [m], phase."""

    T_out: float
    elongation: float
    x_out: float
    phase: Phase


@dataclass(frozen=True)
class BatchEstimate:
    """Estimates over a recording, each ndarray of shape (n_samples,): T_out [N], elongation [m],
    x_out [m], phase (int8 codes of :class:`Phase`)."""

    T_out: np.ndarray
    elongation: np.ndarray
    x_out: np.ndarray
    phase: np.ndarray


class DistalEstimator:
    """Online profile-memory estimator for one tendon.

    Parameters
    ----------
    model : SheathModel
        K, L/EA and (optionally) the route shape, e.g. from calibration.
    n_nodes : int
        Elements of the profile (n_nodes + 1 nodes), >= 1.
    pretension : float
        Initial uniform tension along the tendon [N], >= 0.
    hold_rate : float
        |dT_in/dt| below this is reported as HOLD when the distal end is stuck [N/s].
    rate_time_constant : float
        Time constant of the first-order smoothing of dT_in/dt [s], > 0.
    phase_band : float
        Noise band of the readable phase [N], >= 0 (module docstring; 0: the rate classifier).
    tension_noise : float
        Standard deviation of the T_in reading [N], >= 0: > 0 runs the banded update (module docstring;
        e.g. :func:`estimator.data.noise_level` of a calibration's T_in); 0 (default): the envelope rule.
    released_slack : bool
        The tendon is slack when released to near zero tension (one of an antagonistic pair): the banded update's
        release side has no band there (:func:`estimator.band.band_update`, ``slack``). Default False.

    Raises
    ------
    ValueError
        Non-finite or out-of-range arguments (named in the message).
    """

    def __init__(self, model: SheathModel, n_nodes: int = 100, pretension: float = 0.0,
                 hold_rate: float = 0.5, rate_time_constant: float = 0.02, phase_band: float = 0.2,
                 tension_noise: float = 0.0, released_slack: bool = False):
        if not (pretension >= 0 and math.isfinite(pretension)):
            raise ValueError(f"pretension must be >= 0 N, got {pretension!r}")
        if not (rate_time_constant > 0):
            raise ValueError(f"rate_time_constant must be > 0 s, got {rate_time_constant!r}")
        self.model = model
        self.log_gain, self.weight = model.nodes(int(n_nodes))
        self.positions = np.linspace(0.0, 1.0, self.log_gain.size)  # normalised arc length s/L
        self.hold_rate = float(hold_rate)
        self.tau = float(rate_time_constant)
        if not (math.isfinite(phase_band) and phase_band >= 0):
            raise ValueError(f"phase_band must be >= 0 N, got {phase_band!r}")
        self.phase_band = float(phase_band)
        if not (math.isfinite(tension_noise) and tension_noise >= 0):
            raise ValueError(f"tension_noise must be >= 0 N, got {tension_noise!r}")
        self.tension_noise = float(tension_noise)
        self.band = NOISE_BAND_SIGMAS * self.tension_noise
        self.released_slack = bool(released_slack)
        self._hi_gain = np.exp(self.log_gain)
        self._lo_gain = 1.0 / self._hi_gain
        self.reset(pretension)

    def reset(self, pretension: float = 0.0) -> None:
        """Forget the history: uniform profile at ``pretension`` [N], phase HOLD."""
        self.profile = np.full(self.log_gain.size, float(pretension))
        self._T_prev: float | None = None
        self._t_prev: float | None = None
        self._rate = 0.0
        self.phase = Phase.HOLD
        self._phase_state = new_phase_state(float(pretension))
        self.T_out = float(pretension)
        self.elongation = float(self.weight @ self.profile)
        self._slide = np.zeros(2)        # the banded update's slide: direction and extreme of T_in
        self._x_prev: float | None = None
        self.velocity = 0.0              # smoothed proximal velocity [m/s]

    def step(self, T_in: float, x_in: float, t: float | None = None) -> DistalSample:
        """Update with one proximal sample.

        Parameters
        ----------
        T_in : float
            Proximal tension [N]; negative readings are treated as 0.
        x_in : float
            Proximal displacement [m] (encoder).
        t : float, optional
            Sample time [s] for the phase rate; without it a 1 ms period is assumed.

        Raises
        ------
        ValueError
            ``T_in`` or ``x_in`` is not finite.
        """
        if not (math.isfinite(T_in) and math.isfinite(x_in)):
            raise ValueError(f"proximal sample must be finite, got T_in={T_in!r} N, x_in={x_in!r} m")
        T_prev_out = self.T_out
        dt = 1e-3 if t is None or self._t_prev is None else max(t - self._t_prev, 1e-6)
        if self._x_prev is not None:
            self.velocity = velocity_step(self.velocity, x_in, self._x_prev, dt, self.tau)
        self._x_prev = x_in
        # profile update (envelope rule, or the banded one); T_out is the distal node
        if self.tension_noise > 0.0:
            self.T_out = T_out = band_update(self.profile, self._lo_gain, self._hi_gain, T_in, self.velocity,
                                             self.band, self.tension_noise, self._slide, self.released_slack)
        else:
            self.T_out = T_out = profile_update(self.profile, self.log_gain, T_in)
        # elongation = (1/EA) int T ds
        self.elongation = e = float(self.weight @ self.profile)
        if self._T_prev is not None:
            a = dt / (self.tau + dt)
            self._rate += a * ((T_in - self._T_prev) / dt - self._rate)
        if self.phase_band > 0:
            if self._T_prev is None:
                self._phase_state = new_phase_state(T_in, 0.0 if t is None else t)
            tk = (t if t is not None else (self._t_prev or 0.0) + 1e-3)
            self.phase = Phase(readable_step(self._phase_state, max(T_in, 0.0), T_out, tk, self.model.K,
                                             self.phase_band, self.hold_rate))
        else:
            self.phase = classify_phase(T_out - T_prev_out, T_in, self.model.K, T_out, self._rate, self.hold_rate)
        self._T_prev, self._t_prev = T_in, (t if t is not None else (self._t_prev or 0.0) + 1e-3)
        return DistalSample(T_out, e, x_in - e, self.phase)

    def end_slide(self) -> None:
        """End a whole-tendon slide of the banded update (a pair coupling that moved the distal end takes it over)."""
        self._slide[0] = 0.0

    def replay(self, time: np.ndarray, x_in: np.ndarray, T_in: np.ndarray) -> None:
        """Carry the profile through a recorded proximal history (compiled; e.g. a calibration routine), from
        the present state: the profile, the slide and the smoothed velocity end where :meth:`step` over the
        same samples would leave them (the phase and T_in's rate are not updated).

        time [s], x_in [m], T_in [N]: arrays of shape (n,). Raises ValueError: shapes differ or a value is
        not finite."""
        t, x, T = (np.asarray(a, dtype=float) for a in (time, x_in, T_in))
        if not (t.shape == x.shape == T.shape and t.ndim == 1):
            raise ValueError(f"replay: time, x_in and T_in must be 1-D of equal length, got {t.shape}, {x.shape}, "
                             f"{T.shape}")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(x)) and np.all(np.isfinite(T))):
            raise ValueError("replay: a sample is not finite")
        if t.size == 0:
            return
        v = smoothed_velocity(t, x, self.tau, self.velocity, self._x_prev, self._t_prev)
        if self.tension_noise > 0.0:
            _, _, self.profile, s = band_batch(self.profile, self.log_gain, self.weight, T, v, self.band,
                                               self.tension_noise, (float(self._slide[0]), float(self._slide[1])),
                                               self.released_slack)
            self._slide[:] = s
        else:
            _, _, self.profile = profile_batch(self.profile, self.log_gain, self.weight, T)
        self.velocity, self._x_prev, self._t_prev = float(v[-1]), float(x[-1]), float(t[-1])
        self.T_out = float(self.profile[-1])
        self.elongation = float(self.weight @ self.profile)

    def profile_samples(self, n_points: int) -> np.ndarray:
        """The profile resampled at ``n_points`` equally spaced points, proximal to distal [N]."""
        u = np.linspace(0.0, 1.0, n_points)
        return np.interp(u, self.positions, self.profile)


def classify_phase(dT_out: float, T_in: float, K: float, T_out: float, rate: float, hold_rate: float) -> Phase:
    """Phase from the distal node's motion and the smoothed proximal rate [N/s].

    The distal end slips while T_out sits on the pull line T_in e^-K or the release line T_in e^K
    (within 0.5 % + 1 mN) and T_in moves that way; otherwise it is stuck and the sign of the rate
    tells the transition. ``dT_out`` is kept in the signature for callers that log it.
    """
    return Phase(_classify(dT_out, T_in, K, T_out, rate, hold_rate))


@njit(cache=True)
def _classify(dT_out, T_in, K, T_out, rate, hold_rate):  # pragma: no cover - compiled
    tol = 0.005 * T_out + 1e-3
    if rate > hold_rate:
        if abs(T_out - T_in * math.exp(-K)) <= tol:
            return 1  # PULL
        return 4      # RELEASE_TO_PULL
    if rate < -hold_rate:
        if abs(T_out - T_in * math.exp(K)) <= tol:
            return 2  # RELEASE
        return 3      # PULL_TO_RELEASE
    return 0          # HOLD


@njit(cache=True)
def _readable_batch(T_in, T_out, t, K, band, hold_rate, out):  # pragma: no cover - compiled
    state = np.array([0.0, max(T_in[0], 0.0), max(T_in[0], 0.0), t[0], 0.0])
    for k in range(T_in.shape[0]):
        out[k] = readable_step(state, max(T_in[k], 0.0), T_out[k], t[k], K, band, hold_rate)


@njit(cache=True)
def _phase_batch(T_in, T_out, t, K, tau, hold_rate, out):  # pragma: no cover - compiled
    rate = 0.0
    out[0] = 0
    for k in range(1, T_in.shape[0]):
        dt = t[k] - t[k - 1]
        if dt < 1e-6:
            dt = 1e-6
        a = dt / (tau + dt)
        rate += a * ((T_in[k] - T_in[k - 1]) / dt - rate)
        out[k] = _classify(T_out[k] - T_out[k - 1], max(T_in[k], 0.0), K, T_out[k], rate, hold_rate)


def smoothed_velocity(time: np.ndarray, x_in: np.ndarray, tau: float, v0: float = 0.0, x0: float | None = None,
                      t0: float | None = None) -> np.ndarray:
    """The proximal velocity [m/s], shape (n,), that :class:`DistalEstimator` uses: the backward difference of
    ``x_in`` [m] smoothed by a first-order filter of time constant ``tau`` [s] > 0, from the velocity ``v0``
    after a previous sample (x0, t0) (None: none; the first sample keeps v0). ``time`` [s], shape (n,)."""
    t = np.ascontiguousarray(time, dtype=float)
    x = np.ascontiguousarray(x_in, dtype=float)
    out = np.empty_like(x)
    _smooth(t, x, float(tau), float(v0), np.nan if x0 is None else float(x0), np.nan if t0 is None else float(t0),
            out)
    return out


@njit(cache=True, nogil=True)
def velocity_step(v, x, x_prev, dt, tau):  # pragma: no cover - compiled
    """The smoothed proximal velocity [m/s] after one more sample: the backward difference (x - x_prev) / dt [m/s]
    through a first-order filter of time constant ``tau`` [s] from ``v``; the one formula of the live step, the
    batch and the compiled pair step."""
    return v + dt / (tau + dt) * ((x - x_prev) / dt - v)


@njit(cache=True)
def _smooth(t, x, tau, v, x0, t0, out):  # pragma: no cover - compiled
    xp, tp = x0, t0
    for k in range(x.shape[0]):
        if not math.isnan(xp):
            v = velocity_step(v, x[k], xp, 1e-3 if math.isnan(tp) else max(t[k] - tp, 1e-6), tau)
        xp, tp = x[k], t[k]
        out[k] = v


def estimate_batch(T_in: np.ndarray, x_in: np.ndarray, model: SheathModel, *, time: np.ndarray | None = None,
                   n_nodes: int = 100, pretension: float = 0.0, hold_rate: float = 0.5,
                   rate_time_constant: float = 0.02, phase_band: float = 0.2,
                   tension_noise: float = 0.0) -> BatchEstimate:
    """Profile-memory estimates over recorded arrays (the same maths as :class:`DistalEstimator`).

    Parameters
    ----------
    T_in : ndarray, shape (n,)   proximal tension [N]
    x_in : ndarray, shape (n,)   proximal displacement [m]
    model : SheathModel
    time : ndarray, shape (n,), optional   sample times [s] (default 1 kHz) for the phase
    n_nodes, pretension, hold_rate, rate_time_constant, phase_band, tension_noise : as :class:`DistalEstimator`

    Raises
    ------
    ValueError
        Arrays of different shapes, not 1-D, or with NaN/inf (the first bad index is named); ``tension_noise``
        negative or not finite.
    """
    T_in = np.asarray(T_in, dtype=float)
    x_in = np.asarray(x_in, dtype=float)
    if T_in.ndim != 1 or T_in.shape != x_in.shape:
        raise ValueError(f"T_in and x_in must be 1-D of equal length, got shapes {T_in.shape} and {x_in.shape}")
    for name, arr in (("T_in", T_in), ("x_in", x_in)):
        bad = np.flatnonzero(~np.isfinite(arr))
        if bad.size:
            raise ValueError(f"{name} has a non-finite value at sample {bad[0]}")
    if time is None:
        time = np.arange(T_in.size) * 1e-3
    log_gain, weight = model.nodes(int(n_nodes))
    T0 = np.full(log_gain.size, float(pretension))
    if not (math.isfinite(tension_noise) and tension_noise >= 0):
        raise ValueError(f"tension_noise must be >= 0 N, got {tension_noise!r}")
    if tension_noise > 0.0:
        v = smoothed_velocity(np.asarray(time, dtype=float), x_in, rate_time_constant)
        T_out, elong, _, _ = band_batch(T0, log_gain, weight, T_in, v, NOISE_BAND_SIGMAS * tension_noise,
                                        tension_noise)
    else:
        T_out, elong, _ = profile_batch(T0, log_gain, weight, T_in)
    phase = np.empty(T_in.size, dtype=np.int8)
    if T_in.size and phase_band > 0:
        _readable_batch(T_in, T_out, np.asarray(time, dtype=float), model.K, float(phase_band), float(hold_rate), phase)
    elif T_in.size:
        _phase_batch(T_in, T_out, np.asarray(time, dtype=float), model.K, float(rate_time_constant),
                     float(hold_rate), phase)
    return BatchEstimate(T_out=T_out, elongation=elong, x_out=x_in - elong, phase=phase)
