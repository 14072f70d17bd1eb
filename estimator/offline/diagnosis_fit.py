"""Fitting and scoring for the diagnosis (:mod:`estimator.offline.diagnosis` selects; docs/diagnosis.md).

* :func:`prepare`: block-average the recording to about ``target_rate`` (zero phase; the noise
  drops, the rate-independent maths does not change), a 3-sample mean on T_in, velocity dx_in/dt,
  noise levels, the model's node grid.
* :func:`split_at_rest`: training = the first ``train_fraction`` of the duration, moved to the
  quietest rest within 8 % of it so that whole cycles are held out; never random samples
  (neighbouring samples are almost equal and would leak).
* :func:`fit_model`: K and the extensions' parameters by ``scipy.optimize.least_squares`` on the
  training block, L/EA in closed form inside every evaluation (it enters x_out linearly).
* :func:`heldout_mse`, :func:`raw_rmse`: held-out errors on the averaged series and on the
  measured samples (the model always runs from the first sample, so the held-out block starts from
  the state the training block left, as online use would).
"""
from __future__ import annotations

import itertools
import math
import sys
from dataclasses import replace
from typing import Callable

import numpy as np
from scipy.optimize import least_squares

from estimator.offline.effects import (K_MAX, ROUTE, ROUTE_FORMS, Effect, Parameter, Series, effect, predict,
                                      slide_window)
from estimator.offline.effects_kernels import distal_slide
from estimator.sheath import SheathModel
from estimator.data import MeasuredData, noise_level
from estimator.errors import DataError

__all__ = ["Progress", "trimmed_ms", "paired_trimmed_ms", "sample_block", "rest_reading", "rest_offset", "REST_MIN_S", "REST_RESOLUTIONS", "prepare", "split_at_rest", "fit_model", "start_points", "rest_window", "rest_start", "heldout_mse", "raw_rmse", "noise_level",
           "quantum", "stick_slip_ratio", "STICK_SLIP_WINDOW", "STICK_SLIP_SPEED", "STICK_SLIP_MIN_MOVE", "distal_end_held", "HELD_STEPS", "HELD_SHARE", "NEAR_HELD_SHARE", "distal_at_end", "AT_END_SPEED",
           "AT_END_BAND", "AT_END_SHARE", "AT_END_HIDES", "SIGNALS", "channel_choice", "look_alike", "toe_or_play", "settings_keys", "predictions"]

_K = Parameter("K", "-", 0.0, K_MAX, 0.5, (), "friction exponent mu * total wrap angle")
_SCALE = {"K": 0.1, "c_v": 10.0, "T0": 1.0, "K_rate": 1e-3, "beta": 1.0, "T_c": 1.0, "r_s": 0.1, "a": 0.5,
          "x_p": 2e-5, "d_b": 2e-5, **{f"r_{k}": 0.1 for k in range(1, 12)},
          "b_T_in": 0.5, "b_T_out": 0.5, "g_T_in": 0.02, "g_T_out": 0.02, "tau_T_in": 0.01, "tau_T_out": 0.01,
          "d_T_in": 2e-3, "d_T_out": 2e-3, "b_x_in": 2e-5, "b_x_out": 2e-5, "tau_x_in": 0.01, "tau_x_out": 0.01}
SIGNALS = ("T_out", "x_out")
#: every FIT_STRIDE-th sample of the averaged series enters the least-squares residual (the model
#: runs on all of them; the residual vector, and so the trust-region algebra, is that much shorter)
FIT_STRIDE = 3


def quantum(a: np.ndarray) -> float:
    """The quantisation step of a recorded channel [unit of a]: the 5th percentile of the non-zero
    sample-to-sample steps when the channel only takes multiples of one step (else 0)."""
    d = np.abs(np.diff(np.asarray(a, dtype=float)))
    d = d[d > 0]
    if d.size < 20:
        return 0.0
    q = float(np.percentile(d, 5))
    steps = d[: 2000] / q
    return q if np.all(np.abs(steps - np.round(steps)) < 0.05) else 0.0


#: Stick-slip check (:func:`stick_slip_ratio`): the smoothing window [s] (at least 7 samples), the proximal speed
#: [m/s] above which a sample counts as a steady move (over three windows around it) and below which a hold
STICK_SLIP_WINDOW = 0.025
STICK_SLIP_SPEED = 1e-3
STICK_SLIP_HOLD = 1e-5
#: fewest samples of each kind (steady move, hold) for the ratio to be read, and the shortest time [s] of steady
#: moves and of holds: on a second of moves the edges of the moves (the motor's acceleration, the kink where the slip
#: reaches the distal end) weigh enough to reach 1.5-1.9 without stick-slip (lumped dev26 2501102, 2501113: 0.5-1.1 s
#: of steady moves; the least-moving hidden stiction of dev25-dev27 that reached 1.4 moves for 8.9 s)
STICK_SLIP_MIN_SAMPLES = 200
STICK_SLIP_MIN_MOVE = 3.0
STICK_SLIP_MIN_HOLD = 1.0


