"""Bytes <-> messages: the only place the wire format lives.

Every message is a 3-byte header followed by little-endian, fixed-layout fields::

    offset 0  uint8   MAGIC (0xA7)
    offset 1  uint8   WIRE_VERSION (2: joint instruments added)
    offset 2  uint8   message type: 1 Command, 2 Estimate, 3 Heartbeat, 4 JointCommand, 5 JointEstimate

    Command   (25 bytes after the header)
        uint32 seq | float64 t_master [s] | float64 x_in_cmd [m] | uint8 engaged (0/1) | uint32 marker
    Estimate  (59 bytes + 4 * count after the header)
        uint32 seq | uint32 cmd_seq | float64 t_slave [s] | float64 T_in [N] | float64 x_in [m]
        | float64 T_out_hat [N] | float64 elongation_hat [m] | float64 x_out_hat [m] | uint8 phase
        | uint16 count | float32 profile[count] [N]
    Heartbeat (14 bytes after the header)
        uint8 side | uint32 seq | float64 t_sender [s] | uint8 state
    JointCommand (18 + 8 * n bytes after the header), n = joints, 1..4
        uint32 seq | float64 t_master [s] | uint8 engaged | uint32 marker | uint8 n | float64 angle[n] [rad]
    JointEstimate (19 + 82 * n + 8 * n * p bytes after the header), p = profile points per tendon
        uint32 seq | uint32 cmd_seq | float64 t_slave [s] | uint8 n | uint16 p
        | n x ( float64 torque_hat [N m] | float64 angle_hat [rad]
                | 2 x (float64 T_in [N] | float64 x_in [m] | float64 T_out_hat [N]
                       | float64 elongation_hat [m] | uint8 phase) )        tendon a, then b
        | float32 profile[2 n][p] [N]                                      joint 0 a, joint 0 b, ...

A buffer decodes only if it has exactly the length its type (and profile count) implies. Floats must
be finite both ways: :func:`encode` refuses a message that :func:`decode` would refuse.
Sequence numbers are uint32: producers wrap them with :func:`next_seq`.
"""
from __future__ import annotations

import math
import struct
from functools import lru_cache
from typing import Union

from estimator.phase import Phase
from teleop.errors import CodecError
from teleop.messages import (
    Command,
    Estimate,
    Heartbeat,
    JointCommand,
    JointEstimate,
    JointState,
    Side,
    SideState,
    TendonState,
)

__all__ = [
    "MAGIC", "WIRE_VERSION", "TYPE_COMMAND", "TYPE_ESTIMATE", "TYPE_HEARTBEAT", "TYPE_JOINT_COMMAND",
    "TYPE_JOINT_ESTIMATE", "MAX_JOINTS", "MAX_PROFILE_POINTS", "SEQ_MODULUS", "Message", "encode", "decode", "next_seq", "seq_newer",
]

MAGIC = 0xA7
WIRE_VERSION = 2
TYPE_COMMAND = 1
TYPE_ESTIMATE = 2
TYPE_HEARTBEAT = 3
TYPE_JOINT_COMMAND = 4
TYPE_JOINT_ESTIMATE = 5
MAX_JOINTS = 4
MAX_PROFILE_POINTS = 0xFFFF          # uint16 count
SEQ_MODULUS = 1 << 32                # sequence numbers are uint32

Message = Union[Command, Estimate, Heartbeat, JointCommand, JointEstimate]

_HEADER = struct.Struct("<BBB")
_COMMAND = struct.Struct("<IddBI")
_ESTIMATE = struct.Struct("<IIddddddBH")
_HEARTBEAT = struct.Struct("<BIdB")
_JCMD = struct.Struct("<IdBIB")
_JEST = struct.Struct("<IIdBH")
_JOINT = struct.Struct("<dd4dB4dB")
_HDR = _HEADER.size
_TYPE_NAMES = {TYPE_COMMAND: "Command", TYPE_ESTIMATE: "Estimate", TYPE_HEARTBEAT: "Heartbeat",
               TYPE_JOINT_COMMAND: "JointCommand", TYPE_JOINT_ESTIMATE: "JointEstimate"}
