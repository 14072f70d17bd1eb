"""The rig interface on the wire: motor set-points to a rig, sensor samples back (the ``zenoh`` rig).

The slave's :class:`slave.zenoh_rig.ZenohRig` publishes a :class:`RigSetpoint` every cycle on
``teleop/<instrument>/rig/setpoint``; whatever drives the motors - a motor controller running
zenoh-pico, or ``teleop bridge`` with the simulated rig - answers with a :class:`RigSample` per
cycle on ``teleop/<instrument>/rig/sample``. Little-endian, fixed layout, its own magic byte so that
a teleop message is never taken for a rig message::

    offset 0  uint8  RIG_MAGIC (0xB5)
    offset 1  uint8  RIG_VERSION (1)
    offset 2  uint8  type: 1 RigSetpoint, 2 RigSample

    RigSetpoint (14 + 8 n bytes after the header), n = tendons, 1..MAX_TENDONS
        uint32 seq | float64 t [s] | int8 tissue (-1 keep, 0 off, 1 on; simulated rigs) | uint8 n
        | float64 x_in_cmd[n] [m]
    RigSample (18 + 24 n (+ 40 n) bytes after the header)
        uint32 seq | uint32 setpoint_seq | float64 t [s] | uint8 n | uint8 truth (0/1)
        | n x (float64 x_in [m] | float64 T_in [N] | float64 x_in_cmd [m])             encoder, load cell
        | truth: n x (float64 T_in [N] | T_out [N] | x_in [m] | x_out [m] | elongation [m])

Every float must be finite both ways; a buffer decodes only with exactly the length it implies.
"""
from __future__ import annotations

import math
import struct
from dataclasses import dataclass

from teleop.errors import CodecError

__all__ = ["RIG_MAGIC", "RIG_VERSION", "MAX_TENDONS", "RigSetpoint", "RigSample", "encode_rig", "decode_rig"]

RIG_MAGIC = 0xB5
RIG_VERSION = 1
MAX_TENDONS = 16
_HEADER = struct.Struct("<BBB")
_SETPOINT = struct.Struct("<IdbB")
_SAMPLE = struct.Struct("<IIdBB")
_TYPE_SETPOINT, _TYPE_SAMPLE = 1, 2


@dataclass(frozen=True)
class RigSetpoint:
    """Slave -> rig: seq (uint32), t [s] (slave clock), x_in_cmd [m] per tendon, tissue switch of a
    simulated rig (-1 keep, 0 off, 1 on)."""

    seq: int
    t: float
    x_in_cmd: tuple[float, ...]
    tissue: int = -1


@dataclass(frozen=True)
class RigSample:
    """Rig -> slave: seq, the seq of the set-point applied, t [s] (rig clock), per tendon encoder x_in
    [m], load cell T_in [N] and the applied x_in_cmd [m]; ``truth`` empty, or per tendon (T_in, T_out,
    x_in, x_out, elongation) of a simulator (evaluation only)."""

    seq: int
    setpoint_seq: int
    t: float
    x_in: tuple[float, ...]
    T_in: tuple[float, ...]
    x_in_cmd: tuple[float, ...]
    truth: tuple[tuple[float, float, float, float, float], ...] = ()


def _finite(kind: str, values) -> None:
    if not all(math.isfinite(v) for v in values):
        raise CodecError(f"{kind}: every float on the wire must be finite, got {list(values)}")


def _count(kind: str, n: int) -> None:
    if not 1 <= n <= MAX_TENDONS:
        raise CodecError(f"{kind} has {n} tendons: expected 1 to {MAX_TENDONS}")


