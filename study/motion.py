"""Operator-like proximal motion for the simulators' recordings: what a hand on a master device makes.

A bench protocol (:func:`study.scenarios.protocol`, :func:`study.lumped.protocol.command`) runs designed cycles at a
few set speeds; an operator moves the instrument in goal-directed moves of random amplitude and speed, reverses
part way, pauses, and returns to rest now and then. :func:`hand_motion` makes such a command, seeded:

* a 0.5-1 s hold at 0 (where the encoders are zeroed) and a slow take-up to the rest level;
* then moves to random levels of the span (a quarter of them back to rest), each a minimum-jerk profile at a peak
  speed log-uniform in 2-25 mm/s, about a third of them reversed part way; between moves a hold of 0.1-1.5 s
  (a third of them under 0.2 s: a hand hesitates more than it stops);
* a band-limited wobble (white noise low-passed at 1-3 Hz, a few per cent of the span) on top of the moves
  only, as a hand that does not move in straight lines; the holds stay still;
* the whole limited to ``v_max`` (25 mm/s by default) and kept within the span.

Levels are fractions ``u`` of the span from the rest position ``x_rest`` to the top position ``x_top`` [m].
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["HAND_SPEED", "hand_motion"]

#: [m/s] the fastest an operator's hand drives the proximal end here (peak speed of a move)
HAND_SPEED = 0.025


def _min_jerk(x0: float, x1: float, v_peak: float, dt: float) -> np.ndarray:
    """A minimum-jerk move from x0 to x1 [m] with peak speed ``v_peak`` [m/s], sampled at ``dt`` [s] (x0 excluded)."""
    duration = max(1.875 * abs(x1 - x0) / v_peak, 2 * dt)
    tau = np.arange(1, int(math.ceil(duration / dt)) + 1) * dt / duration
    tau = np.minimum(tau, 1.0)
    return x0 + (x1 - x0) * (10 * tau ** 3 - 15 * tau ** 4 + 6 * tau ** 5)


def _wobble(n: int, dt: float, rng: np.random.Generator) -> np.ndarray:
    """Band-limited noise, shape (n,): white noise through a second-order low-pass at 1-3 Hz, unit rms."""
    from scipy.signal import butter, sosfiltfilt

    fc = float(rng.uniform(1.0, 3.0))
    sos = butter(2, min(fc * 2.0 * dt, 0.9), output="sos")
    w = sosfiltfilt(sos, rng.standard_normal(n + 200))[100:100 + n]
    return w / max(float(np.std(w)), 1e-12)


def _rate_limit(x: np.ndarray, v_max: float, dt: float) -> np.ndarray:
    """``x`` followed at most ``v_max`` [m/s] fast: y[k] = y[k-1] + clip(x[k] - y[k-1], +- v_max dt)."""
    y = np.empty_like(x)
    step = v_max * dt
    prev = float(x[0])
    for k, target in enumerate(x):
        prev += min(max(float(target) - prev, -step), step)
        y[k] = prev
    return y


def hand_motion(duration: float, rate_hz: float, x_rest: float, x_top: float, rng: np.random.Generator,
                v_max: float = HAND_SPEED) -> np.ndarray:
    """Proximal displacement command [m], shape (round(duration * rate_hz),), starting at 0 (module docstring).

    Parameters
    ----------
    duration : float > 0 [s]; rate_hz : float > 0 [Hz]
    x_rest, x_top : float [m], the rest and the top of the span, x_top > x_rest
    rng : numpy Generator (every random choice)
    v_max : float > 0 [m/s], the fastest the command moves

    Raises
    ------
    ValueError
        ``duration``, ``rate_hz`` or ``v_max`` not > 0, or ``x_top`` not above ``x_rest``.
    """
    if not (duration > 0 and rate_hz > 0 and v_max > 0):
        raise ValueError(f"duration, rate_hz and v_max must be > 0, got {duration!r} s, {rate_hz!r} Hz, {v_max!r} m/s")
    if not x_top > x_rest:
        raise ValueError(f"x_top must exceed x_rest, got {x_top!r} <= {x_rest!r} m")
    dt, n = 1.0 / rate_hz, int(round(duration * rate_hz))
    span = x_top - x_rest
    parts = [np.zeros(max(1, int(round(rng.uniform(0.5, 1.0) / dt))))]
    if x_rest != 0.0:
        parts.append(_min_jerk(0.0, x_rest, 0.002, dt))
        parts.append(np.full(max(1, int(round(rng.uniform(0.3, 0.6) / dt))), x_rest))
    n_rest = sum(p.size for p in parts)
    moving = [np.zeros(n_rest, dtype=bool)]
    x, count = x_rest, n_rest
    while count < n:
        u = 0.0 if rng.random() < 0.25 else float(rng.uniform(0.1, 1.0))
        v = float(math.exp(rng.uniform(math.log(0.002), math.log(v_max))))
        target = x_rest + u * span
        if rng.random() < 0.35:           # reversed part way: a correction before the goal
            seg = _min_jerk(x, x + rng.uniform(0.3, 0.8) * (target - x), v, dt)
        else:
            seg = _min_jerk(x, target, v, dt)
        hold = rng.uniform(0.1, 0.2) if rng.random() < 0.33 else rng.uniform(0.2, 1.5)
        rest = np.full(max(1, int(round(hold / dt))), float(seg[-1]))
        parts += [seg, rest]
        moving += [np.ones(seg.size, dtype=bool), np.zeros(rest.size, dtype=bool)]
        x, count = float(seg[-1]), count + seg.size + rest.size
    cmd, on = np.concatenate(parts)[:n], np.concatenate(moving)[:n]
    envelope = np.convolve(on.astype(float), np.ones(max(1, int(0.1 / dt))) / max(1, int(0.1 / dt)), mode="same")
    cmd = cmd + float(rng.uniform(0.01, 0.04)) * span * envelope * _wobble(n, dt, rng)
    cmd[n_rest:] = np.clip(cmd[n_rest:], x_rest, x_top)
    cmd[:n_rest] = np.concatenate(parts)[:n_rest][:n]
    return _rate_limit(cmd, v_max, dt)