_PHASES = {int(p): p for p in Phase}
_SIDES = {int(s): s for s in Side}
_STATES = {int(s): s for s in SideState}
_U32 = 0xFFFFFFFF


@lru_cache(maxsize=64)
def _profile_struct(n: int) -> struct.Struct:
    return struct.Struct(f"<{n}f")


def next_seq(seq: int) -> int:
    """The sequence number after ``seq``, wrapping at 2**32 (uint32 on the wire)."""
    return (seq + 1) & _U32


def seq_newer(seq: int, than: int | None) -> bool:
    """Whether sequence number ``seq`` comes after ``than`` (uint32 wrap, half the range ahead; None: yes)."""
    return than is None or 0 < (seq - than) % SEQ_MODULUS < SEQ_MODULUS // 2


def _check_finite(kind: str, names: tuple[str, ...], values: tuple[float, ...]) -> None:
    # One C-level sum catches NaN/inf; only then look for the culprit (an overflowing sum of finite
    # values is a false alarm and passes the per-field check).
    if math.isfinite(sum(values)):
        return
    for name, v in zip(names, values):
        if not math.isfinite(v):
            raise CodecError(f"{kind}.{name} is {v!r}: every float on the wire must be finite")


def _check_uint(kind: str, name: str, v: int, bits: int) -> None:
    if not (isinstance(v, int) and 0 <= v < (1 << bits)):
        raise CodecError(f"{kind}.{name} is {v!r}: expected an integer in [0, 2**{bits})")


def _check_profile(kind: str, profile) -> None:
    # a sum of float32-range values cannot overflow float64: it is finite iff every value is
    if not math.isfinite(sum(profile)):
        for i, v in enumerate(profile):
            if not math.isfinite(v):
                raise CodecError(f"{kind}.profile[{i}] is {v!r}: every float on the wire must be finite")


_CMD_FLOATS = ("t_master", "x_in_cmd")
_EST_FLOATS = ("t_slave", "T_in", "x_in", "T_out_hat", "elongation_hat", "x_out_hat")


