"""The extended single-tendon model of the offline diagnosis, one sample at a time: what it fits, run in the live loop.

:class:`ExtendedEstimator` runs the profile-memory model extended by the catalogue's effects
(``estimator.offline.effects.catalogue``) causally: each :meth:`~ExtendedEstimator.step` takes the proximal
readings T_in [N], x_in [m] and the time t [s] and returns the distal tension and elongation. Per sample:

1. the proximal sensors' corrections (the model runs on the true inputs), as the batch model's:
   T = (T_in - b_T) / (1 + g_T) - d_T (t - t_0),  x = x_in - b_x,  t_0 the first step's time;
2. with ``average`` n > 1, T the mean of the last n corrected readings and the proximal velocity v the slope of x
   across them (the fit's block mean at its sample rate, run causally: n = the live rate / the fit's rate); with
   n = 1 each reading as it is and v the backward difference of x smoothed over ``rate_time_constant``
   (:func:`estimator.online.distal.velocity_step`, the base estimator's); the sliding speed |v| (or, with
   ``velocity_form`` 1, the mean of |v| and the speed of the estimate's own distal end);
3. one sample of the compiled loop of the batch model (:func:`estimator.extended_loop.run_span`) on the kept
   profile: friction exponent (K + K_rate (t - t_0) + dK [t - t_0 >= t_s]) (1 + c_v speed), static friction r_s
   (breakaway or Stribeck form), the tension-independent friction a, the pretension T0, the stiffening strain phi
   (beta, T_c);
4. the lumped pre-sliding (a Dahl lag of the friction T - T_out in proximal travel, x_p), the elongation
   (L/EA) E1 and the distal end x - (L/EA) E1 through the distal backlash's play (d_b).

Over a recording, with the same inputs (the corrected T_in, the velocities of step 2), the outputs are the batch
model's (``estimator.offline.effects.kernels.run_extended``, ``travel_lag``, ``backlash_play``) to the last bit.
What the batch prediction has and the per-cycle form does not: the rule that a measured distal end seen moving
starts a whole-tendon slide (no distal measurement live: off), the pretension's cap by the distal rest reading
(the profile starts uniform at T0), the slack rule's hold of the distal end (it reads T_in after the sample), the
distal sensors' reading models (the live estimate is the true distal value).

:data:`PER_CYCLE` says for every single-tendon catalogue entry how it runs per cycle, or why it does not.
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from typing import NamedTuple

import numpy as np
from numba import njit

from estimator.band import NOISE_BAND_SIGMAS
from estimator.extended_loop import (
    N_PAR,
    N_ST,
    P_A,
    P_BAND,
    P_BETA,
    P_C_V,
    P_K,
    P_K_RATE,
    P_K_STEP,
    P_R_S,
    P_SIGMA,
    P_T0,
    P_T_MIN,
    P_T_SLIP,
    P_T_STEP,
    P_TC,
    P_V_ST,
    S_SLIDING,
    S_T_ORIGIN,
    friction_bounds,
    run_span,
    start_extended,
)
from estimator.online.distal import velocity_step
from estimator.online.friction_observer import FrictionObserver, FrictionTracker

__all__ = ["PER_CYCLE", "TRACKED", "PARAMETERS", "T_SLIP", "ExtendedSample", "ExtendedEstimator"]

_DISTAL_READING = ("a reading model of the distal {what}: it says what the bench's distal sensor read, not what the "
                   "tendon does; the live loop has no distal sensor and estimates the true distal value")
_FUTURE = ("undoing the lag of a proximal channel reads it tau ahead of the present sample (the future), which a "
           "per-cycle estimator cannot")

#: For every single-tendon catalogue entry (the ids of ``estimator.offline.effects.catalogue.CATALOGUE``):
#: (has a per-cycle form, how it runs per cycle or why it does not).
PER_CYCLE: dict[str, tuple[bool, str]] = {
    "velocity_friction": (True, "K (1 + c_v v) in the compiled sample loop, v the smoothed proximal speed; the "
                                "form on the mean of the proximal and distal speeds takes the speed of the estimate's "
                                "own distal end (the measured one is not there live)"),
    "pretension": (True, "the initial profile, uniform at T0 (the batch caps it by the distal rest reading, which the "
                         "live loop does not have)"),
    "curvature_drift": (True, "tracked online: K from the proximal loop's width, one estimate per branch of full slip "
                              "(estimator.online.friction_observer), drifting at the fitted K_rate from the last "
                              "estimate on"),
    "friction_step": (True, "tracked online: K from the proximal loop's width, one estimate per branch of full slip "
                            "(estimator.online.friction_observer), so a sheath reshaped at any instant of the session "
                            "is followed; the fitted instant t_s is not replayed"),
    "tendon_stiffening": (True, "phi(T) in the elongation sum of the compiled sample loop"),
    "stiction": (True, "the static bound and its breakaway (or the Stribeck form) in the compiled sample loop"),
    "friction_offset": (True, "the capstan law on T + a in the compiled sample loop"),
    "presliding": (True, "the lumped form: the friction lagged in proximal travel, its state kept between steps; "
                         "the per-node form drives the distal end by the measured x_out and has none"),
    "distal_backlash": (True, "a play operator on the estimated distal end, its output kept between steps"),
    "sensor_offset:T_in": (True, "T_in - b corrected before the sample loop"),
    "sensor_gain:T_in": (True, "T_in / (1 + g) corrected before the sample loop"),
    "sensor_drift:T_in": (True, "T_in - d (t - t_0) corrected before the sample loop, t_0 the first step"),
    "sensor_offset:x_in": (True, "x_in - b corrected before the distal end is computed"),
    "sensor_lag:T_in": (False, _FUTURE),
    "sensor_lag:x_in": (False, _FUTURE),
    "sensor_offset:T_out": (False, _DISTAL_READING.format(what="load cell")),
    "sensor_gain:T_out": (False, _DISTAL_READING.format(what="load cell")
                          + " (the data cannot tell it from sensor_gain:T_in, which has one)"),
    "sensor_drift:T_out": (False, _DISTAL_READING.format(what="load cell")),
    "sensor_lag:T_out": (False, _DISTAL_READING.format(what="load cell")),
    "sensor_offset:x_out": (False, _DISTAL_READING.format(what="position sensor")
                            + " (the data cannot tell it from sensor_offset:x_in, which has one)"),
    "sensor_lag:x_out": (False, _DISTAL_READING.format(what="position sensor")),
}

#: The entries whose per-cycle form tracks the friction online (``ExtendedEstimator(track_friction=True)``): friction
#: that changes during the recording changes in the session too, at its own instants and rates.
TRACKED = ("curvature_drift", "friction_step")

#: The parameters :class:`ExtendedEstimator` runs, by the catalogue's names (SI units), with their neutral values:
#: K [-], T0 [N], c_v [s/m], velocity_form (0 proximal speed, 1 the mean with the distal one), K_rate [1/s],
#: beta [-], T_c [N], r_s [-], v_st [m/s] (the Stribeck speed; 0: the breakaway form), a [N], x_p [m] (0: off),
#: d_b [m], b_T_in [N], g_T_in [-], d_T_in [N/s], b_x_in [m], the friction step dK [-] at t_s [s] after the first step.
PARAMETERS: dict[str, float] = {"K": math.nan, "T0": 0.0, "c_v": 0.0, "velocity_form": 0.0, "K_rate": 0.0,
                                "beta": 0.0, "T_c": 1.0, "r_s": 0.0, "v_st": 0.0, "a": 0.0, "x_p": 0.0, "d_b": 0.0,
                                "b_T_in": 0.0, "g_T_in": 0.0, "d_T_in": 0.0, "b_x_in": 0.0, "dK": 0.0, "t_s": 0.0}
#: a sensor parameter's prefix -> the kind of its catalogue entry (sensor_<kind>:<channel>)
_KIND = {"b": "offset", "g": "gain", "d": "drift", "tau": "lag"}
#: the largest friction exponent the tracked friction takes [-] (the fits' bound, ``K_MAX`` of the offline models)
_K_MAX = 5.0
#: relaxation time of static friction after a breakaway [s] (the batch kernel's)
T_SLIP = 0.02

# indices of the per-cycle parameters ``q`` and of the per-cycle state ``o``
_Q_B_T, _Q_G_T, _Q_D_T, _Q_B_X, _Q_X_P, _Q_D_B, _Q_C, _Q_TAU, _Q_SPEED = range(9)
_O_STEPS, _O_T0, _O_V, _O_X_PREV, _O_T_PREV, _O_V_OUT, _O_XO_PREV, _O_LAG, _O_PLAY = range(9)


class ExtendedSample(NamedTuple):
    """One step's output: distal tension T_out [N], elongation [m], distal end x_out [m], the largest friction
    exponent K_now [-] of the step (drift, speed and static friction included: K (1 + c_v v) (1 + r_s)) and the
    corrected proximal tension T_in [N]."""

    T_out: float
    elongation: float
    x_out: float
    K_now: float
    T_in: float


@njit(cache=True, nogil=True)
def _step(T_raw, x_raw, t, q, par, u, w, Y, st, tab, dY, G, io, slide, one_T, one_E, o, ring,
          out):  # pragma: no cover - compiled
    """One sample (module docstring, steps 1-4) on the kept state; writes ``out`` = (T_out, elongation, x_out,
    K_now, T_in)."""
    first = o[_O_STEPS] == 0.0
    if first:
        o[_O_T0] = t
    T = (T_raw - q[_Q_B_T]) / (1.0 + q[_Q_G_T]) - q[_Q_D_T] * (t - o[_O_T0])
    x = x_raw - q[_Q_B_X]
    dt = 1e-3
    if not first:
        dt = max(t - o[_O_T_PREV], 1e-6)
    n = ring.shape[1]
    if n > 1:                       # the mean of T over the window, the slope of x across it
        k = int(o[_O_STEPS])
        j = k % n
        ring[0, j], ring[1, j], ring[2, j] = T, x, t
        m = min(k + 1, n)
        acc = 0.0
        for i in range(m):
            acc += ring[0, i]
        T = acc / m
        old = (j + 1) % n if k + 1 >= n else 0
        o[_O_V] = 0.0 if m == 1 else (x - ring[1, old]) / max(t - ring[2, old], 1e-6)
    elif not first:
        o[_O_V] = velocity_step(o[_O_V], x, o[_O_X_PREV], dt, q[_Q_TAU])
    v = o[_O_V]
    spd = abs(v)
    if q[_Q_SPEED] > 0.5:
        spd = 0.5 * (abs(v) + abs(o[_O_V_OUT]))
    io[0, 0] = T
    io[1, 0] = v
    io[2, 0] = spd
    io[3, 0] = t
    run_span(io[0], io[1], io[2], io[3], slide, 0, 1, u, w, par, Y, st, tab, dY, G, one_T, one_E)
    T_out = one_T[0]
    E1 = one_E[0]
    x_p = q[_Q_X_P]
    if x_p > 0.0:                   # lumped pre-sliding: the friction lagged in proximal travel
        F = T - T_out
        y = F if first else F + (o[_O_LAG] - F) * math.exp(-abs(x - o[_O_X_PREV]) / x_p)
        o[_O_LAG] = y
        T_out = T - y
    c = q[_Q_C]
    x_out = x - c * E1
    half = 0.5 * q[_Q_D_B]
    if half > 0.0:                  # the distal backlash's play, from mid-gap at the first step
        p = x_out if first else o[_O_PLAY]
        if x_out - p > half:
            p = x_out - half
        elif p - x_out > half:
            p = x_out + half
        o[_O_PLAY] = p
        x_out = p
    if not first:
        o[_O_V_OUT] = velocity_step(o[_O_V_OUT], x_out, o[_O_XO_PREV], dt, q[_Q_TAU])
    o[_O_XO_PREV] = x_out
    o[_O_X_PREV] = x
    o[_O_T_PREV] = t
    o[_O_STEPS] += 1.0
    Kk = par[P_K] + par[P_K_RATE] * (t - o[_O_T0])
    if t - o[_O_T0] >= par[P_T_STEP]:
        Kk += par[P_K_STEP]
    out[0] = T_out
    out[1] = c * E1
    out[2] = x_out
    out[3] = (Kk if Kk > 0.0 else 0.0) * (1.0 + par[P_C_V] * spd) * (1.0 + par[P_R_S])
    out[4] = T


class ExtendedEstimator:
    """The extended single-tendon model run one sample per :meth:`step` (module docstring).

    Parameters
    ----------
    values : the model's parameters by the names of :data:`PARAMETERS` (SI units; K required, the others neutral
        when missing); a name of another catalogue entry is refused with the reason it has no per-cycle form
    u, w : the nodes' normalised wrap angle (0 proximal to 1 distal, non-decreasing) and trapezoid weights (sum 1),
        shape (m + 1,), m >= 1: the node grid the parameters were fitted on
    compliance : L/EA [m/N] >= 0
    tension_noise : standard deviation of the T_in reading [N] >= 0: the memory's noise band is
        NOISE_BAND_SIGMAS times that of the averaged T_in, and a turn of T_in must exceed 2 of it to count as a
        breakaway (0: exact)
    T_min : proximal tension [N] below which a breakaway gets no relaxation (None: 10 ``tension_noise``)
    rate_time_constant : time constant of the smoothed proximal velocity [s] > 0 (``average`` 1)
    average : the readings averaged per step, >= 1: T_in is the mean of the last ``average`` corrected readings and
        the velocity the slope of x_in across them (their noise: ``tension_noise`` / sqrt(``average``)); the fit's
        sample interval at the live rate runs the model on what it was fitted on (1: each reading as it is, the
        velocity smoothed over ``rate_time_constant``)
    track_friction : friction that changes during the session tracked online
        (:mod:`estimator.online.friction_observer`): the step dK at t_s is not replayed, and K (with the drift K_rate
        from the last estimate on) follows the proximal loop's width, one estimate per branch of full slip (False:
        the fitted change replayed from the first step, the batch model's form)

    Raises
    ------
    ValueError
        K missing, a name that is no parameter of :data:`PARAMETERS` (with the reason of its entry), a value not
        finite or out of range (K, compliance, T0, c_v, a, x_p, d_b, r_s, v_st, beta, t_s >= 0; T_c > 0; g_T_in > -1),
        or a node grid of another shape.
    """

    def __init__(self, values: Mapping[str, float], u: np.ndarray, w: np.ndarray, compliance: float, *,
                 tension_noise: float = 0.0, T_min: float | None = None, rate_time_constant: float = 0.02,
                 average: int = 1, track_friction: bool = False):
        v = _checked(values)
        self.values = v
        self.u = np.ascontiguousarray(u, dtype=np.float64)
        self.w = np.ascontiguousarray(w, dtype=np.float64)
        if not (self.u.ndim == 1 and self.u.shape == self.w.shape and self.u.size >= 2
                and np.all(np.isfinite(self.u)) and np.all(np.isfinite(self.w)) and np.all(np.diff(self.u) >= 0.0)):
            raise ValueError("u and w must be finite, of equal shape (m + 1,), m >= 1, u non-decreasing")
        for name, x, ok in (("compliance", compliance, compliance >= 0.0),
                            ("tension_noise", tension_noise, tension_noise >= 0.0),
                            ("rate_time_constant", rate_time_constant, rate_time_constant > 0.0)):
            if not (math.isfinite(x) and ok):
                raise ValueError(f"{name} out of range: {x!r}")
        if not (isinstance(average, int) and 1 <= average <= 1000):
            raise ValueError(f"average must be a whole number of samples in [1, 1000], got {average!r}")
        self.average = average
        self._ring = np.zeros((3, average))
        tension_noise = tension_noise / math.sqrt(average)     # the noise of the averaged T_in
        T_min = 10.0 * tension_noise if T_min is None else T_min
        if not (math.isfinite(T_min) and T_min >= 0.0):
            raise ValueError(f"T_min must be a finite tension >= 0 N, got {T_min!r}")
        self.compliance, self.tension_noise = float(compliance), float(tension_noise)
        self.band = NOISE_BAND_SIGMAS * self.tension_noise
        par = np.zeros(N_PAR)
        par[P_K], par[P_A], par[P_T0], par[P_K_RATE], par[P_C_V] = v["K"], v["a"], v["T0"], v["K_rate"], v["c_v"]
        par[P_R_S], par[P_T_SLIP], par[P_T_MIN], par[P_SIGMA] = v["r_s"], T_SLIP, T_min, self.tension_noise
        par[P_BETA], par[P_TC], par[P_V_ST], par[P_BAND] = v["beta"], v["T_c"], v["v_st"], self.band
        par[P_K_STEP], par[P_T_STEP] = (0.0, 0.0) if track_friction else (v["dK"], v["t_s"])
        self._par = par
        self.track_friction = bool(track_friction)
        q = np.zeros(9)
        q[_Q_B_T], q[_Q_G_T], q[_Q_D_T], q[_Q_B_X] = v["b_T_in"], v["g_T_in"], v["d_T_in"], v["b_x_in"]
        q[_Q_X_P], q[_Q_D_B], q[_Q_C], q[_Q_TAU] = v["x_p"], v["d_b"], self.compliance, rate_time_constant
        q[_Q_SPEED] = v["velocity_form"]
        self._q = q
        m1 = self.u.size
        self._Y, self._st, self._tab = np.empty(m1), np.empty(N_ST), np.empty((3, m1))
        self._dY, self._G = np.zeros(m1), np.zeros(m1)
        self._io, self._slide = np.empty((4, 1)), np.zeros(0, dtype=np.int8)
        self._one_T, self._one_E = np.empty(1), np.empty(1)
        self._o, self._out = np.zeros(9), np.empty(5)
        self.reset()

    def reset(self) -> None:
        """Back to rest: the profile uniform at T0, nothing stepped (the next step is the first: t_0, the play's
        middle and the velocity start there)."""
        self._par[P_K] = self.values["K"]
        start_extended(self.u, self.w, self._par, -1.0, self._Y, self._st, self._tab)
        self._o[:] = 0.0
        self.observer = FrictionObserver(self.values["a"], self._par[P_T_MIN]) if self.track_friction else None
        self.tracker = FrictionTracker(K_max=_K_MAX) if self.track_friction else None
        self._ring[:] = 0.0
        T0 = self.values["T0"]
        self.sample = ExtendedSample(T0, 0.0, 0.0, self.values["K"], T0)
        self._K_max = self.values["K"] * (1.0 + self.values["r_s"])   # the largest friction exponent of the run

    @property
    def steps(self) -> int:
        """Samples stepped since construction or :meth:`reset`."""
        return int(self._o[_O_STEPS])

    @property
    def profile(self) -> np.ndarray:
        """The tension profile T_i [N], proximal to distal, shape (m + 1,) (a copy)."""
        return self._Y - self.values["a"]

    def step(self, T_in: float, x_in: float, t: float) -> ExtendedSample:
        """Advance by one proximal sample: T_in [N], x_in [m] (the readings), t [s] (increasing). Returns the
        :class:`ExtendedSample`. Raises ValueError: a reading or the time is not finite."""
        if not (math.isfinite(T_in) and math.isfinite(x_in) and math.isfinite(t)):
            raise ValueError(f"proximal sample must be finite, got T_in={T_in!r} N, x_in={x_in!r} m, t={t!r} s")
        _step(float(T_in), float(x_in), float(t), self._q, self._par, self.u, self.w, self._Y, self._st, self._tab,
              self._dY, self._G, self._io, self._slide, self._one_T, self._one_E, self._o, self._ring, self._out)
        o = self._out
        self.sample = s = ExtendedSample(float(o[0]), float(o[1]), float(o[2]), float(o[3]), float(o[4]))
        if s.K_now > self._K_max:
            self._K_max = s.K_now
        if self.observer is not None:
            self._track(s, float(t))
        return s

    @property
    def friction(self) -> float:
        """The friction exponent K [-] at the last step (tracked, or the fitted K, its drift and step)."""
        since = max(self._o[_O_T_PREV] - self._st[S_T_ORIGIN], 0.0) if self.steps else 0.0
        step = self._par[P_K_STEP] if self.steps and since >= self._par[P_T_STEP] else 0.0
        return float(self._par[P_K] + self._par[P_K_RATE] * since + step)

    def _track(self, s: ExtendedSample, t: float) -> None:
        """One sample into the friction observer; a branch's estimate sets K (``track_friction``)."""
        assert self.observer is not None and self.tracker is not None
        par = self._par
        speed = 1.0 + self.values["c_v"] * abs(self._o[_O_V])
        drift = par[P_K_RATE] * (t - self._st[S_T_ORIGIN])
        K_now = par[P_K] + drift                    # the step is not replayed while tracking: K and its drift
        K_branch = self.observer.observe(s.T_in, s.x_out, int(self._st[S_SLIDING]), speed, K_now)
        if K_branch is None:
            return
        K = self.tracker.update(K_branch, K_now)
        if K is None:
            return
        par[P_K] = K - drift                        # K + K_rate (t' - t_0) = K at t, drifting on from there
        friction_bounds(self.u, par[P_K], par[P_R_S], self._tab)

    def out_of_range(self, s: ExtendedSample) -> str | None:
        """Why ``s`` leaves the physical range, or None: a negative distal tension, or a distal tension above the
        proximal one by more than e^K (the friction's bound on T + a, with the noise band h: T_out > (max(T_in, 0) +
        h + a) e^K - a + 1 mN, K the larger of ``s.K_now`` and the largest of the run's steps: a profile set at a
        higher speed or before a drift keeps that friction's tensions), or an output that is not finite."""
        if not (math.isfinite(s.T_out) and math.isfinite(s.x_out)):
            return "a non-finite estimate"
        if s.T_out < 0.0:
            return f"T_out = {s.T_out:.3g} N < 0"
        a = self.values["a"]
        bound = (max(s.T_in, 0.0) + self.band + a) * math.exp(max(s.K_now, self._K_max)) - a + 1e-3
        if s.T_out > bound:
            return f"T_out = {s.T_out:.3g} N above T_in e^K = {bound:.3g} N"
        return None