def _smoothed_speed(t: np.ndarray, x: np.ndarray, max_window: int | None = None) -> tuple[np.ndarray, float, int]:
    """|dx/dt| from a quadratic Savitzky-Golay derivative over STICK_SLIP_WINDOW (at least 7 samples, odd, at most
    ``max_window``), with the median sample interval and the window: (speed (n,) [m/s], dt [s], window [samples])."""
    from scipy.signal import savgol_filter

    dt = float(np.median(np.diff(t)))
    w = max(7, int(round(STICK_SLIP_WINDOW / dt)) | 1)
    if max_window is not None:
        w = min(w, max_window - (1 - max_window % 2))
    return np.abs(savgol_filter(x, w, 2, deriv=1, delta=dt)), dt, w


#: a block "holds a release" when its proximal tension falls from its running maximum by at least this share of its
#: range (:func:`holds_release`). Where the friction sits along the sheath (the route, E7) shows only while a slip
#: front crosses the sheath after a reversal; a monotonic pull identifies the route's integral, not its shape.
#: Session 29: on lumped dev45 the forward fit blocks of the other protocols fall by 0.66 of their maximum or more; one
#: (4402103, a single slow pull to 18 N with its release after the forward fit block) by 0.005. Of 1302 protocols
#: scanned (lumped dev40-dev45, the rig's dev45) it is the only one with a fold whose fit block holds no release
RELEASE_SHARE = 0.2


def holds_release(T_in: np.ndarray, share: float = RELEASE_SHARE) -> bool:
    """Whether the proximal tension of a block falls from its running maximum by at least ``share`` of its range
    (a reversal the slip front then crosses: what shows the route's shape; literature.md E7).

    Parameters
    ----------
    T_in : ndarray (n,) [N]; share : float in (0, 1]

    Returns
    -------
    bool (False for fewer than 2 samples or a constant block)
    """
    y = np.asarray(T_in, dtype=float)
    span = float(np.ptp(y)) if y.size else 0.0
    if y.size < 2 or not span > 0.0:
        return False
    return float(np.max(np.maximum.accumulate(y) - y)) >= share * span


def stick_slip_ratio(time: np.ndarray, x_in: np.ndarray, T_in: np.ndarray) -> float | None:
    """How much rougher the proximal tension is in steady moves than in holds (literature.md E4: stick-slip).

    A quasi-static friction law, with or without a static peak, gives a proximal tension that is smooth while the
    proximal end moves steadily; static friction above kinetic with a falling (Stribeck) branch makes the tendon
    stick and slip, and the proximal load cell reads the saw-tooth on top of its noise. The ratio compares the
    high-frequency part of T_in (T_in less a quadratic Savitzky-Golay fit over STICK_SLIP_WINDOW) on samples
    where the proximal speed stays above STICK_SLIP_SPEED for three windows with the same on holds (speed below
    STICK_SLIP_HOLD): median absolute values, the holds' at least a quarter of T_in's quantisation step. It is
    about 1 for white sensor noise.

    Parameters
    ----------
    time : ndarray (n,) [s], increasing; x_in : ndarray (n,) [m]; T_in : ndarray (n,) [N]

    Returns
    -------
    float or None
        The ratio (dimensionless), or None when fewer than STICK_SLIP_MIN_SAMPLES steady-move or hold samples,
        under STICK_SLIP_MIN_MOVE seconds of steady moves or under STICK_SLIP_MIN_HOLD seconds of holds exist.

    Raises
    ------
    ValueError
        Arrays of different lengths.
    """
    from scipy.ndimage import minimum_filter1d
    from scipy.signal import savgol_filter

    t, x, y = (np.asarray(a, dtype=float) for a in (time, x_in, T_in))
    if not t.shape == x.shape == y.shape:
        raise ValueError(f"stick_slip_ratio: time, x_in and T_in differ in length ({t.size}, {x.size}, {y.size})")
    if t.size < 2 * STICK_SLIP_MIN_SAMPLES:
        return None
    v, dt, w = _smoothed_speed(t, x)
    moving = minimum_filter1d(v, 3 * w) > STICK_SLIP_SPEED
    hold = v < STICK_SLIP_HOLD
    n_move, n_hold = int(moving.sum()), int(hold.sum())
    if (min(n_move, n_hold) < STICK_SLIP_MIN_SAMPLES or n_move * dt < STICK_SLIP_MIN_MOVE
            or n_hold * dt < STICK_SLIP_MIN_HOLD):
        return None
    r = np.abs(y - savgol_filter(y, w, 2))
    return float(np.median(r[moving]) / max(float(np.median(r[hold])), 0.25 * quantum(y), 1e-12))


