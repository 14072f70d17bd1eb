"""The project's error hierarchy.

Every error subclasses a builtin so callers that only know the builtin still catch it.
The CLI turns any :class:`TeleopError` into a one-line message and exit code 2.
"""
from __future__ import annotations


class TeleopError(Exception):
    """Base class of every error this project raises on purpose."""


class ConfigError(TeleopError, ValueError):
    """A configuration file or value is wrong (unknown key, wrong type, out of range)."""


class DataError(TeleopError, ValueError):
    """A measured-data file is wrong (missing column, NaN, non-increasing time, ...)."""


class CalibrationError(TeleopError, ValueError):
    """A calibration could not be computed from the given recording."""


class CodecError(TeleopError, ValueError):
    """A wire message could not be decoded (short, wrong version, wrong type, non-finite)."""


class DeviceError(TeleopError, OSError):
    """A haptic device could not be found, opened, read or written."""


class TransportError(TeleopError, RuntimeError):
    """The Zenoh transport could not be opened or used."""
