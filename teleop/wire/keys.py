"""Zenoh key expressions of the project: ``teleop/<instrument>/<side>/<stream>``.

The only place key strings are spelled. Streams and who publishes them::

    teleop/<id>/master/command     Command    master -> slave
    teleop/<id>/slave/estimate     Estimate   slave  -> master
    teleop/<id>/<side>/heartbeat   Heartbeat  each side -> the other
    teleop/<id>/<side>/alive       liveliness token of each side's process

``<id>`` is the instrument id from the config (``instrument.id``), letters, digits, ``_`` and ``-``
only, so it can never smuggle a ``/`` or a wildcard into a key.
"""
from __future__ import annotations

import re

from teleop.errors import ConfigError
from teleop.wire.messages import Side

__all__ = [
    "ROOT", "STREAMS", "SIDES", "LIVELINESS", "RIG_STREAMS", "validate_instrument_id", "side_name", "key", "rig_key",
    "command_key", "estimate_key", "heartbeat_key", "liveliness_key", "liveliness_pattern",
    "instrument_keys", "parse_key", "run_key",
]

ROOT = "teleop"
STREAMS = ("command", "estimate", "heartbeat")
SIDES = ("master", "slave")
LIVELINESS = "alive"

_ID = re.compile(r"[A-Za-z0-9_-]+")
# which side publishes which stream
_PUBLISHERS = {"command": ("master",), "estimate": ("slave",), "heartbeat": SIDES}


def validate_instrument_id(instrument: str, *, where: str = "instrument.id") -> str:
    """Return ``instrument`` if it is a valid key segment.

    Parameters
    ----------
    instrument : str
        Instrument id, non-empty, characters ``[A-Za-z0-9_-]`` only.
    where : str
        What to name in the error message (a config key, a CLI flag).

    Raises
    ------
    ConfigError
        Not a string, empty, or with another character (``/``, ``*``, space, ...).
    """
    if not isinstance(instrument, str) or not _ID.fullmatch(instrument):
        raise ConfigError(f"{where}: {instrument!r} is not a valid instrument id "
                          f"(expected letters, digits, '_' or '-' only, at least one)")
    return instrument


def side_name(side: Side | str) -> str:
    """``"master"`` or ``"slave"`` for a :class:`Side` or its name (any case).

    Raises
    ------
    ConfigError
        Anything else.
    """
    if isinstance(side, Side):
        return side.name.lower()
    if isinstance(side, str) and side.lower() in SIDES:
        return side.lower()
    raise ConfigError(f"side: {side!r} is not a side (expected one of {', '.join(SIDES)})")


def key(instrument: str, side: Side | str, stream: str) -> str:
    """The key of one stream: ``teleop/<instrument>/<side>/<stream>``.

    Raises
    ------
    ConfigError
        Invalid instrument id, unknown side or stream, or a stream that side does not publish
        (commands come from the master, estimates from the slave).
    """
    validate_instrument_id(instrument)
    s = side_name(side)
    if stream not in STREAMS:
        raise ConfigError(f"stream: {stream!r} is not a stream (expected one of {', '.join(STREAMS)})")
    if s not in _PUBLISHERS[stream]:
        raise ConfigError(f"stream: the {s} does not publish {stream!r} "
                          f"(only the {' and '.join(_PUBLISHERS[stream])})")
    return f"{ROOT}/{instrument}/{s}/{stream}"


def command_key(instrument: str) -> str:
    """``teleop/<instrument>/master/command``: Command, master -> slave."""
    return key(instrument, "master", "command")


def estimate_key(instrument: str) -> str:
    """``teleop/<instrument>/slave/estimate``: Estimate, slave -> master."""
    return key(instrument, "slave", "estimate")


RIG_STREAMS = ("setpoint", "sample")


def rig_key(instrument: str, stream: str) -> str:
    """The key of the rig interface (:mod:`teleop.wire.rig`): ``teleop/<instrument>/rig/<setpoint|sample>``.

    Raises
    ------
    ConfigError
        Invalid instrument id or unknown stream.
    """
    validate_instrument_id(instrument)
    if stream not in RIG_STREAMS:
        raise ConfigError(f"rig stream: {stream!r} is not one of {', '.join(RIG_STREAMS)}")
    return f"{ROOT}/{instrument}/rig/{stream}"


def heartbeat_key(instrument: str, side: Side | str) -> str:
    """``teleop/<instrument>/<side>/heartbeat``: Heartbeat of that side."""
    return key(instrument, side, "heartbeat")


def liveliness_key(instrument: str, side: Side | str) -> str:
    """``teleop/<instrument>/<side>/alive``: the liveliness token of that side's process."""
    validate_instrument_id(instrument)
    return f"{ROOT}/{instrument}/{side_name(side)}/{LIVELINESS}"


def liveliness_pattern(instrument: str) -> str:
    """``teleop/<instrument>/*/alive``: the liveliness tokens of both sides (for monitors)."""
    validate_instrument_id(instrument)
    return f"{ROOT}/{instrument}/*/{LIVELINESS}"


def instrument_keys(instrument: str) -> str:
    """``teleop/<instrument>/**``: every key of one instrument (for recorders and monitors)."""
    validate_instrument_id(instrument)
    return f"{ROOT}/{instrument}/**"


def parse_key(key_expr: str) -> tuple[str, Side, str]:
    """Split a concrete key into ``(instrument, side, stream_or_alive)``.

    Raises
    ------
    ConfigError
        Not a key of this project (wrong root, wrong number of segments, unknown side or stream).
    """
    parts = str(key_expr).split("/")
    if len(parts) != 4 or parts[0] != ROOT or parts[3] not in STREAMS + (LIVELINESS,):
        raise ConfigError(f"key {key_expr!r} is not {ROOT}/<instrument>/<side>/<stream>")
    instrument, side, stream = parts[1], side_name(parts[2]), parts[3]
    validate_instrument_id(instrument, where=f"key {key_expr!r}")
    return instrument, Side[side.upper()], stream


def run_key(instrument: str) -> str:
    """``teleop/<instrument>/run``: queryable answering the run id the processes of a session share
    (:mod:`live.discovery`)."""
    validate_instrument_id(instrument)
    return f"{ROOT}/{instrument}/run"
