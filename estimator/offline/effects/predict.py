"""The batch prediction of the base model extended by catalogue effects (:func:`run_model`), and the slack rule.

:func:`run_model` (called by :func:`estimator.offline.effects.catalogue.predict`) runs, in order: the proximal
sensors' corrections (the model runs on the true inputs), the compiled kernel
(:func:`estimator.offline.effects.kernels.run_extended`, or the per-node pre-sliding kernel), pre-sliding on
T_out and the distal backlash on x_out, then the distal sensors' reading models. :func:`slack_hold` holds the
tendon's ends while it is slack (a tendon carries no compression). Used by
:mod:`estimator.offline.effects.catalogue`; this module imports nothing of it.
"""
from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from estimator.extended_loop import V_STOP
from estimator.offline.effects.kernels import (
    backlash_play,
    distal_slide,
    run_extended,
    travel_lag,
)
from estimator.offline.effects.presliding_kernel import node_presliding
from estimator.offline.effects.slack_kernel import held_tension, slack_index
from estimator.offline.effects.types import Prediction, Series

__all__ = ["run_model", "lookahead", "slack_hold", "slide_window", "SLIDE_WINDOW", "SLACK_SIGMAS", "SLACK_TAUT",
           "SLACK_WINDOW", "SLACK_MEAN", "SLACK_HELD"]

#: the window [s] over which the measured distal end must have moved by more than its resolution to count as moving
#: (Series.slide_travel; :func:`estimator.offline.effects.kernels.distal_slide`): 0.2 mm/s (V_STOP) over 50 ms is
#: 10 um, above the resolution of every simulated encoder (quanta up to 2 um)
SLIDE_WINDOW = 0.05
#: T_in below SLACK_SIGMAS x its noise level counts as a slack tendon (the prepared T_in of a slack tendon stays
#: below 2 sigma in 95 % of its samples)
SLACK_SIGMAS = 3.0
#: ... and a slack tendon is taut again before its proximal end is back where it went slack only when T_in
#: reaches SLACK_TAUT x that threshold (6 sigma: beyond what the noise gives in a recording's slack phases)
SLACK_TAUT = 2.0
#: ... or when the mean of T_in over SLACK_WINDOW samples (30 ms at the prepared 200 Hz; its noise is about 0.6
#: of one sample's after the 3-sample mean of `prepare`) is above SLACK_MEAN x the threshold (5 sigma of the
#: mean, about 3e-7 per sample)
SLACK_WINDOW = 6
SLACK_MEAN = 1.0
#: ... and a tendon is taut wherever the means of T_in over the SLACK_HELD samples before and after (both, so
#: a drop to zero is slack at once) are above SLACK_SIGMAS x their own noise, sqrt(3 / (SLACK_HELD + 2)) of the
#: threshold's sigma (the 3-sample mean of `prepare`), 1.1 sigma at 20 samples (0.1 s at the prepared 200 Hz).
#: A taut tendon released against a weak load carries T_in = T_out e^-K, which can sit below 3 sigma
SLACK_HELD = 20


def slide_window(time: np.ndarray) -> int:
    """SLIDE_WINDOW in samples of ``time`` [s], shape (n,), n >= 2 (at least 1)."""
    return max(1, int(round(SLIDE_WINDOW * (time.size - 1) / max(float(time[-1] - time[0]), 1e-12))))


def _rest_T_out(s: Series) -> float:
    """T_out over the initial rest of a series [N] (median of the samples before x_in first moves by 5 um);
    -1 without T_out. With pretension the distal end rests where the load holds it, which need not be the
    preload: a constant-force load below it lets the distal part of the tendon slide back."""
    if s.T_out is None:
        return -1.0
    moved = np.flatnonzero(np.abs(s.x_in - s.x_in[0]) > 5e-6)
    stop = max(int(moved[0]) if moved.size else len(s.x_in), 3)
    return max(float(np.median(s.T_out[:stop])), 0.0)


def _shift(time: np.ndarray, y: np.ndarray, tau: float) -> np.ndarray:
    """y(t - tau) by linear interpolation (held at the ends)."""
    return y if tau == 0.0 else np.interp(time - tau, time, y)