def encode(msg: Message) -> bytes:
    """Serialise a message to bytes (see the module docstring for the layout).

    Parameters
    ----------
    msg : Command, Estimate, Heartbeat, JointCommand or JointEstimate
        Floats finite; ``seq``/``cmd_seq``/``marker`` in [0, 2**32); at most
        :data:`MAX_PROFILE_POINTS` profile points, each finite in float32; 1 to :data:`MAX_JOINTS`
        joints, two tendons each, profiles none or one per tendon of one length.

    Returns
    -------
    bytes

    Raises
    ------
    CodecError
        Not a message, a non-finite float, an integer out of its wire range, too long a profile, a
        joint count outside 1..4, profiles that are not one per tendon.
    """
    t = type(msg)
    if isinstance(msg, Command):
        _check_finite("Command", _CMD_FLOATS, (msg.t_master, msg.x_in_cmd))
        try:
            body = _COMMAND.pack(msg.seq, msg.t_master, msg.x_in_cmd, bool(msg.engaged), msg.marker)
        except struct.error:
            _check_uint("Command", "seq", msg.seq, 32)
            _check_uint("Command", "marker", msg.marker, 32)
            raise CodecError(f"Command fields do not fit the wire format: {msg!r}") from None
        return _HEADER.pack(MAGIC, WIRE_VERSION, TYPE_COMMAND) + body
    if isinstance(msg, Estimate):
        floats = (msg.t_slave, msg.T_in, msg.x_in, msg.T_out_hat, msg.elongation_hat, msg.x_out_hat)
        _check_finite("Estimate", _EST_FLOATS, floats)
        profile = msg.profile
        n = len(profile)
        if n > MAX_PROFILE_POINTS:
            raise CodecError(f"Estimate.profile has {n} points: at most {MAX_PROFILE_POINTS} fit the wire")
        if msg.phase not in _PHASES or isinstance(msg.phase, bool):
            raise CodecError(f"Estimate.phase is {msg.phase!r}: expected a Phase")
        try:
            head = _ESTIMATE.pack(msg.seq, msg.cmd_seq, *floats, int(msg.phase), n)
        except struct.error:
            _check_uint("Estimate", "seq", msg.seq, 32)
            _check_uint("Estimate", "cmd_seq", msg.cmd_seq, 32)
            raise CodecError(f"Estimate fields do not fit the wire format: {msg!r}") from None
        try:
            if n:
                _check_profile("Estimate", profile)
            prof = _profile_struct(n).pack(*profile)
        except (struct.error, TypeError, OverflowError) as e:
            raise CodecError(f"Estimate.profile must hold finite floats within float32 range ({e})") from None
        return _HEADER.pack(MAGIC, WIRE_VERSION, TYPE_ESTIMATE) + head + prof
    if isinstance(msg, Heartbeat):
        _check_finite("Heartbeat", ("t_sender",), (msg.t_sender,))
        if msg.side not in _SIDES or isinstance(msg.side, bool):
            raise CodecError(f"Heartbeat.side is {msg.side!r}: expected a Side")
        if msg.state not in _STATES or isinstance(msg.state, bool):
            raise CodecError(f"Heartbeat.state is {msg.state!r}: expected a SideState")
        _check_uint("Heartbeat", "seq", msg.seq, 32)
        body = _HEARTBEAT.pack(int(msg.side), msg.seq, msg.t_sender, int(msg.state))
        return _HEADER.pack(MAGIC, WIRE_VERSION, TYPE_HEARTBEAT) + body
    if isinstance(msg, JointCommand):
        return _encode_joint_command(msg)
    if isinstance(msg, JointEstimate):
        return _encode_joint_estimate(msg)
    raise CodecError(f"cannot encode a {t.__name__}: expected Command, Estimate, Heartbeat, JointCommand or "
                     f"JointEstimate")


def _joint_count(kind: str, n: int) -> None:
    if not 1 <= n <= MAX_JOINTS:
        raise CodecError(f"{kind} has {n} joints: expected 1 to {MAX_JOINTS}")


def _encode_joint_command(msg: JointCommand) -> bytes:
    n = len(msg.angles)
    _joint_count("JointCommand", n)
    _check_finite("JointCommand", ("t_master",) + tuple(f"angles[{i}]" for i in range(n)), (msg.t_master, *msg.angles))
    _check_uint("JointCommand", "seq", msg.seq, 32)
    _check_uint("JointCommand", "marker", msg.marker, 32)
    try:
        return (_HEADER.pack(MAGIC, WIRE_VERSION, TYPE_JOINT_COMMAND)
                + _JCMD.pack(msg.seq, msg.t_master, bool(msg.engaged), msg.marker, n) + struct.pack(f"<{n}d", *msg.angles))
    except struct.error:
        raise CodecError(f"JointCommand fields do not fit the wire format: {msg!r}") from None


