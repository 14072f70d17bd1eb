"""Motion protocols for the lumped simulator's recordings: what a bench operator would run.

A protocol is a proximal displacement command sampled at the recording rate, built from blocks in a
seeded random order, each block starting and ending at the rest level (so a split at a block
boundary holds out whole cycles). Moves follow a raised-cosine velocity profile (no step in the
command); "slow" and "fast" refer to the mean speed of a move. Levels are fractions ``u`` in [0, 1]
of the span from the rest position to the top position. Blocks:

* ``slow``  - one pull/release cycle at 1-4 mm/s to 50-100 % of the span, holds at the top and bottom;
* ``fast``  - the same at 12-30 mm/s;
* ``minor`` - nested minor loops: up to a, back to 30-70 % of a, up past a, part way down, down;
* ``dwell`` - a staircase up and down with 0.5-2 s holds (relaxation, creep of a bristle state);
* ``wiggle``- small sinusoidal oscillations (5-20 % of the span, 0.5-3 Hz) around a mid level;
* ``saw``   - a triangle wave of 2-4 periods between two random levels at a constant speed.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["BLOCKS", "command"]

BLOCKS = ("slow", "fast", "minor", "dwell", "wiggle", "saw")


class _Builder:
    def __init__(self, rate_hz: float, x_rest: float, x_top: float, rng: np.random.Generator):
        self.dt = 1.0 / rate_hz
        self.rest, self.top, self.rng = x_rest, x_top, rng
        self.parts: list[np.ndarray] = []
        self.x = 0.0
        self.n = 0

    def level(self, u: float) -> float:
        return self.rest + u * (self.top - self.rest)

    def _add(self, arr: np.ndarray) -> None:
        self.parts.append(arr)
        self.n += arr.size
        self.x = float(arr[-1])

    def move(self, u: float, speed: float, absolute: float | None = None) -> None:
        """Raised-cosine move to level u (or to ``absolute`` [m]) at mean speed ``speed`` [m/s]."""
        x1 = self.level(u) if absolute is None else absolute
        steps = max(2, int(math.ceil(abs(x1 - self.x) / speed / self.dt)))
        tau = np.arange(1, steps + 1) / steps
        self._add(self.x + (x1 - self.x) * 0.5 * (1.0 - np.cos(math.pi * tau)))

    def hold(self, lo: float, hi: float) -> None:
        steps = max(1, int(round(self.rng.uniform(lo, hi) / self.dt)))
        self._add(np.full(steps, self.x))

    def speed(self, lo: float, hi: float) -> float:
        return float(math.exp(self.rng.uniform(math.log(lo), math.log(hi))))


def _slow(b: _Builder, lo: float = 0.001, hi: float = 0.004) -> None:
    v = b.speed(lo, hi)
    b.move(b.rng.uniform(0.5, 1.0), v)
    b.hold(0.3, 1.5)
    b.move(0.0, v)
    b.hold(0.3, 1.5)


def _fast(b: _Builder) -> None:
    _slow(b, 0.012, 0.030)


def _minor(b: _Builder) -> None:
    v = b.speed(0.002, 0.015)
    a = b.rng.uniform(0.35, 0.7)
    b.move(a, v)
    b.hold(0.1, 0.6)
    b.move(a * b.rng.uniform(0.3, 0.7), v)
    b.hold(0.1, 0.6)
    top = b.rng.uniform(a + 0.15, 1.0)
    b.move(top, v)
    b.hold(0.1, 0.6)
    b.move(top * b.rng.uniform(0.4, 0.7), v)
    b.hold(0.1, 0.6)
    b.move(0.0, v)
    b.hold(0.3, 1.0)


def _dwell(b: _Builder) -> None:
    k = int(b.rng.integers(3, 6))
    v = b.speed(0.002, 0.02)
    for j in range(1, k + 1):
        b.move(j / k * b.rng.uniform(0.85, 1.0), v)
        b.hold(0.5, 2.0)
    for j in range(k - 1, -1, -1):
        b.move(j / k, v)
        b.hold(0.5, 2.0)


def _wiggle(b: _Builder) -> None:
    mid, amp, f = b.rng.uniform(0.35, 0.65), b.rng.uniform(0.05, 0.2), b.rng.uniform(0.5, 3.0)
    b.move(mid, b.speed(0.003, 0.015))
    n = int(round(int(b.rng.integers(3, 9)) / f / b.dt))
    t = np.arange(1, n + 1) * b.dt
    b._add(b.level(mid) + amp * (b.top - b.rest) * np.sin(2 * math.pi * f * t))
    b.move(0.0, b.speed(0.003, 0.015))
    b.hold(0.3, 1.0)


def _saw(b: _Builder) -> None:
    lo = b.rng.uniform(0.0, 0.4)
    hi = b.rng.uniform(lo + 0.3, 1.0)
    v = b.speed(0.002, 0.02)
    b.move(lo, v)
    for _ in range(int(b.rng.integers(2, 5))):
        for u in (hi, lo):
            x1 = b.level(u)
            steps = max(2, int(math.ceil(abs(x1 - b.x) / v / b.dt)))
            b._add(np.linspace(b.x, x1, steps + 1)[1:])
    b.move(0.0, v)
    b.hold(0.3, 1.0)


_KINDS = {"slow": _slow, "fast": _fast, "minor": _minor, "dwell": _dwell, "wiggle": _wiggle, "saw": _saw}


def command(duration: float, rate_hz: float, x_rest: float, x_top: float, rng: np.random.Generator,
            blocks: tuple[str, ...] = BLOCKS) -> np.ndarray:
    """Proximal displacement command [m], shape (round(duration * rate_hz),), starting at 0.

    A 0.5-1 s hold at 0 (where the encoders are zeroed), a slow take-up to ``x_rest`` [m], then
    shuffled ``blocks`` between ``x_rest`` and ``x_top`` [m] until ``duration`` [s] is filled (the
    last block is cut).

    Raises
    ------
    ValueError
        ``duration`` or ``rate_hz`` not > 0, ``x_top`` not above ``x_rest``, or an unknown block.
    """
    if not (duration > 0 and rate_hz > 0):
        raise ValueError(f"duration and rate_hz must be > 0, got {duration!r} s, {rate_hz!r} Hz")
    if not x_top > x_rest:
        raise ValueError(f"x_top must exceed x_rest, got {x_top!r} <= {x_rest!r} m")
    for k in blocks:
        if k not in _KINDS:
            raise ValueError(f"unknown protocol block {k!r}; expected some of {BLOCKS}")
    n = int(round(duration * rate_hz))
    b = _Builder(rate_hz, x_rest, x_top, rng)
    b.hold(0.5, 1.0)
    if x_rest != 0.0:
        b.move(0.0, 0.002)
        b.hold(0.3, 0.6)
    while b.n < n:
        for j in rng.permutation(len(blocks)):
            _KINDS[blocks[j]](b)
    return np.concatenate(b.parts)[:n]
