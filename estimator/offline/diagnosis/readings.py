"""Model-free readings of a recording that the diagnosis's rules use (:mod:`estimator.offline.diagnosis.selection`).

Each reads one physical symptom straight from the measured samples, without a fit:

* :func:`stick_slip_ratio`: how much rougher the proximal tension is in steady moves than in holds (stick-slip);
* :func:`holds_release`: whether a block's proximal tension falls from its maximum (what shows the route's shape);
* :func:`distal_end_held`, :func:`distal_at_end`: a distal end that never moves, or sits on a stop;
* :func:`rest_reading`, :func:`rest_offset`: an encoder reading away from zero at the initial rest;
* :func:`channel_choice`, :func:`look_alike`, :func:`toe_or_play`: which of two look-alike effects the data
  point to;
* :func:`rest_tension`: a tension both load cells read alike at the initial rest (a pretension, not an encoder);
* :func:`speed_or_lag`: whether the distal tension's departure in slip grows with the sliding speed (velocity
  friction) or follows its own rate of change a fixed time late (a load-cell lag).

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
           "rest_offset", "channel_choice", "look_alike", "toe_or_play", "rest_tension", "speed_or_lag"]


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



def rest_tension(data: MeasuredData) -> dict | None:
    """What the two load cells read at the initial rest, and whether it is a pretension.

    A pretension is tension the tendon carries at rest, so both load cells read it (alike, or within the capstan
    ratio e^K that friction holds when the load settled against the preload) while the encoders, zeroed at that
    rest, read zero. An encoder offset moves no tension and shifts its position channel at every tension, the rest
    included; a load-cell offset reads on one channel only. The reading: the medians of T_in and T_out over the initial
    rest (the samples before x_in first moves by 5 um) in their noise sigmas (noise or quantisation, whichever is
    larger).

    Parameters
    ----------
    data : MeasuredData with time [s], T_in [N] and T_out [N]

    Returns
    -------
    dict or None
        {"T_in_N", "T_out_N": the rest medians [N], "sigmas": the smaller of the two in its noise sigmas [-],
        "pretension": both at least REST_TENSION_SIGMAS and within a factor REST_TENSION_RATIO of each other};
        None without T_out or without an initial rest of REST_MIN_S.
    """
    if data.T_out is None:
        return None
    stop = _rest_stop(data)
    if stop < 5 or data.time[stop - 1] - data.time[0] < th.REST_MIN_S:
        return None
    med, sig = {}, {}
    for name in ("T_in", "T_out"):
        a = np.asarray(getattr(data, name), dtype=float)
        med[name] = float(np.median(a[:stop]))
        sig[name] = max(noise_level(a), quantum(a), 1e-9)
    sigmas = min(med[n] / sig[n] for n in med)
    agree = max(med["T_in"], med["T_out"]) <= th.REST_TENSION_RATIO * min(med["T_in"], med["T_out"])
    return {"T_in_N": med["T_in"], "T_out_N": med["T_out"], "sigmas": sigmas,
            "pretension": bool(sigmas >= th.REST_TENSION_SIGMAS and agree)}


def speed_or_lag(data: MeasuredData) -> dict | None:
    """Whether the distal tension's departure from the capstan ratio in slip grows with the sliding speed or lags.

    In slip the capstan law holds z = s (ln T_in - ln T_out) = K on both branches (s the sign of the proximal
    motion: the pull and the release). Velocity friction, mu (1 + c_v |v|), adds K c_v |v|: it grows with the
    sliding speed and vanishes at rest, whatever the tension does. A distal load cell late by tau reads T_out(t - tau)
    and adds tau |d ln T_out / dt|: every change read a fixed time late, whatever the speed - on a stiff load a small
    move late by tau departs as much as a fast one on a soft load, and at the tension of a constant load nothing
    departs at any speed. Both grow with speed on one load, but in proportion to |v| against |v| k / T (k the load's
    stiffness): over the tensions and loads of a recording they separate. The reading regresses z on the
    slip samples (|v| above HAND_SLIP_SPEED, T_in and T_out moving with the proximal end, the distal
    rate within a factor 2 of the proximal one, both tensions above 10 noise sigmas; weights T_out / sigma) on a
    constant per branch, |v| and |d ln T_out / dt| (Savitzky-Golay derivatives over HAND_WINDOW).

    Parameters
    ----------
    data : MeasuredData with time [s], x_in [m], T_in [N], T_out [N]

    Returns
    -------
    dict or None
        {"speed": c_v K [s/m], "delay": tau [s], "K": the mean of the two intercepts [-], "n": slip samples,
        "moving_s": their time [s], "speed_t", "delay_t": each term over its standard error [-]}; None without T_out
        or with fewer than HAND_MIN_SLIP_S seconds of slip. The standard errors treat each stretch of slip (runs of
        slip samples less than a window apart) as one observation: the smoothing and the load's own motion correlate
        the samples of one move, not those of two.
    """
    from scipy.signal import savgol_filter

    if data.T_out is None:
        return None
    t, x, T_in, T_out = (np.asarray(a, dtype=float) for a in (data.time, data.x_in, data.T_in, data.T_out))
    if t.size < 50:
        return None
    dt = float(np.median(np.diff(t)))
    w = max(7, int(round(th.HAND_WINDOW / dt)) | 1)
    if w >= t.size:
        return None
    sig_in = max(noise_level(T_in), quantum(T_in), 1e-9)
    sig_out = max(noise_level(T_out), quantum(T_out), 1e-9)
    Ti, To = savgol_filter(T_in, w, 2), savgol_filter(T_out, w, 2)
    v = savgol_filter(x, w, 2, deriv=1, delta=dt)
    di, do = savgol_filter(T_in, w, 2, deriv=1, delta=dt), savgol_filter(T_out, w, 2, deriv=1, delta=dt)
    s = np.sign(v)
    ok = ((np.abs(v) > th.HAND_SLIP_SPEED) & (Ti > 10.0 * sig_in) & (To > 10.0 * sig_out)
          & (np.sign(di) == s) & (np.sign(do) == s))
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = (do / To) / (di / Ti)
    ok &= (ratio > 0.5) & (ratio < 2.0)
    n = int(ok.sum())
    if n * dt < th.HAND_MIN_SLIP_S:
        return None
    z = s[ok] * (np.log(Ti[ok]) - np.log(To[ok]))
    pull = (s[ok] > 0).astype(float)
    A = np.column_stack((pull, 1.0 - pull, np.abs(v[ok]), np.abs(do[ok] / To[ok])))
    keep = A[:, :2].sum(axis=0) > 0
    A = np.column_stack((A[:, :2][:, keep], A[:, 2:]))
    wt = To[ok] / sig_out
    X, y = A * wt[:, None], z * wt
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    se = _stretch_errors(X, y - X @ coef, np.flatnonzero(ok), w)
    return {"speed": float(coef[-2]), "delay": float(coef[-1]), "K": float(np.mean(coef[:-2])), "n": n,
            "moving_s": n * dt, "speed_t": float(coef[-2] / se[-2]), "delay_t": float(coef[-1] / se[-1])}


def _stretch_errors(X: np.ndarray, e: np.ndarray, index: np.ndarray, gap: int) -> np.ndarray:
    """Standard errors of a least-squares fit whose residuals ``e`` correlate within a stretch of samples: the
    sandwich estimate with one cluster per stretch (sample indices ``index`` less than ``gap`` apart), scaled by
    G / (G - 1) for G stretches. (p,) [units of the coefficients]; inf where a coefficient is not determined."""
    stretch = np.concatenate(([0], np.cumsum(np.diff(index) >= gap)))
    bread = np.linalg.pinv(X.T @ X)
    scores = np.zeros((int(stretch[-1]) + 1, X.shape[1]))
    np.add.at(scores, stretch, X * e[:, None])
    groups = scores.shape[0]
    var = np.diag(bread @ (scores.T @ scores) @ bread) * groups / max(groups - 1, 1)
    return np.where(var > 0.0, np.sqrt(np.maximum(var, 0.0)), np.inf)
