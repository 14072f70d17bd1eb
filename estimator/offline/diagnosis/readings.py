"""Model-free readings of a recording that the diagnosis's rules use (:mod:`estimator.offline.diagnosis.selection`).

Each reads one physical symptom straight from the measured samples, without a fit:

* :func:`stick_slip_ratio`: how much rougher the proximal tension is in steady moves than in holds (stick-slip);
* :func:`holds_release`: whether a block's proximal tension falls from its maximum (what shows the route's shape);
* :func:`distal_end_held`, :func:`distal_at_end`: a distal end that never moves, or sits on a stop;
* :func:`rest_reading`, :func:`rest_offset`: an encoder reading away from zero at the initial rest;
* :func:`channel_choice`, :func:`look_alike`, :func:`toe_or_play`: which of two look-alike effects the data
  point to.

The numbers they use are in :mod:`estimator.offline.diagnosis.thresholds`.
"""
from __future__ import annotations

import math

import numpy as np

from estimator.data import MeasuredData, noise_level
from estimator.offline.diagnosis import thresholds as th
from estimator.offline.diagnosis.fit import quantum
from estimator.offline.effects.catalogue import effect

__all__ = ["holds_release", "stick_slip_ratio", "distal_end_held", "distal_at_end", "sample_block", "rest_reading",
           "rest_offset", "channel_choice", "look_alike", "toe_or_play"]


def _smoothed_speed(t: np.ndarray, x: np.ndarray, max_window: int | None = None) -> tuple[np.ndarray, float, int]:
    """|dx/dt| from a quadratic Savitzky-Golay derivative over STICK_SLIP_WINDOW (at least 7 samples, odd, at most
    ``max_window``), with the median sample interval and the window: (speed (n,) [m/s], dt [s], window [samples])."""
    from scipy.signal import savgol_filter

    dt = float(np.median(np.diff(t)))
    w = max(7, int(round(th.STICK_SLIP_WINDOW / dt)) | 1)
    if max_window is not None:
        w = min(w, max_window - (1 - max_window % 2))
    return np.abs(savgol_filter(x, w, 2, deriv=1, delta=dt)), dt, w



def holds_release(T_in: np.ndarray, share: float = th.RELEASE_SHARE) -> bool:
    """Whether the proximal tension of a block falls from its running maximum by at least ``share`` of its range
    (a reversal the slip front then crosses: what shows the route's shape; docs/concepts/effects.md).

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
    """How much rougher the proximal tension is in steady moves than in holds (stick-slip, docs/concepts/effects.md).

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
    if t.size < 2 * th.STICK_SLIP_MIN_SAMPLES:
        return None
    v, dt, w = _smoothed_speed(t, x)
    moving = minimum_filter1d(v, 3 * w) > th.STICK_SLIP_SPEED
    hold = v < th.STICK_SLIP_HOLD
    n_move, n_hold = int(moving.sum()), int(hold.sum())
    if (min(n_move, n_hold) < th.STICK_SLIP_MIN_SAMPLES or n_move * dt < th.STICK_SLIP_MIN_MOVE
            or n_hold * dt < th.STICK_SLIP_MIN_HOLD):
        return None
    r = np.abs(y - savgol_filter(y, w, 2))
    return float(np.median(r[moving]) / max(float(np.median(r[hold])), 0.25 * quantum(y), 1e-12))



def distal_end_held(data: MeasuredData, share: float = th.HELD_SHARE) -> dict | None:
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
    if span <= max(th.HELD_STEPS * step, share * travel):
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
    moving = speed > th.AT_END_SPEED
    travel = float(np.sum(speed[moving]) * dt)
    if travel <= 0.0:
        return None
    low, high = (float(v) for v in np.percentile(x_out, (0.5, 99.5)))
    band = max(th.HELD_STEPS * max(quantum(x_out), noise_level(x_out)), th.AT_END_BAND * (high - low))
    at_end = (np.abs(x_out - high) <= band) | (np.abs(x_out - low) <= band)
    share = float(np.sum(speed[moving & at_end]) * dt / travel)
    return {"share": share, "band_m": band, "range_m": high - low,
            "hides": list(th.AT_END_HIDES) if share >= th.AT_END_SHARE else []}


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


def rest_offset(data: MeasuredData) -> str | None:
    """The position channel that reads away from zero at the initial rest, as the catalogue id of its offset
    (``"sensor_offset:x_in"`` or ``"sensor_offset:x_out"``; the larger reading in resolutions when both do), or None:
    no channel does, or the recording has no initial rest of REST_MIN_S (it starts moving).

    Positions are zeroed at the initial rest (docs/reference/formats.md), and no physical effect of the catalogue
    moves a reading there (a pretension loads the rest, it does not move the encoders): a reading away from zero is an
    encoder's zero offset, read model-free (docs/concepts/effects.md)."""
    stop = _rest_stop(data)
    if stop < 5 or data.time[stop - 1] - data.time[0] < th.REST_MIN_S:
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
    return best if best is not None and ratio[best] > th.REST_RESOLUTIONS else None


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
    pretension fits (a constant-force load's loaded rest is explained by pretension's initial profile
    too)."""
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
    ``fits``: id -> (S, fitted values)."""
    group = ("tendon_stiffening", "distal_backlash")
    if best not in group or not all(g in fits and g in price and price[g] < 1.0 for g in group):
        return best
    toe = fits["tendon_stiffening"][1]
    beta, t_c = effect("tendon_stiffening").parameters
    if toe.get("beta", 0.0) >= 0.9 * beta.upper or toe.get("T_c", math.inf) <= 2.0 * t_c.lower:
        return "distal_backlash"
    return min(group, key=lambda g: fits[g][0])

