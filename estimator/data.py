"""Measured data of one tendon: the arrays of a recording, in SI units (no file I/O here).

The CSV format that stores them (docs/reference/formats.md, "Measured-data CSV") is read and written by
:mod:`teleop.recording.measured`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from estimator.errors import DataError

__all__ = ["MeasuredData", "noise_level"]


def noise_level(a: np.ndarray) -> float:
    """Robust white-noise level [unit of a] of a sampled signal, shape (n,), from its second differences
    (MAD / sqrt(6): a smooth signal's own second differences are negligible at the sample rate); 0 below 5
    samples."""
    a = np.asarray(a, dtype=float)
    if a.size < 5:
        return 0.0
    d2 = a[2:] - 2.0 * a[1:-1] + a[:-2]
    return float(1.4826 * np.median(np.abs(d2 - np.median(d2))) / math.sqrt(6.0))


@dataclass(frozen=True, eq=False)
class MeasuredData:
    """One tendon's recording; every array has shape (n_samples,) and dtype float64.

    Attributes
    ----------
    time : ndarray [s], strictly increasing.
    x_in : ndarray [m], proximal tendon displacement, + = drawn toward the actuator.
    T_in : ndarray [N], proximal tension.
    x_out : ndarray [m] or None, distal displacement, same sign convention.
    T_out : ndarray [N] or None, distal tension.
    extra : dict of str -> ndarray, the other numeric columns in file order (units unknown).
    metadata : dict of str -> str, the ``# key: value`` lines.
    source : str, where the data came from (file path), used in error messages.
    """

    time: np.ndarray
    x_in: np.ndarray
    T_in: np.ndarray
    x_out: np.ndarray | None = None
    T_out: np.ndarray | None = None
    extra: dict[str, np.ndarray] = field(default_factory=dict)
    metadata: dict[str, str] = field(default_factory=dict)
    source: str = "<memory>"

    def __post_init__(self) -> None:
        n = np.shape(self.time)
        for name, arr in self.columns().items():
            if np.ndim(arr) != 1 or np.shape(arr) != n:
                raise DataError(f"{self.source}: column '{name}' has shape {np.shape(arr)}, "
                                f"expected {n} like 'time'")

    def __len__(self) -> int:
        return int(np.shape(self.time)[0])

    def columns(self) -> dict[str, np.ndarray]:
        """Every present column by name, in file order: required, optional, then extra."""
        cols = {"time": self.time, "x_in": self.x_in, "T_in": self.T_in}
        if self.x_out is not None:
            cols["x_out"] = self.x_out
        if self.T_out is not None:
            cols["T_out"] = self.T_out
        cols.update(self.extra)
        return cols

    @property
    def elongation(self) -> np.ndarray | None:
        """Tendon elongation ``x_in - x_out`` [m], shape (n_samples,), or None without ``x_out``."""
        return None if self.x_out is None else self.x_in - self.x_out

    @property
    def duration(self) -> float:
        """``time[-1] - time[0]`` [s] (0.0 for fewer than two samples)."""
        return float(self.time[-1] - self.time[0]) if len(self) >= 2 else 0.0

    def slice(self, start: int | None, stop: int | None) -> MeasuredData:
        """Samples ``start:stop`` by index (Python slice semantics, views, not copies)."""
        s = slice(start, stop)

        def cut(a):
            return None if a is None else a[s]

        return replace(self, time=self.time[s], x_in=self.x_in[s], T_in=self.T_in[s],
                       x_out=cut(self.x_out), T_out=cut(self.T_out),
                       extra={k: v[s] for k, v in self.extra.items()}, metadata=dict(self.metadata))

    def require_distal(self) -> MeasuredData:
        """Return self if ``x_out`` or ``T_out`` is present, else raise DataError naming both."""
        if self.x_out is None and self.T_out is None:
            raise DataError(f"{self.source}: needs a distal column 'x_out' or 'T_out' "
                            f"(have: {', '.join(self.columns())})")
        return self