def _true_inputs(s: Series, g: Callable) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The proximal channels' true values from their readings (T_in, x_in, velocity)."""
    t, T_in, x_in, vel = s.time, s.T_in, s.x_in, s.velocity
    t0 = float(t[0])
    if g("sensor_offset:T_in"):
        T_in = T_in - g("sensor_offset:T_in")
    if g("sensor_gain:T_in"):
        T_in = T_in / (1.0 + g("sensor_gain:T_in"))
    if g("sensor_drift:T_in"):
        T_in = T_in - g("sensor_drift:T_in") * (t - t0)
    if g("sensor_lag:T_in"):
        T_in = _shift(t, T_in, -g("sensor_lag:T_in"))
    if g("sensor_lag:x_in"):
        x_in, vel = _shift(t, x_in, -g("sensor_lag:x_in")), _shift(t, vel, -g("sensor_lag:x_in"))
    if g("sensor_offset:x_in"):
        x_in = x_in - g("sensor_offset:x_in")
    return T_in, x_in, vel


def _memory(s: Series, knobs: dict, g: Callable, T_in, x_in, vel, u, x_p: float, node: bool,
            compliance: float | None, speed_form: bool, v_st: float, band: float, whole: tuple | None):
    """The profile memory over the series: (T_out [N], E1 [N], the distal slide directions or None). ``whole``: the
    uncut series and its true inputs (T_in, x_in) when ``s`` is its first samples (run_model's ``stop``)."""
    t = s.time
    if node and x_p > 0.0 and (compliance is not None or s.x_out is not None):   # per node: K, K_rate, T0, E9 only
        kw = {k: v for k, v in knobs.items() if k in ("K", "K_rate", "T0", "beta", "Tc")}
        # L/EA estimated on the uncut series: the same pass as without stop
        full, T_in_full, x_in_full = (s, T_in, x_in) if whole is None else whole
        stop = None if whole is None else len(s)
        T_out, E1 = _NODE(lambda: node_presliding(T_in_full, x_in_full, full.x_out, full.time, u, s.w, x_p=x_p,
                                                  compliance=compliance, stop=stop, **kw),
                          (T_in_full, x_in_full, full.x_out, full.time, s.w),
                          (u.tobytes(), x_p, compliance, stop, tuple(sorted(kw.items()))))
        return T_out, E1, None
    speed = None
    if knobs.get("c_v") and speed_form and s.x_out is not None:
        speed = 0.5 * (np.abs(vel) + np.abs(np.gradient(s.x_out, t)))
    T0_out = -1.0
    if knobs.get("T0") and (T0_out := _rest_T_out(s)) >= 0.0:
        # the distal rest reading in true tension: through the T_out reading model fitted with it (no drift at t0)
        T0_out = max((T0_out - g("sensor_offset:T_out")) / (1.0 + g("sensor_gain:T_out")), 0.0)
    # where the measured distal end moves the whole tendon slides; a fitted x_out lag undone first
    slide = s.slide
    if slide is not None and s.x_out is not None and g("sensor_lag:x_out"):
        slide = distal_slide(_shift(t, s.x_out, -g("sensor_lag:x_out")), s.slide_travel, slide_window(t))
    T_out, E1 = _recent_run(T_in, vel, t, u, s.w, slide, speed, dict(T_min=s.T_min, sigma=s.sigma_T_in, v_st=v_st,
                                                                      T0_out=T0_out, band=band, **knobs))
    return T_out, E1, slide


def _where(a: np.ndarray | None) -> tuple | None:
    return None if a is None else (a.__array_interface__["data"][0], a.shape, a.strides, a.dtype.str)


class _Recent:
    """The last few results of a pure function of arrays and numbers, by where the (read-only) arrays lie and the
    numbers' values; the arrays are kept alive with them, and the results are made read-only. A fit varies the
    parameters that act outside the kernel (the distal sensors' reading models, an x_in offset, the backlash,
    pre-sliding's travel lag, and beside per-node pre-sliding every knob it does not read) as often as the others,
    and those leave the kernel's run and the slack rule as they were."""

    def __init__(self, size: int = 4):
        self.size = size
        self.kept: list[tuple[tuple, tuple, tuple]] = []

    def __call__(self, compute: Callable, arrays: tuple, numbers: tuple) -> tuple:
        key = (tuple(_where(a) for a in arrays), numbers)
        for k, _, out in self.kept:
            if k == key:
                return out
        out = compute()
        for a in out:
            a.flags.writeable = False
        self.kept.insert(0, (key, arrays, out))
        del self.kept[self.size:]
        return out


_RUNS = _Recent()       # the kernel's (T_out, E1)
_NODE = _Recent()       # per-node pre-sliding's (T_out, E1)
_TAUT = _Recent()       # the slack rule's last taut sample and x_in there, (index, x_in[index])


