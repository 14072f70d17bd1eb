"""The project's error hierarchy.

Every error subclasses a builtin so callers that only know the builtin still catch it.
The CLI turns any :class:`TeleopError` (and any ValueError) into a one-line message and exit code 2.
:class:`DataError` and :class:`CalibrationError` are defined by the estimator (floor 0, which imports
nothing of the rest) in :mod:`estimator.errors`; they subclass ``ValueError`` like the others.
"""
from __future__ import annotations

__all__ = ["TeleopError", "ConfigError", "CodecError", "DeviceError", "TransportError"]


class TeleopError(Exception):
    """Base class of every error this project raises on purpose."""


class ConfigError(TeleopError, ValueError):
    """A configuration file or value is wrong (unknown key, wrong type, out of range)."""


class CodecError(TeleopError, ValueError):
    """A wire message could not be decoded (short, wrong version, wrong type, non-finite)."""


class DeviceError(TeleopError, OSError):
    """A haptic device could not be found, opened, read or written."""


class TransportError(TeleopError, RuntimeError):
    """The Zenoh transport could not be opened or used."""