#: x_out counts as held (the distal end never moved: a stop, or a load the tension never broke free) when its
#: 0.5-99.5 % range is within HELD_STEPS resolution steps (quantum or noise) or HELD_SHARE of x_in's travel
#: (session 10: the clean twin of lumped dev11 1019112, a preloaded spring that T_out never lifted off its
#: stop, x_out within one 1.2 um quantum, 0.3 % of x_in's travel; among the other 183 clean dev11 rigs the
#: least-moving x_out spans 173 quanta, 19 % of x_in's travel)
HELD_STEPS = 4.0
HELD_SHARE = 0.01
#: ... and barely moves below NEAR_HELD_SHARE of x_in's travel: a distal end pressed on a stop moves by the stop's
#: deflection and the tendon's pre-sliding, which the base model reads as elongation. Such an x_out is set aside
#: when the diagnosis with it leaves structure no effect explains and the one without it does not (session 13:
#: lumped dev14 1301113, a pretension holding a joint on its stop, x_out 1.4 % of the travel, distal backlash +
#: pretension + unknown -> pretension; 1302101, a preloaded spring barely lifted, 3.2 %, unknown -> curvature
#: drift; lumped dev10 901102, a pretension on a joint at 6.3 %, and dev11 1001112, one at 1.0 %, are named with
#: x_out and keep it; in lumped dev10, dev11, dev13, dev14 no other x_out moves between 1 % and 19 % of the
#: travel, in rig dev14 none below 45 %)
NEAR_HELD_SHARE = 0.1
#: the distal end counts as at an end of its range (a joint on its stop, a preloaded spring not lifted, a slack
#: tendon at rest) within AT_END_BAND of x_out's 0.5-99.5 % range (at least HELD_STEPS resolution steps) of that
#: range's top or bottom; the proximal end moves where x_in's speed exceeds AT_END_SPEED [m/s]
AT_END_SPEED = 1e-4
AT_END_BAND = 0.02
#: ... and a recording whose distal end sits at an end for AT_END_SHARE of the proximal travel or more cannot show
#: the effects AT_END_HIDES: session 27, lumped 3900000+ and 4000000+ (unseen sets, 320 hidden effects): every x_out
#: lag whose distal end moved was named (12 of 12, share 0.004-0.42), none of the four on joints driven onto their
#: stop and held there (share 0.89-0.98; the delay fitted within 2 % and S 0.90-0.97: the one rise to the stop lies
#: in one fold's fit block, and no validation block holds a move of x_out). The other effects at or above the share
#: were named (up to the gain pair) 29 times in 31, below it 260 in 273; 9 of 48 clean recordings reach 0.84-0.96
AT_END_SHARE = 0.8
AT_END_HIDES = ("sensor_lag:x_out",)


def distal_end_held(data: MeasuredData, share: float = HELD_SHARE) -> dict | None:
    """Whether a recording's x_out stands still (module constants HELD_STEPS, HELD_SHARE): then it shows
    only that the distal end was held, nothing of the tendon (no elongation, no play, no lag can be read
    from it). ``share``: the part of x_in's travel [-] below which x_out counts as standing (NEAR_HELD_SHARE:
    barely moving). Returns {"range_m", "step_m", "travel_m"} when held, None when x_out moves or is absent."""
    if data.x_out is None:
        return None
    x_out = np.asarray(data.x_out, dtype=float)
    span = float(np.percentile(x_out, 99.5) - np.percentile(x_out, 0.5))
    step = max(quantum(x_out), noise_level(x_out))
    travel = float(np.ptp(np.asarray(data.x_in, dtype=float)))
    if span <= max(HELD_STEPS * step, share * travel):
        return {"range_m": span, "step_m": step, "travel_m": travel}
    return None


def distal_at_end(data: MeasuredData) -> dict | None:
    """How much of the proximal travel the distal end spends at an end of its range (module constants AT_END_*):
    a joint driven onto its stop and held there, or a load the tension never lifts, shows the tendon's
    elongation but not the distal end's own motion, so a lag of the distal encoder cannot show (AT_END_HIDES).

    The share is the proximal travel (x_in's speed, a quadratic Savitzky-Golay derivative over
    STICK_SLIP_WINDOW, integrated where it exceeds AT_END_SPEED) during which x_out lies within the band of
    the top or the bottom of its 0.5-99.5 % range, over all of that travel.

    Parameters
    ----------
    data : MeasuredData with time [s], x_in [m] and x_out [m]

    Returns
    -------
    dict or None
        {"share": [-] in [0, 1], "band_m": [m], "range_m": x_out's 0.5-99.5 % range [m], "hides": the catalogue
        ids that cannot show (AT_END_HIDES when share >= AT_END_SHARE, else [])}; None without x_out or
        when x_in never moves faster than AT_END_SPEED.

    Raises
    ------
    ValueError
        Fewer than 7 samples.
    """
    if data.x_out is None:
        return None
    t, x_in, x_out = (np.asarray(a, dtype=float) for a in (data.time, data.x_in, data.x_out))
    if t.size < 7:
        raise ValueError(f"distal_at_end: {t.size} samples, at least 7 needed")
    speed, dt, _ = _smoothed_speed(t, x_in, max_window=t.size)
    moving = speed > AT_END_SPEED
    travel = float(np.sum(speed[moving]) * dt)
    if travel <= 0.0:
        return None
    low, high = (float(v) for v in np.percentile(x_out, (0.5, 99.5)))
    band = max(HELD_STEPS * max(quantum(x_out), noise_level(x_out)), AT_END_BAND * (high - low))
    at_end = (np.abs(x_out - high) <= band) | (np.abs(x_out - low) <= band)
    share = float(np.sum(speed[moving & at_end]) * dt / travel)
    return {"share": share, "band_m": band, "range_m": high - low,
            "hides": list(AT_END_HIDES) if share >= AT_END_SHARE else []}