def _recent_run(T_in, vel, t, u, w, slide, speed, numbers: dict) -> tuple[np.ndarray, np.ndarray]:
    """The kernel's (T_out, E1) (:func:`estimator.offline.effects.kernels.run_extended`), read-only."""
    return _RUNS(lambda: run_extended(T_in, vel, t, u, w, speed=speed, slide=slide, **numbers),
                 (T_in, vel, t, w, slide, speed), (u.tobytes(), tuple(sorted(numbers.items()))))


def _x_out(s: Series, g: Callable, x_in, E1, taut, x_held, d_b: float, compliance: float | None,
           fit_mask: slice | np.ndarray | None) -> tuple[np.ndarray, float]:
    """The distal position reading and L/EA [m/N] (fitted by linear least squares when not given and x_out is
    measured; offset and lag are linear in it): a taut tendon's end, through the distal backlash's play.
    ``x_held`` is x_in at the last taut sample, ``x_in[taut]``."""
    t = s.time
    tau_x = g("sensor_lag:x_out", 0.0)
    A = _shift(t, x_held, tau_x)
    if g("sensor_offset:x_out"):
        A = A + g("sensor_offset:x_out")
    B = _shift(t, E1[taut], tau_x)
    c = compliance
    if c is None:
        c = 0.0
        if s.x_out is not None:
            m = slice(None) if fit_mask is None else fit_mask
            a, b = B[m], A[m] - s.x_out[m]
            den = float(a @ a)
            c = max(float(a @ b) / den, 0.0) if den > 0 else 0.0
    x_out = np.multiply(B, c)
    np.subtract(A, x_out, out=x_out)
    if d_b > 0.0:       # the joint through its play; L/EA refined on the samples in contact
        fitted = np.ones(x_in.size, dtype=bool)
        if fit_mask is not None:
            fitted[:] = False
            fitted[fit_mask] = True
        for _ in range(3 if compliance is None and s.x_out is not None else 1):
            x_end = (x_in - c * E1)[taut]
            delta = backlash_play(x_end, d_b) - x_end                 # +-d_b/2 in contact
            x_out = _shift(t, x_end + delta, tau_x) + g("sensor_offset:x_out", 0.0)
            if compliance is None and s.x_out is not None:
                on = (np.abs(np.abs(delta) - 0.5 * d_b) < 1e-3 * d_b) & fitted
                a = B[on]
                den = float(a @ a)
                if den > 0:
                    c = max(float(a @ (A + _shift(t, delta, tau_x) - s.x_out)[on]) / den, 0.0)
                    x_out = _shift(t, (x_in - c * E1)[taut] + delta, tau_x) + g("sensor_offset:x_out", 0.0)
    return x_out, c


def run_model(s: Series, knobs: dict[str, float], sensors: dict[str, float], u: np.ndarray, *, x_p: float = 0.0,
              d_b: float = 0.0, node: bool = False, compliance: float | None = None,
              fit_mask: slice | np.ndarray | None = None, speed_form: bool = False, v_st: float = 0.0,
              band: float = 0.0, stop: int | None = None) -> Prediction:
    """The model's outputs over a series (:func:`estimator.offline.effects.catalogue.predict` sets the arguments).

    ``knobs``: the kernel's knobs (K and the physical effects'); ``sensors``: sensor effect id -> its value;
    ``u``: the nodes' wrap shape; ``x_p`` [m] pre-sliding travel (per node with ``node``); ``d_b`` [m] the distal
    backlash; ``compliance`` L/EA [m/N] (None: fitted on ``fit_mask`` when x_out is measured); ``speed_form``: the
    sliding speed is the mean of the proximal and the distal one; ``v_st`` [m/s] the Stribeck speed (0: the
    breakaway form); ``band`` [N] the memory's noise band; ``stop``: the outputs are wanted on the first ``stop``
    samples only (None: all). The model then runs over the samples those depend on (:func:`lookahead`), with the
    same outputs there as over the whole series; ``fit_mask`` must lie within them.
    """
    def g(key: str, default: float = 0.0) -> float:
        return sensors.get(key, default)
    T_in, x_in, vel = _true_inputs(s, g)
    whole = None
    if stop is not None and (n := lookahead(s, sensors, stop)) < len(s):
        whole = (s, T_in, x_in)
        s, T_in, x_in, vel = s.slice(n), T_in[:n], x_in[:n], vel[:n]
    t = s.time
    T_out, E1, slide = _memory(s, knobs, g, T_in, x_in, vel, u, x_p, node, compliance, speed_form, v_st, band,
                               whole)
    if x_p > 0.0 and not node:
        T_out = T_in - travel_lag(T_in - T_out, x_in, x_p)
    # distal channels: the reading from the true output
    if g("sensor_gain:T_out"):
        T_out = T_out * (1.0 + g("sensor_gain:T_out"))
    if g("sensor_offset:T_out"):
        T_out = T_out + g("sensor_offset:T_out")
    if g("sensor_drift:T_out"):
        T_out = T_out + g("sensor_drift:T_out") * (t - float(t[0]))
    T_out = _shift(t, T_out, g("sensor_lag:T_out", 0.0))
    # a slack tendon: T_in at the noise around zero - the tendon carries no compression, the proximal end moves
    # without it and the distal end stays where the last taut sample left it
    def taut_at() -> tuple[np.ndarray, np.ndarray]:
        moving = None if slide is None else slide * vel > V_STOP      # the distal end carried along: taut
        taut = slack_hold(T_in, SLACK_SIGMAS * s.sigma_T_in, x_in, moving)
        return taut, x_in[taut]
    taut, x_held = _TAUT(taut_at, (T_in, x_in, slide, vel), (s.sigma_T_in,))
    x_out, c = _x_out(s, g, x_in, E1, taut, x_held, d_b, compliance, fit_mask)
    if stop is not None:
        T_out, x_out = T_out[:stop], x_out[:stop]
    return Prediction(T_out=T_out, x_out=x_out, compliance=float(c))


