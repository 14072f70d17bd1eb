"""Errors raised by the estimator (floor 0: it imports nothing else of this project).

Both subclass :class:`ValueError`, so callers that only know the builtin still catch them;
the rest of the project's hierarchy is :mod:`teleop.errors`.
"""
from __future__ import annotations

__all__ = ["EstimatorError", "CalibrationError", "DataError"]


class EstimatorError(Exception):
    """Base class of the errors the estimator raises on purpose."""


class CalibrationError(EstimatorError, ValueError):
    """A calibration could not be computed from the given recording (or read from its file)."""


class DataError(EstimatorError, ValueError):
    """Measured data are wrong (missing column, NaN, non-increasing time, wrong shape, ...)."""
