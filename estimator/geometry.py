"""Sheath geometry: the route of a sheath as straight runs and circular arcs, proximal to distal.

The friction exponent of a route is K = mu * total bend angle (Phee et al. 2009, eq. (2)); the normalised wrap angle
along it shapes the tension profile of :class:`estimator.sheath.SheathModel`. Plain numpy: a process that only reads a
configuration (the master, the recorder) loads no compiled code for it.
"""
from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

__all__ = ["Run", "SheathGeometry"]


@dataclass(frozen=True)
class Run:
    """One piece of the sheath route.

    Parameters
    ----------
    length : float
        Arc length of the piece [m], > 0.
    radius : float
        Bend radius [m], > 0; ``math.inf`` for a straight run.
    """

    length: float
    radius: float = math.inf

    def __post_init__(self) -> None:
        if not (math.isfinite(self.length) and self.length > 0):
            raise ValueError(f"sheath run length must be a positive number of metres, got {self.length!r}")
        if not (self.radius > 0) or math.isnan(self.radius):
            raise ValueError(f"sheath run bend radius must be > 0 m (inf for straight), got {self.radius!r}")

    @property
    def angle(self) -> float:
        """Bend angle of the piece [rad] = length / radius (0 for a straight run)."""
        return 0.0 if math.isinf(self.radius) else self.length / self.radius


class SheathGeometry:
    """The route of a sheath as straight runs and arcs, proximal to distal.

    K = mu * sum_i (x_i - x_{i-1}) / R_i  (Phee et al. 2009, eq. (2)) is ``mu * total_angle``.

    Parameters
    ----------
    runs : sequence of Run or of (length [m], radius [m]) pairs
        At least one piece.

    Raises
    ------
    ValueError
        No pieces, or a piece with a non-positive length or radius.
    """

    def __init__(self, runs: Iterable[Run | tuple[float, float]]):
        pieces = [r if isinstance(r, Run) else Run(*r) for r in runs]
        if not pieces:
            raise ValueError("a sheath needs at least one run")
        self.runs: tuple[Run, ...] = tuple(pieces)
        self._ends = np.cumsum([r.length for r in pieces])
        self._angles = np.array([r.angle for r in pieces])

    @classmethod
    def uniform(cls, length: float, total_angle: float) -> SheathGeometry:
        """One arc of constant curvature (or a straight run when ``total_angle`` is 0) [m, rad]."""
        if total_angle < 0:
            raise ValueError(f"total bend angle must be >= 0 rad, got {total_angle}")
        radius = math.inf if total_angle == 0 else length / total_angle
        return cls([Run(length, radius)])

    @property
    def length(self) -> float:
        """Total sheath length L [m]."""
        return float(self._ends[-1])

    @property
    def total_angle(self) -> float:
        """Total wrap angle sum(theta_i) [rad]."""
        return float(self._angles.sum())

    def curvature(self, s: np.ndarray | float) -> np.ndarray:
        """Curvature kappa(s) [1/m] at arc positions ``s`` [m] (shape preserved), measured from the proximal end."""
        s = np.asarray(s, dtype=float)
        idx = np.clip(np.searchsorted(self._ends, s, side="right"), 0, len(self.runs) - 1)
        kappa = np.array([0.0 if math.isinf(r.radius) else 1.0 / r.radius for r in self.runs])
        return kappa[idx]

    def wrap_angle(self, s: np.ndarray | float) -> np.ndarray:
        """Cumulative wrap angle theta(s) = int_0^s kappa [rad] at arc positions ``s`` [m] (exact, piecewise linear)."""
        s_arr = np.clip(np.asarray(s, dtype=float), 0.0, self.length)
        starts = np.concatenate(([0.0], self._ends[:-1]))
        lengths = self._ends - starts
        # fraction of each piece covered up to s, broadcast over pieces: shape (..., n_runs)
        frac = np.clip((s_arr[..., None] - starts) / lengths, 0.0, 1.0)
        return frac @ self._angles

    def describe(self) -> str:
        """One-line summary, e.g. for logs."""
        return f"L = {self.length:.3f} m, total bend {math.degrees(self.total_angle):.1f} deg in {len(self.runs)} runs"