def lookahead(s: Series, sensors: dict[str, float], stop: int) -> int:
    """How many first samples of ``s`` the model's outputs on its first ``stop`` samples depend on (at most
    ``len(s)``): the model runs forward in time, and only three of its steps read later samples - undoing a lag
    of a proximal channel or of x_out (its value at t + tau), the slack rule (the mean of T_in over the
    SLACK_HELD samples from each sample on) and the distal speed (a central difference)."""
    n = len(s)
    tau = max(sensors.get(f"sensor_lag:{c}", 0.0) for c in ("T_in", "x_in", "x_out"))
    last = s.time[min(stop + SLACK_HELD, n - 1)] + max(tau, 0.0)
    return min(int(np.searchsorted(s.time, last, side="right")) + 2, n)


def slack_hold(T_in: np.ndarray, threshold: float, x_in: np.ndarray | None = None,
               moving: np.ndarray | None = None) -> np.ndarray:
    """Index of the last taut sample at every sample, shape (n,) (the sample itself where the tendon is taut;
    the first sample before any taut one). Indexing a position with it holds the tendon's ends while it is
    slack: a tendon carries no compression, so a proximal end moving at zero tension leaves the rest behind.

    T_in [N], shape (n,); ``threshold`` [N] (<= 0: never slack); x_in [m], shape (n,) or None.
    Without x_in a sample is taut where T_in >= ``threshold``. With x_in the slack is geometric:
    once slack, the tendon is taut again only when T_in >= ``threshold`` with the proximal end back where it
    went slack (the paid-out length taken up) or with its mean over the last SLACK_WINDOW samples >= SLACK_MEAN x
    ``threshold`` (a tension above zero: a taut tendon at low tension whose noise dips below the threshold, as
    a spring load near its rest on release), or when T_in >= SLACK_TAUT x ``threshold`` anywhere: a single noise
    sample above ``threshold`` in a long slack phase does not end the hold. With x_in a sample is also taut,
    whatever T_in's own value, where the means of T_in over the SLACK_HELD samples before it and after it both
    exceed ``threshold`` sqrt(3 / (SLACK_HELD + 2)) (a tendon released against a weak load at T_out e^-K, under
    the threshold but held above zero), and wherever ``moving`` (bool, shape (n,), optional) is set: the measured
    distal end carried along the way the proximal end moves (a joint spring holding the tendon taut at a low
    T_in)."""
    idx = np.arange(T_in.shape[0])
    if threshold <= 0.0:
        return idx
    if x_in is None:
        return np.maximum.accumulate(np.where(T_in >= threshold, idx, 0))
    T = np.ascontiguousarray(T_in, dtype=np.float64)
    held = held_tension(T, SLACK_HELD)
    if moving is not None:
        held[moving] = np.inf
    return slack_index(T, np.ascontiguousarray(x_in, dtype=np.float64), float(threshold),
                       float(SLACK_TAUT * threshold), SLACK_WINDOW, float(SLACK_MEAN * threshold), held,
                       float(threshold * math.sqrt(3.0 / (SLACK_HELD + 2))))