#: the memory reads the measured distal end (session 20): where x_out moves the way x_in does, the whole tendon
#: slides (a stuck distal part holds the distal end), whatever the memory with the fitted K holds. Motion is
#: x_out's travel beyond SLIDE_QUANTA quanta, SLIDE_SIGMAS x its noise and SLIDE_SHARE of x_in's range.
SLIDE_SEEN = True
SLIDE_QUANTA = 2.0
SLIDE_SIGMAS = 4.0
SLIDE_SHARE = 1e-4


def prepare(data: MeasuredData, *, n_nodes: int = 32, target_rate: float = 200.0,
            wrap_shape: np.ndarray | None = None) -> Series:
    """Block-average a recording to about ``target_rate`` [Hz] and set up the model's node grid.

    Parameters
    ----------
    data : MeasuredData with time [s], x_in [m], T_in [N] and x_out [m] and/or T_out [N]
    n_nodes : elements of the tension profile (32 keeps the elongation error below 0.1 um)
    wrap_shape : normalised route shape, see :class:`estimator.sheath.SheathModel` (None: uniform)

    Raises
    ------
    DataError
        No distal column, or a non-finite sample in a column. ValueError: fewer than 400 samples after
        averaging.
    """
    data.require_distal()
    for name in ("time", "x_in", "T_in", "x_out", "T_out"):
        col = getattr(data, name)
        bad = np.flatnonzero(~np.isfinite(np.asarray(col, dtype=float))) if col is not None else np.empty(0, int)
        if bad.size:
            raise DataError(f"{data.source}: column {name} has {bad.size} non-finite samples (first at sample "
                            f"{int(bad[0])}); cut the recording before them or repair the column")
    t = np.asarray(data.time, dtype=float)
    fs = (t.size - 1) / max(t[-1] - t[0], 1e-12)
    m = max(1, int(fs // target_rate))
    nb = t.size // m
    if nb < 400:
        raise ValueError(f"{data.source}: {t.size} samples at {fs:.0f} Hz are too few to diagnose (need >= 400 "
                         f"after averaging to {target_rate:.0f} Hz, i.e. a few cycles)")

    def dec(a):
        return None if a is None else np.asarray(a, dtype=float)[: nb * m].reshape(nb, m).mean(axis=1)

    time, x_in, T_in = dec(t), dec(data.x_in), dec(data.T_in)
    sigma_in = noise_level(T_in) / math.sqrt(3.0)          # after the mean below
    # a further 3-sample zero-phase mean on T_in: the play operator latches noise extremes (times
    # e^K on release), and this halves that bias while keeping reversal corners (docs/diagnosis.md)
    T_in = np.convolve(np.pad(T_in, 1, mode="edge"), np.ones(3) / 3.0, mode="valid")
    velocity = np.gradient(x_in, time)
    shape, weight = SheathModel(K=1.0, compliance=1.0, wrap_shape=wrap_shape).nodes(int(n_nodes))
    T_min = max(10.0 * sigma_in, 0.01 * float(np.ptp(T_in)))
    x_out = dec(data.x_out)
    travel, slide = 0.0, None
    if x_out is not None and data.x_out is not None and SLIDE_SEEN:
        travel = max(SLIDE_QUANTA * quantum(data.x_out), SLIDE_SIGMAS * noise_level(x_out),
                     SLIDE_SHARE * float(np.ptp(x_in)))
        slide = distal_slide(x_out, travel, slide_window(time))
    return Series(time, x_in, T_in, velocity, dec(data.T_out), x_out, shape, weight, T_min, sigma_in, travel, slide)


def split_at_rest(s: Series, train_fraction: float) -> int:
    """Index of the first held-out sample: near ``train_fraction`` of the duration, at a rest.

    Within +-8 % of the duration around the nominal split the sample with the lowest
    (0.5 s mean speed / its median + T_in / range of T_in) is taken, so the split falls in a hold at
    low tension between cycles when there is one. Raises ValueError for a fraction outside
    [0.3, 0.9] or blocks of fewer than 20 samples.
    """
    if not 0.3 <= train_fraction <= 0.9:
        raise ValueError(f"train_fraction must be in [0.3, 0.9], got {train_fraction!r}")
    t = s.time
    dur = t[-1] - t[0]
    lo = np.searchsorted(t, t[0] + (train_fraction - 0.08) * dur)
    hi = np.searchsorted(t, t[0] + (train_fraction + 0.08) * dur)
    win = max(1, min(int(round(0.5 / max(np.median(np.diff(t)), 1e-9))), len(s) // 4))
    v = np.convolve(np.abs(s.velocity), np.ones(win) / win, mode="same")
    score = v / max(float(np.median(v)), 1e-12) + (s.T_in - s.T_in.min()) / max(float(np.ptp(s.T_in)), 1e-12)
    k = int(lo + np.argmin(score[lo:hi])) if hi > lo else int(np.searchsorted(t, t[0] + train_fraction * dur))
    if k < 20 or len(s) - k < 20:
        raise ValueError(f"a {train_fraction:.0%} split leaves a block with fewer than 20 samples")
    return k


def _params(effects: list[Effect], route: bool | str = False) -> list[Parameter]:
    shares = list(ROUTE_FORMS[route]) if isinstance(route, str) else list(ROUTE) if route else []
    return [_K] + shares + [p for e in effects for p in e.parameters]


def _residual_scales(s: Series) -> dict[str, float]:
    out = {}
    for name in SIGNALS:
        y = getattr(s, name)
        if y is not None:
            out[name] = max(float(np.ptp(y)), 1e-12)
    return out


def fit_model(effects: list[Effect], train: Series, starts: list[dict[str, float]], *,
              max_starts: int = 2, route: bool | str = False, fixed: dict[str, float] | None = None,
              mask: slice | None = None) -> tuple[dict[str, float], float, float]:
    """Least-squares fit of K and the parameters of ``effects`` on a training series.

    Every start (dict of parameter values, missing ones neutral) is scored, the best
    ``max_starts`` are refined by ``scipy.optimize.least_squares`` (trust-region reflective, within
    the parameters' bounds, in variables scaled to O(1)). L/EA is solved in closed form inside
    every residual evaluation. ``route``: fit the route shares r_1, r_2 too (estimator.offline.effects.ROUTE), or with
    "fine" the sixths r_1 ... r_5 (estimator.offline.effects.ROUTE_FINE), with "twelfths" r_1 ... r_11
    (estimator.offline.effects.ROUTE_TWELFTHS);
    ``fixed``: values held (e.g. the base model's route); ``mask``: the samples of ``train`` whose
    residuals count (default all; the model always runs from the first sample). A refinement that takes
    no step at all (K on the edge of a step in the residual) is tried again with K held, then with all
    free from there, and that is kept when it costs less with the effects' parameters inside their bounds
    (session 14). Returns (values, compliance [m/N], cost).
    """
    m = slice(None) if mask is None else mask
    params = _params(effects, route)
    # an effect's form (Effect.variants: held, not fitted) travels with the first start
    fixed = {**{k: starts[0][k] for k in settings_keys(effects) if starts and k in starts[0]}, **(fixed or {})}
    scale = np.array([_SCALE[p.name] for p in params])
    lo = np.array([p.lower for p in params]) / scale
    hi = np.array([p.upper for p in params]) / scale
    norm = _residual_scales(train)
    ys = {k: getattr(train, k)[m][::FIT_STRIDE] for k in norm}

    def values(z):
        return {**fixed, **{p.name: float(v) for p, v in zip(params, z * scale)}}

    def residual(z):
        pr = predict(effects, values(z), train, fit_mask=m)
        return np.concatenate([(getattr(pr, k)[m][::FIT_STRIDE] - ys[k]) / v for k, v in norm.items()])

    def refine(fun, z, lower, upper):
        return least_squares(fun, z, bounds=(lower, upper), diff_step=1e-2, x_scale=1.0, ftol=1e-6, xtol=1e-6,
                             max_nfev=40 * len(z))

    z_starts = [np.clip(np.array([st.get(p.name, p.neutral) for p in params]) / scale, lo, hi) for st in starts]
    ranked = sorted(z_starts, key=lambda z: float(np.sum(residual(z) ** 2)))
    own = slice(len(_params([], route)), None)             # the effects' parameters
    span = 1e-3 * (hi[own] - lo[own])
    best = None
    for z0 in ranked[:max_starts]:
        sol = refine(residual, z0, lo, hi)
        if np.array_equal(sol.x, z0) and len(params) > 1:
            # not a single step taken: K sits on the edge of a step in the residual (the memory or slack rule
            # of some sample flips just below it), every trial step lowers K and fails, and the trust region
            # shrinks to nothing. The others are refitted with K held, then all from there - kept only when an
            # effect's parameters stay inside their bounds (lumped dev14 1305113: from there a T_in gain ran
            # to its -0.5 bound, S 0.04 -> 0.02, and displaced the friction offset that was there)
            def rest_of(y):
                return residual(np.concatenate([z0[:1], y]))
            sub = refine(rest_of, z0[1:], lo[1:], hi[1:])
            again = refine(residual, np.concatenate([z0[:1], sub.x]), lo, hi)
            inside = bool(np.all((again.x[own] > lo[own] + span) & (again.x[own] < hi[own] - span)))
            if again.cost < sol.cost and inside:
                sol = again
        if best is None or sol.cost < best.cost:
            best = sol
    assert best is not None         # max_starts >= 1 and at least one start
    vals = values(best.x)
    c = predict(effects, vals, train, fit_mask=m).compliance
    return vals, c, float(best.cost)


def settings_keys(effects: list[Effect]) -> set[str]:
    """Names of the held settings of ``effects`` (the keys of their ``variants``)."""
    return {k for e in effects for v in e.variants for k in v}


#: second start of K [-] for an extension when the base model's K fell below a tenth of it (start_points)
K_RESTART = 0.6


def start_points(effects: list[Effect], base: dict[str, float], s: Series, fixed: dict[str, float]) -> list[dict]:
    """Starting points: the fitted values so far, and the product of each new parameter's starts
    (the effects' held settings, e.g. the pre-sliding form, taken from ``fixed``)."""
    held = {k: fixed[k] for k in settings_keys(effects) if k in fixed}
    first = rest_window(s)
    grids = []
    for e in effects:
        for p in e.parameters:
            if p.name in fixed:
                grids.append([(p.name, fixed[p.name])])
            elif p.rest == "replace":      # from the rest reading only (Parameter.rest)
                grids.append([(p.name, max(rest_start(p.name, s, first), 0.1))])
            elif p.rest == "extend":       # ... or also, when it lies beyond the starts
                rest = rest_start(p.name, s, first)
                grids.append([(p.name, v) for v in (*p.starts, *((rest,) if abs(rest) > max(p.starts) else ()))])
            else:
                grids.append([(p.name, v) for v in (p.starts or (p.neutral,))])
    # a base model driven to K = 0 by what it lacks (lumped dev11 1001112: a 4.2 N pretension) sits where the
    # noise band of the memory rule leaves K without a gradient: the extension also starts from a typical K
    ks = [base["K"]] + ([K_RESTART] if base["K"] < 0.1 * K_RESTART else [])
    return [{"K": k, **held, **dict(combo)} for k in ks for combo in itertools.product(*grids)]


def rest_window(s: Series) -> slice:
    """The first samples of a prepared series, taken as the initial rest before the first move (the first
    half percent, at least 3; the start values of Parameter.rest)."""
    return slice(0, max(3, len(s) // 200))


def rest_start(name: str, s: Series, first: slice) -> float:
    """The value parameter ``name`` takes if the samples ``first`` (the initial rest) read it alone: T_in
    there for a tension (the pretension T0, the T_in offset b_T_in) [N]; x_out - x_in for the x_out offset
    and x_in - x_out for the x_in offset (no elongation at rest without a pretension) [m]; nan without x_out."""
    if name in ("b_x_out", "b_x_in"):
        if s.x_out is None:
            return float("nan")
        d = float(np.median(s.x_out[first] - s.x_in[first]))
        return d if name == "b_x_out" else -d
    return float(np.median(s.T_in[first]))


def heldout_mse(pr, s: Series, k: int) -> dict[str, float]:
    return {name: float(np.mean((getattr(pr, name)[k:] - getattr(s, name)[k:]) ** 2))
            for name in SIGNALS if getattr(s, name) is not None}


def raw_rmse(pr, s: Series, data: MeasuredData, t_split: float) -> dict[str, float | None]:
    """Held-out rmse on the measured samples (predictions interpolated to the raw time base)."""
    m = data.time >= t_split
    out: dict[str, float | None] = {}
    for name, unit in (("T_out", "N"), ("x_out", "m")):
        y = getattr(data, name)
        out[f"rmse_{name}_{unit}"] = None if y is None else float(
            np.sqrt(np.mean((np.interp(data.time[m], s.time, getattr(pr, name)) - y[m]) ** 2)))
    return out


class Progress:
    """A one-line stderr bar (``enabled`` True), a callback(done, total, label), or nothing."""

    def __init__(self, total: int, enabled: bool | Callable):
        self.total, self.done, self.enabled = total, 0, enabled

    def __call__(self, label: str) -> None:
        self.done = min(self.done + 1, self.total)
        if callable(self.enabled):
            self.enabled(self.done, self.total, label)
        elif self.enabled:
            n = 30 * self.done // self.total
            sys.stderr.write(f"\rdiagnose [{'#' * n}{'.' * (30 - n)}] {self.done}/{self.total} {label:<28}")
            if self.done >= self.total:
                sys.stderr.write("\n")
            sys.stderr.flush()

    def finish(self) -> None:
        while self.done < self.total:       # the steps that were not needed
            self("done")


def trimmed_ms(r: np.ndarray, trim: float) -> float:
    """Mean square of a residual without its largest ``trim`` share: the short transients of fast moves
    (load and motor dynamics outside any quasi-static model) do not decide the model choice."""
    r2 = np.sort(r * r)
    return float(np.mean(r2[: max(1, int(round(r2.size * (1.0 - trim))))]))


def paired_trimmed_ms(r: np.ndarray, r_ref: np.ndarray, trim: float) -> tuple[float, float]:
    """Mean squares of two models' residuals on the same samples: without the largest ``trim`` share of
    min(|r|, |r_ref|), i.e. the transients that neither model explains. Returns (ms of r, ms of r_ref).

    Trimming each model by its own largest residuals (:func:`trimmed_ms`) would drop exactly what one of
    them explains when that lives in a few short events: a lagging T_out load cell on a constant-force load
    differs from the base model only at the few steps where the load leaves or lands on its stop (session 7,
    lumped dev8 seed 713111: 42 ms of lag, the base's residual 9.2 x the floor untrimmed, 1.5 x trimmed)."""
    k = max(1, int(round(r.size * (1.0 - trim))))
    keep = np.argsort(np.minimum(np.abs(r), np.abs(r_ref)), kind="stable")[:k]
    return float(np.mean(r[keep] ** 2)), float(np.mean(r_ref[keep] ** 2))


def sample_block(data: MeasuredData, t0: float, t1: float) -> dict:
    """Raw sample range [start, stop) and time range [s] of data.time in [t0, t1)."""
    i0, i1 = int(np.searchsorted(data.time, t0)), int(np.searchsorted(data.time, t1))
    return {"index": [i0, i1], "time_s": [float(data.time[min(i0, len(data) - 1)]),
                                          float(data.time[max(i1 - 1, i0)])], "n_samples": i1 - i0}


def _rest_stop(data: MeasuredData) -> int:
    """The end of the initial rest: the index of the first sample where x_in has moved by 5 um (len when never)."""
    x = np.asarray(data.x_in, dtype=float)
    moved = np.flatnonzero(np.abs(x - x[0]) > 5e-6)
    return int(moved[0]) if moved.size else len(x)


def rest_reading(data: MeasuredData, name: str) -> float:
    """|median| of a channel over the initial rest (the samples before x_in first moves by 5 um, at least 5) [unit]."""
    stop = max(_rest_stop(data), 5)
    return abs(float(np.median(np.asarray(getattr(data, name), dtype=float)[:stop])))


#: an initial rest (the samples before x_in first moves by 5 um, :func:`rest_reading`) shorter than this [s] is not
#: read for an offset: a recording that starts in motion has no rest to be zeroed at
REST_MIN_S = 0.1
#: a position channel whose initial rest reads further from zero than this many resolutions (its quantum, its
#: noise level, 1 nm) is off its zero (positions are zeroed at the initial rest, docs/formats.md)
REST_RESOLUTIONS = 3.0


def rest_offset(data: MeasuredData) -> str | None:
    """The position channel that reads away from zero at the initial rest, as the catalogue id of its offset
    (``"sensor_offset:x_in"`` or ``"sensor_offset:x_out"``; the larger reading in resolutions when both do), or None:
    no channel does, or the recording has no initial rest of REST_MIN_S (it starts moving).

    Positions are zeroed at the initial rest (docs/formats.md), and no physical effect of the catalogue moves a
    reading there (a pretension loads the rest, it does not move the encoders): a reading away from zero is an
    encoder's zero offset, read model-free (literature.md E14)."""
    stop = _rest_stop(data)
    if stop < 5 or data.time[stop - 1] - data.time[0] < REST_MIN_S:
        return None
    ratio = {}
    for name in ("x_in", "x_out"):
        a = getattr(data, name)
        if a is None:
            continue
        a = np.asarray(a, dtype=float)
        resolution = max(quantum(a), noise_level(a), 1e-9)
        ratio[f"sensor_offset:{name}"] = rest_reading(data, name) / resolution
    best = max(ratio, key=lambda k: ratio[k], default=None)
    return best if best is not None and ratio[best] > REST_RESOLUTIONS else None


def channel_choice(data: MeasuredData, eid: str) -> str:
    """Of two equivalent effects, the one the data point to: an offset on a position channel shows as a
    reading away from zero at the initial rest (positions are zeroed there); a gain is reported on
    T_out by convention (it is not separable from one on T_in)."""
    if eid in ("sensor_offset:x_in", "sensor_offset:x_out") and data.x_out is not None:
        return "sensor_offset:x_in" if rest_reading(data, "x_in") > rest_reading(data, "x_out") \
            else "sensor_offset:x_out"
    if eid in ("sensor_gain:T_in", "sensor_gain:T_out"):
        return "sensor_gain:T_out"
    return eid


def look_alike(best: str, price: dict, data: MeasuredData) -> str:
    """Pretension and a position offset both shift x_out by a constant after the first pull (by
    (L/EA) T0 or by b); when both explain the data about equally (price within 10 %), the initial
    rest decides: positions are zeroed there, so an offset shows as a reading away from zero, while
    pretension leaves them at zero. Pretension cannot move the rest reading at all, so a reading away
    from zero names the offset whenever the offset is acceptable (price < 1), however much better
    pretension fits (session 6: a constant-force load's loaded rest is explained by pretension's
    initial profile too, lumped dev6 seed 516110: offset -84 um read at rest, pretension priced 0.28,
    the offset 0.66)."""
    group = ("pretension", "sensor_offset:x_in")
    if best not in group or data.x_out is None or not all(g in price for g in group):
        return best
    other = group[1] if best == group[0] else group[0]
    tol = 3.0 * max(quantum(data.x_out), quantum(data.x_in), noise_level(np.asarray(data.x_out, dtype=float)), 1e-9)
    moved = max(rest_reading(data, "x_in"), rest_reading(data, "x_out")) > tol
    if price[other] > 1.1 * price[best]:
        return group[1] if best == group[0] and moved and price[group[1]] < 1.0 else best
    return group[1] if moved else group[0]


def toe_or_play(best: str, fits: dict[str, tuple[float, dict[str, float]]], price: dict) -> str:
    """Tendon stiffening and a distal backlash both bend x_out at low tension: a toe (extra compliance
    beta below T_c) and a dead travel. When both are acceptable (price < 1), the better validation score S
    names the cause (not the ranking's factor per extra parameter: a toe is not a backlash with one more
    parameter), unless the fitted toe is degenerate - beta at its upper bound or T_c at its lower end,
    i.e. all the toe's travel taken up at a tension within the noise: that is a dead travel, a backlash.
    ``fits``: id -> (S, fitted values). Session 6, lumped dev6: 503110 (stiffening, S 0.038) was named
    backlash (S 0.061) by the ranking; 507110 (backlash) was named stiffening at beta 20, T_c 0.08 N."""
    group = ("tendon_stiffening", "distal_backlash")
    if best not in group or not all(g in fits and g in price and price[g] < 1.0 for g in group):
        return best
    toe = fits["tendon_stiffening"][1]
    beta, t_c = effect("tendon_stiffening").parameters
    if toe.get("beta", 0.0) >= 0.9 * beta.upper or toe.get("T_c", math.inf) <= 2.0 * t_c.lower:
        return "distal_backlash"
    return min(group, key=lambda g: fits[g][0])


def predictions(result: dict, data: MeasuredData) -> dict[str, np.ndarray | None]:
    """Re-run the base and the extended model of a :func:`estimator.offline.diagnosis.diagnose` result on the
    measured samples (re-exported by estimator.offline.diagnosis).

    Returns
    -------
    dict of ndarray, shape (n_samples,) (None for a signal not recorded): ``T_out_base``,
    ``T_out_ext`` [N], ``x_out_base``, ``x_out_ext`` [m] (interpolated from the averaged series to
    ``data.time``), ``velocity`` [m/s] and ``phase`` (int8 codes of :class:`estimator.phase.Phase`,
    from the base model).
    """
    from estimator.online.distal import estimate_batch      # local: phase classification only
    from estimator.sheath import SheathModel

    st = result["settings"]
    shape = None if st.get("wrap_shape") is None else np.asarray(st["wrap_shape"], dtype=float)
    if st.get("distal_end_held"):        # x_out was not used (diagnose): no x_out prediction either
        data = replace(data, x_out=None)
    s = prepare(data, n_nodes=st["n_nodes"], target_rate=st["target_rate_hz"], wrap_shape=shape)
    out: dict[str, np.ndarray | None] = {}
    for tag, model in (("base", result["base_model"]), ("ext", result["model"])):
        pr = predict(model["effects"], model["values"], s, compliance=model["compliance"])
        for name in SIGNALS:
            out[f"{name}_{tag}"] = None if getattr(data, name) is None else np.interp(data.time, s.time,
                                                                                     getattr(pr, name))
    out["velocity"] = np.interp(data.time, s.time, s.velocity)
    base = result["base_model"]
    out["phase"] = estimate_batch(np.interp(data.time, s.time, s.T_in), data.x_in,
                                  SheathModel(K=base["values"]["K"], compliance=max(base["compliance"], 1e-12),
                                              wrap_shape=shape), time=data.time, n_nodes=st["n_nodes"]).phase
    return out