def _encode_joint_estimate(msg: JointEstimate) -> bytes:
    n = len(msg.joints)
    _joint_count("JointEstimate", n)
    _check_finite("JointEstimate", ("t_slave",), (msg.t_slave,))
    _check_uint("JointEstimate", "seq", msg.seq, 32)
    _check_uint("JointEstimate", "cmd_seq", msg.cmd_seq, 32)
    profiles = msg.profiles
    points = len(profiles[0]) if profiles else 0
    if profiles and (len(profiles) != 2 * n or any(len(p) != points for p in profiles)):
        raise CodecError(f"JointEstimate.profiles: expected none or {2 * n} profiles (two per joint) of one length")
    if points > MAX_PROFILE_POINTS:
        raise CodecError(f"JointEstimate.profiles have {points} points: at most {MAX_PROFILE_POINTS} fit the wire")
    parts = [_HEADER.pack(MAGIC, WIRE_VERSION, TYPE_JOINT_ESTIMATE), _JEST.pack(msg.seq, msg.cmd_seq, msg.t_slave, n,
                                                                                 points)]
    for i, j in enumerate(msg.joints):
        vals, phases = [j.torque_hat, j.angle_hat], []
        for td in j.tendons:
            vals += [td.T_in, td.x_in, td.T_out_hat, td.elongation_hat]
            if td.phase not in _PHASES or isinstance(td.phase, bool):
                raise CodecError(f"JointEstimate.joints[{i}] phase is {td.phase!r}: expected a Phase")
            phases.append(int(td.phase))
        if len(j.tendons) != 2:
            raise CodecError(f"JointEstimate.joints[{i}] has {len(j.tendons)} tendons: expected 2 (a, b)")
        _check_finite(f"JointEstimate.joints[{i}]", _JOINT_FLOATS, tuple(vals))
        parts.append(_JOINT.pack(*vals[:6], phases[0], *vals[6:], phases[1]))
    try:
        for k, p in enumerate(profiles):
            _check_profile(f"JointEstimate.profiles[{k}]", p)
            parts.append(_profile_struct(points).pack(*p))
    except (struct.error, TypeError, OverflowError) as e:
        raise CodecError(f"JointEstimate.profiles must hold finite floats within float32 range ({e})") from None
    return b"".join(parts)


_JOINT_FLOATS = ("torque_hat", "angle_hat", "a.T_in", "a.x_in", "a.T_out_hat", "a.elongation_hat",
                 "b.T_in", "b.x_in", "b.T_out_hat", "b.elongation_hat")


def _decode_joint_command(buf) -> JointCommand:
    if len(buf) < _HDR + _JCMD.size:
        _expect_len("JointCommand", buf, _HDR + _JCMD.size)
    seq, t, engaged, marker, n = _JCMD.unpack_from(buf, _HDR)
    _joint_count("JointCommand", n)
    _expect_len("JointCommand", buf, _HDR + _JCMD.size + 8 * n)
    angles = struct.unpack_from(f"<{n}d", buf, _HDR + _JCMD.size)
    _check_finite("JointCommand", ("t_master",) + tuple(f"angles[{i}]" for i in range(n)), (t, *angles))
    if engaged > 1:
        raise CodecError(f"JointCommand.engaged byte is {engaged}: expected 0 or 1")
    return JointCommand(seq, t, tuple(angles), engaged == 1, marker)


def _decode_joint_estimate(buf) -> JointEstimate:
    if len(buf) < _HDR + _JEST.size:
        _expect_len("JointEstimate", buf, _HDR + _JEST.size)
    seq, cmd_seq, t, n, points = _JEST.unpack_from(buf, _HDR)
    _joint_count("JointEstimate", n)
    need = _HDR + _JEST.size + _JOINT.size * n + 8 * n * points
    if len(buf) != need:
        raise CodecError(f"JointEstimate with {n} joints and {points} profile points needs {need} bytes, got {len(buf)}")
    _check_finite("JointEstimate", ("t_slave",), (t,))
    joints, off = [], _HDR + _JEST.size
    for i in range(n):
        v = _JOINT.unpack_from(buf, off)
        off += _JOINT.size
        floats = v[:6] + v[7:11]
        _check_finite(f"JointEstimate.joints[{i}]", _JOINT_FLOATS, floats)
        pa, pb = _PHASES.get(v[6]), _PHASES.get(v[11])
        if pa is None or pb is None:
            raise CodecError(f"JointEstimate.joints[{i}] phase {v[6] if pa is None else v[11]} is not a Phase "
                             f"(0..{len(_PHASES) - 1})")
        joints.append(JointState(v[0], v[1], (TendonState(v[2], v[3], v[4], v[5], pa),
                                              TendonState(v[7], v[8], v[9], v[10], pb))))
    profiles = []
    for k in range(2 * n if points else 0):
        p = _profile_struct(points).unpack_from(buf, off)
        off += 4 * points
        _check_profile(f"JointEstimate.profiles[{k}]", p)
        profiles.append(p)
    return JointEstimate(seq, cmd_seq, t, tuple(joints), tuple(profiles))