def _checked(values: Mapping[str, float]) -> dict[str, float]:
    """The parameters of :data:`PARAMETERS` from ``values`` as floats, neutral where missing (class Raises)."""
    extra = sorted(set(values) - set(PARAMETERS))
    if extra:
        prefix, _, channel = extra[0].partition("_")
        eid = f"sensor_{_KIND.get(prefix, '')}:{channel}"
        reason = f"{eid}: {PER_CYCLE[eid][1]})" if eid in PER_CYCLE else f"it runs {', '.join(PARAMETERS)})"
        raise ValueError(f"{extra[0]!r} is no parameter the per-cycle estimator runs (" + reason)
    if "K" not in values:
        raise ValueError("K (the friction exponent) is required")
    v = {k: float(values.get(k, d)) for k, d in PARAMETERS.items()}
    for k, x in v.items():
        if not math.isfinite(x):
            raise ValueError(f"{k} must be finite, got {x!r}")
    for k in ("K", "T0", "c_v", "a", "x_p", "d_b", "r_s", "v_st", "beta", "t_s"):
        if v[k] < 0.0:
            raise ValueError(f"{k} must be >= 0, got {v[k]!r}")
    if v["T_c"] <= 0.0 or v["g_T_in"] <= -1.0:
        raise ValueError(f"T_c must be > 0 and g_T_in > -1, got {v['T_c']!r}, {v['g_T_in']!r}")
    return v