def encode_rig(msg: RigSetpoint | RigSample) -> bytes:
    """Bytes of a rig message (module docstring).

    Raises
    ------
    CodecError
        Another type, a non-finite float, a tendon count outside 1..MAX_TENDONS, arrays of different
        lengths, an integer out of its wire range.
    """
    try:
        if isinstance(msg, RigSetpoint):
            n = len(msg.x_in_cmd)
            _count("RigSetpoint", n)
            _finite("RigSetpoint", (msg.t, *msg.x_in_cmd))
            return (_HEADER.pack(RIG_MAGIC, RIG_VERSION, _TYPE_SETPOINT) + _SETPOINT.pack(msg.seq, msg.t, msg.tissue, n)
                    + struct.pack(f"<{n}d", *msg.x_in_cmd))
        if isinstance(msg, RigSample):
            n = len(msg.x_in)
            _count("RigSample", n)
            if len(msg.T_in) != n or len(msg.x_in_cmd) != n or len(msg.truth) not in (0, n):
                raise CodecError(f"RigSample: x_in, T_in, x_in_cmd (and truth) must have one entry per tendon, "
                                 f"got {n}, {len(msg.T_in)}, {len(msg.x_in_cmd)}, {len(msg.truth)}")
            body = [v for k in range(n) for v in (msg.x_in[k], msg.T_in[k], msg.x_in_cmd[k])]
            body += [float(v) for tr in msg.truth for v in tr]
            if len(body) != n * (3 + (5 if msg.truth else 0)):
                raise CodecError("RigSample: truth must hold 5 values per tendon")
            _finite("RigSample", (msg.t, *body))
            return (_HEADER.pack(RIG_MAGIC, RIG_VERSION, _TYPE_SAMPLE)
                    + _SAMPLE.pack(msg.seq, msg.setpoint_seq, msg.t, n, 1 if msg.truth else 0)
                    + struct.pack(f"<{len(body)}d", *body))
    except struct.error as e:
        raise CodecError(f"{type(msg).__name__} does not fit the wire format: {e}") from None
    raise CodecError(f"cannot encode a {type(msg).__name__} as a rig message")


def decode_rig(buf: bytes | bytearray | memoryview) -> RigSetpoint | RigSample:
    """The rig message in ``buf`` (module docstring).

    Raises
    ------
    CodecError
        Not a rig message (magic), another version, unknown type, wrong length, non-finite float.
    """
    if len(buf) < _HEADER.size:
        raise CodecError(f"rig message truncated: {len(buf)} bytes")
    magic, version, mtype = _HEADER.unpack_from(buf)
    if magic != RIG_MAGIC:
        raise CodecError(f"not a rig message: magic byte 0x{magic:02X}, expected 0x{RIG_MAGIC:02X}")
    if version != RIG_VERSION:
        raise CodecError(f"rig message version {version}, this build speaks {RIG_VERSION}")
    off = _HEADER.size
    if mtype == _TYPE_SETPOINT and len(buf) >= off + _SETPOINT.size:
        seq, t, tissue, n = _SETPOINT.unpack_from(buf, off)
        _count("RigSetpoint", n)
        if len(buf) != off + _SETPOINT.size + 8 * n:
            raise CodecError(f"RigSetpoint with {n} tendons: {len(buf)} bytes, expected {off + _SETPOINT.size + 8 * n}")
        x = struct.unpack_from(f"<{n}d", buf, off + _SETPOINT.size)
        _finite("RigSetpoint", (t, *x))
        return RigSetpoint(seq, t, tuple(x), tissue)
    if mtype == _TYPE_SAMPLE and len(buf) >= off + _SAMPLE.size:
        seq, sp_seq, t, n, truth = _SAMPLE.unpack_from(buf, off)
        _count("RigSample", n)
        m = n * (3 + (5 if truth else 0))
        if truth > 1 or len(buf) != off + _SAMPLE.size + 8 * m:
            raise CodecError(f"RigSample with {n} tendons (truth {truth}): {len(buf)} bytes, "
                             f"expected {off + _SAMPLE.size + 8 * m}")
        v = struct.unpack_from(f"<{m}d", buf, off + _SAMPLE.size)
        _finite("RigSample", (t, *v))
        tr = tuple(tuple(v[3 * n + 5 * k: 3 * n + 5 * k + 5]) for k in range(n)) if truth else ()
        return RigSample(seq, sp_seq, t, tuple(v[0:3 * n:3]), tuple(v[1:3 * n:3]), tuple(v[2:3 * n:3]), tr)
    raise CodecError(f"rig message of type {mtype} and {len(buf)} bytes: expected a RigSetpoint (1) or RigSample (2)")