def _expect_len(kind: str, buf, need: int) -> None:
    if len(buf) != need:
        what = "truncated" if len(buf) < need else "too long"
        raise CodecError(f"{kind} message {what}: {len(buf)} bytes, expected {need}")


def decode(buf: bytes | bytearray | memoryview) -> Message:
    """Parse bytes produced by :func:`encode` back into a message.

    Parameters
    ----------
    buf : bytes-like
        One whole message, exactly.

    Returns
    -------
    Command, Estimate, Heartbeat, JointCommand or JointEstimate
        Every float finite; enums are :class:`Phase`, :class:`Side`, :class:`SideState`; the profile
        is a tuple of Python floats (float32 precision).

    Raises
    ------
    CodecError
        Shorter than a header, wrong magic, another wire version, unknown message type, a length that
        does not match the type or the profile count (joint count: 1..4), a non-finite float, an
        unknown enum value.
    """
    if len(buf) < _HDR:
        raise CodecError(f"message truncated: {len(buf)} bytes, a header alone is {_HDR}")
    magic, version, mtype = _HEADER.unpack_from(buf)
    if magic != MAGIC:
        raise CodecError(f"not a teleop message: magic byte 0x{magic:02X}, expected 0x{MAGIC:02X}")
    if version != WIRE_VERSION:
        raise CodecError(f"message version {version}, this build speaks {WIRE_VERSION}")
    if mtype == TYPE_ESTIMATE:
        if len(buf) < _HDR + _ESTIMATE.size:
            _expect_len("Estimate", buf, _HDR + _ESTIMATE.size)
        seq, cmd_seq, t, T_in, x_in, T_out, el, x_out, phase, n = _ESTIMATE.unpack_from(buf, _HDR)
        need = _HDR + _ESTIMATE.size + 4 * n
        if len(buf) != need:
            raise CodecError(f"Estimate profile count {n} needs {need} bytes, got {len(buf)}")
        floats = (t, T_in, x_in, T_out, el, x_out)
        _check_finite("Estimate", _EST_FLOATS, floats)
        ph = _PHASES.get(phase)
        if ph is None:
            raise CodecError(f"Estimate.phase {phase} is not a Phase (0..{len(_PHASES) - 1})")
        profile = _profile_struct(n).unpack_from(buf, _HDR + _ESTIMATE.size) if n else ()
        if n:
            _check_profile("Estimate", profile)
        return Estimate(seq, cmd_seq, t, T_in, x_in, T_out, el, x_out, ph, profile)
    if mtype == TYPE_COMMAND:
        _expect_len("Command", buf, _HDR + _COMMAND.size)
        seq, t, x, engaged, marker = _COMMAND.unpack_from(buf, _HDR)
        _check_finite("Command", _CMD_FLOATS, (t, x))
        if engaged > 1:
            raise CodecError(f"Command.engaged byte is {engaged}: expected 0 or 1")
        return Command(seq, t, x, engaged == 1, marker)
    if mtype == TYPE_HEARTBEAT:
        _expect_len("Heartbeat", buf, _HDR + _HEARTBEAT.size)
        side, seq, t, state = _HEARTBEAT.unpack_from(buf, _HDR)
        _check_finite("Heartbeat", ("t_sender",), (t,))
        if side not in _SIDES:
            raise CodecError(f"Heartbeat.side {side} is not a Side (1 master, 2 slave)")
        if state not in _STATES:
            raise CodecError(f"Heartbeat.state {state} is not a SideState (0..{len(_STATES) - 1})")
        return Heartbeat(_SIDES[side], seq, t, _STATES[state])
    if mtype == TYPE_JOINT_COMMAND:
        return _decode_joint_command(buf)
    if mtype == TYPE_JOINT_ESTIMATE:
        return _decode_joint_estimate(buf)
    raise CodecError(f"unknown message type {mtype}: expected one of {sorted(_TYPE_NAMES)} "
                     f"({', '.join(_TYPE_NAMES.values())})")
