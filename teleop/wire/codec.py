"""Bytes <-> messages: the only place the wire format lives.

Every message is a 3-byte header followed by little-endian, fixed-layout fields::

    offset 0  uint8   MAGIC (0xA7)
    offset 1  uint8   WIRE_VERSION (3: one Command and one Estimate over every axis of any instrument)
    offset 2  uint8   message type: 1 Command, 2 Estimate, 3 Heartbeat

    Command   (18 + 8 n bytes after the header), n = axes, 1..16
        uint32 seq | float64 t_master [s] | uint8 engaged (0/1) | uint32 marker | uint8 n
        | float64 target[n] [m of a tendon axis, rad of a pair]
    Estimate  (19 + sum over axes of (17 + 33 m_k) + 4 m p bytes after the header), m_k = tendons of
              axis k (1 or 2), m = sum of m_k, p = profile points per tendon
        uint32 seq | uint32 cmd_seq | float64 t_slave [s] | uint8 n | uint16 p
        | n x ( uint8 m_k | float64 effort_hat [N or N m] | float64 position_hat [m or rad]
                | m_k x (float64 T_in [N] | float64 x_in [m] | float64 T_out_hat [N]
                         | float64 elongation_hat [m] | uint8 phase) )
        | float32 profile[m][p] [N]                      axis 0 first tendon, axis 0 second tendon, ...
    Heartbeat (14 bytes after the header)
        uint8 side | uint32 seq | float64 t_sender [s] | uint8 state

Version 2 (Command/Estimate of one tendon beside JointCommand/JointEstimate) and older are refused
with a message naming the version seen and the one expected. A buffer decodes only if it has exactly
the length its counts imply. Floats must be finite both ways: :func:`encode` refuses a message that
:func:`decode` would refuse. Sequence numbers are uint32: producers wrap them with :func:`next_seq`.
"""
from __future__ import annotations

import math
import struct
from functools import lru_cache

from estimator.phase import Phase
from teleop.errors import CodecError
from teleop.wire.messages import AxisState, Command, Estimate, Heartbeat, Side, SideState, TendonState

__all__ = [
    "MAGIC", "WIRE_VERSION", "TYPE_COMMAND", "TYPE_ESTIMATE", "TYPE_HEARTBEAT", "MAX_AXES", "MAX_PROFILE_POINTS",
    "SEQ_MODULUS", "Message", "encode", "decode", "next_seq", "seq_newer", "prepare_estimate",
]

MAGIC = 0xA7
WIRE_VERSION = 3
TYPE_COMMAND = 1
TYPE_ESTIMATE = 2
TYPE_HEARTBEAT = 3
MAX_AXES = 16                        # uint8 count; 8 antagonistic pairs of a bimanual instrument are 16 tendons
MAX_PROFILE_POINTS = 0xFFFF          # uint16 count
SEQ_MODULUS = 1 << 32                # sequence numbers are uint32

Message = Command | Estimate | Heartbeat

_HEADER = struct.Struct("<BBB")
_COMMAND = struct.Struct("<IdBIB")
_ESTIMATE = struct.Struct("<IIdBH")
_AXIS = struct.Struct("<Bdd")
_TENDON = struct.Struct("<4dB")
_HEARTBEAT = struct.Struct("<BIdB")
_HDR = _HEADER.size
_TYPE_NAMES = {TYPE_COMMAND: "Command", TYPE_ESTIMATE: "Estimate", TYPE_HEARTBEAT: "Heartbeat"}
_PHASES = {int(p): p for p in Phase}
_SIDES = {int(s): s for s in Side}
_STATES = {int(s): s for s in SideState}
_U32 = 0xFFFFFFFF
_TENDON_FLOATS = ("T_in", "x_in", "T_out_hat", "elongation_hat")
#: A decoded axis's states are made without their frozen ``__init__`` (a field at a time through
#: ``object.__setattr__``): a third of the time, on the master's receive path. Equal to the ones it would make.
_NEW = object.__new__


@lru_cache(maxsize=64)
def _floats(n: int, code: str = "d") -> struct.Struct:
    return struct.Struct(f"<{n}{code}")


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
    for name, v in zip(names, values, strict=False):
        if not math.isfinite(v):
            raise CodecError(f"{kind}.{name} is {v!r}: every float on the wire must be finite")


def _check_uint(kind: str, name: str, v: int, bits: int) -> None:
    if not (isinstance(v, int) and not isinstance(v, bool) and 0 <= v < (1 << bits)):
        raise CodecError(f"{kind}.{name} is {v!r}: expected an integer in [0, 2**{bits})")


def _check_profile(kind: str, profile) -> None:
    # a sum of float32-range values cannot overflow float64: it is finite iff every value is
    if not math.isfinite(sum(profile)):
        for i, v in enumerate(profile):
            if not math.isfinite(v):
                raise CodecError(f"{kind}[{i}] is {v!r}: every float on the wire must be finite")


def _axis_count(kind: str, n: int) -> None:
    if not 1 <= n <= MAX_AXES:
        raise CodecError(f"{kind} has {n} axes: expected 1 to {MAX_AXES}")


def _phase(kind: str, ph) -> int:
    if ph not in _PHASES or isinstance(ph, bool):
        raise CodecError(f"{kind}.phase is {ph!r}: expected a Phase")
    return int(ph)


def encode(msg: Message) -> bytes:
    """Serialise a message to bytes (see the module docstring for the layout).

    Parameters
    ----------
    msg : Command, Estimate or Heartbeat
        Floats finite; ``seq``/``cmd_seq``/``marker`` in [0, 2**32); 1 to :data:`MAX_AXES` axes, each
        of one or two tendons; profiles none or one per tendon, all of one length of at most
        :data:`MAX_PROFILE_POINTS` points, each finite in float32.

    Returns
    -------
    bytes

    Raises
    ------
    CodecError
        Not a message, a non-finite float, an integer out of its wire range, an axis count outside
        1..16, an axis of neither one nor two tendons, profiles that are not one per tendon, too long a
        profile.
    """
    if isinstance(msg, Command):
        return _encode_command(msg)
    if isinstance(msg, Estimate):
        return _encode_estimate(msg)
    if isinstance(msg, Heartbeat):
        _check_finite("Heartbeat", ("t_sender",), (msg.t_sender,))
        if msg.side not in _SIDES or isinstance(msg.side, bool):
            raise CodecError(f"Heartbeat.side is {msg.side!r}: expected a Side")
        if msg.state not in _STATES or isinstance(msg.state, bool):
            raise CodecError(f"Heartbeat.state is {msg.state!r}: expected a SideState")
        _check_uint("Heartbeat", "seq", msg.seq, 32)
        body = _HEARTBEAT.pack(int(msg.side), msg.seq, msg.t_sender, int(msg.state))
        return _HEADER.pack(MAGIC, WIRE_VERSION, TYPE_HEARTBEAT) + body
    raise CodecError(f"cannot encode a {type(msg).__name__}: expected Command, Estimate or Heartbeat")


def _encode_command(msg: Command) -> bytes:
    n = len(msg.targets)
    _axis_count("Command", n)
    _check_finite("Command", ("t_master",) + tuple(f"targets[{i}]" for i in range(n)), (msg.t_master, *msg.targets))
    _check_uint("Command", "seq", msg.seq, 32)
    _check_uint("Command", "marker", msg.marker, 32)
    try:
        return (_HEADER.pack(MAGIC, WIRE_VERSION, TYPE_COMMAND)
                + _COMMAND.pack(msg.seq, msg.t_master, bool(msg.engaged), msg.marker, n)
                + _floats(n).pack(*msg.targets))
    except struct.error:
        raise CodecError(f"Command fields do not fit the wire format: {msg!r}") from None


@lru_cache(maxsize=8)
def _axis_struct(k: int) -> struct.Struct:
    """An axis of ``k`` tendons: uint8 k | effort_hat | position_hat | k x (4 float64 | uint8 phase)."""
    return struct.Struct("<Bdd" + "4dB" * k)


def _name_bad_axis(i: int, ax: AxisState) -> None:
    """Raise the CodecError naming the first non-finite float or bad phase of axis ``i`` (the slow path)."""
    kind = f"Estimate.axes[{i}]"
    _check_finite(kind, ("effort_hat", "position_hat"), (ax.effort_hat, ax.position_hat))
    for j, td in enumerate(ax.tendons):
        tk = f"{kind}.tendons[{j}]"
        _check_finite(tk, _TENDON_FLOATS, (td.T_in, td.x_in, td.T_out_hat, td.elongation_hat))
        _phase(tk, td.phase)


def _name_bad_estimate(msg: Estimate) -> None:
    """Raise the CodecError naming the first non-finite float or bad phase of ``msg`` (the slow path)."""
    _check_finite("Estimate", ("t_slave",), (msg.t_slave,))
    for i, ax in enumerate(msg.axes):
        _name_bad_axis(i, ax)


#: Bodies encoded ahead (:func:`prepare_estimate`): id(axes) -> (axes, profiles, body, profile points). An entry
#: holds its tuples, so an id in it is never reused; a message whose axes and profiles are those very tuples
#: (immutable, of frozen states) has that body. Cleared when full.
_BODIES: dict[int, tuple[tuple, tuple, bytes, int]] = {}
_BODIES_MAX = 8


def prepare_estimate(axes: tuple[AxisState, ...], profiles: tuple[tuple[float, ...], ...] = ()) -> bool:
    """Encode an Estimate's axes and profiles ahead of its send: :func:`encode` of an Estimate holding these
    very tuples then packs only its header (sequence numbers and time). The slave encodes each cycle's
    estimate as soon as it is estimated, before the command it answers arrives.

    Parameters
    ----------
    axes : tuple of AxisState
        The estimate's axes (the same tuple object must go into the Estimate).
    profiles : tuple of tuple of float
        Its profiles (likewise).

    Returns
    -------
    bool
        True when encoded; False when they do not fit the wire (then :func:`encode` raises its CodecError
        on the message as without preparation).
    """
    try:
        body, points = _estimate_body(Estimate(0, 0, 0.0, axes, profiles))
    except CodecError:
        return False
    if len(_BODIES) >= _BODIES_MAX:
        _BODIES.clear()
    _BODIES[id(axes)] = (axes, profiles, body, points)
    return True


def _encode_estimate(msg: Estimate) -> bytes:
    _check_uint("Estimate", "seq", msg.seq, 32)
    _check_uint("Estimate", "cmd_seq", msg.cmd_seq, 32)
    _check_finite("Estimate", ("t_slave",), (msg.t_slave,))
    hit = _BODIES.get(id(msg.axes))
    if hit is not None and hit[0] is msg.axes and hit[1] is msg.profiles:
        body, points = hit[2], hit[3]
    else:
        body, points = _estimate_body(msg)
    return (_HEADER.pack(MAGIC, WIRE_VERSION, TYPE_ESTIMATE)
            + _ESTIMATE.pack(msg.seq, msg.cmd_seq, msg.t_slave, len(msg.axes), points) + body)


def _estimate_body(msg: Estimate) -> tuple[bytes, int]:
    """The axes and profiles of ``msg`` on the wire, and the profile points (CodecError naming what does not fit)."""
    n = len(msg.axes)
    _axis_count("Estimate", n)
    parts = []
    total = 0.0
    m = 0
    try:
        for i, ax in enumerate(msg.axes):
            tendons = ax.tendons
            k = len(tendons)
            if k not in (1, 2):
                raise CodecError(f"Estimate.axes[{i}] has {k} tendons: expected 1 (a single tendon) or 2 (a pair)")
            vals: list = [k, ax.effort_hat, ax.position_hat]
            total += ax.effort_hat + ax.position_hat
            for td in tendons:
                ph = td.phase
                if ph not in _PHASES or isinstance(ph, bool):
                    raise TypeError
                total += td.T_in + td.x_in + td.T_out_hat + td.elongation_hat
                vals += (td.T_in, td.x_in, td.T_out_hat, td.elongation_hat, int(ph))
            parts.append(_axis_struct(k).pack(*vals))
            m += k
    except (TypeError, struct.error):
        _name_bad_estimate(msg)
        raise CodecError(f"Estimate fields do not fit the wire format: {msg!r}") from None
    if not math.isfinite(total):
        _name_bad_estimate(msg)
    profiles = msg.profiles
    points = len(profiles[0]) if profiles else 0
    if profiles and (len(profiles) != m or any(len(p) != points for p in profiles)):
        raise CodecError(f"Estimate.profiles: expected none or {m} profiles (one per tendon) of one length, "
                         f"got {len(profiles)}")
    if points > MAX_PROFILE_POINTS:
        raise CodecError(f"Estimate.profiles have {points} points: at most {MAX_PROFILE_POINTS} fit the wire")
    try:
        for k, p in enumerate(profiles):
            _check_profile(f"Estimate.profiles[{k}]", p)
            parts.append(_floats(points, "f").pack(*p))
    except (struct.error, TypeError, OverflowError) as e:
        raise CodecError(f"Estimate.profiles must hold finite floats within float32 range ({e})") from None
    return b"".join(parts), points


def _expect_len(kind: str, buf, need: int) -> None:
    if len(buf) != need:
        what = "truncated" if len(buf) < need else "too long"
        raise CodecError(f"{kind} message {what}: {len(buf)} bytes, expected {need}")


def _decode_command(buf) -> Command:
    if len(buf) < _HDR + _COMMAND.size:
        _expect_len("Command", buf, _HDR + _COMMAND.size)
    seq, t, engaged, marker, n = _COMMAND.unpack_from(buf, _HDR)
    _axis_count("Command", n)
    _expect_len("Command", buf, _HDR + _COMMAND.size + 8 * n)
    targets = _floats(n).unpack_from(buf, _HDR + _COMMAND.size)
    _check_finite("Command", ("t_master",) + tuple(f"targets[{i}]" for i in range(n)), (t, *targets))
    if engaged > 1:
        raise CodecError(f"Command.engaged byte is {engaged}: expected 0 or 1")
    return Command(seq, t, targets, engaged == 1, marker)


def _decode_estimate(buf) -> Estimate:
    if len(buf) < _HDR + _ESTIMATE.size:
        _expect_len("Estimate", buf, _HDR + _ESTIMATE.size)
    seq, cmd_seq, t, n, points = _ESTIMATE.unpack_from(buf, _HDR)
    _axis_count("Estimate", n)
    _check_finite("Estimate", ("t_slave",), (t,))
    axes, off, m, size = [], _HDR + _ESTIMATE.size, 0, len(buf)
    for i in range(n):
        if off >= size:
            raise CodecError(f"Estimate message truncated: {size} bytes end inside axis {i} of {n}")
        k = buf[off]
        if k not in (1, 2):
            raise CodecError(f"Estimate.axes[{i}] has {k} tendons: expected 1 (a single tendon) or 2 (a pair)")
        st = _axis_struct(k)
        if off + st.size > size:
            raise CodecError(f"Estimate message truncated: {size} bytes end inside axis {i} of {n}")
        v = st.unpack_from(buf, off)
        off += st.size
        tendons = []
        for j in range(k):
            T_in, x_in, T_out, el, ph = v[3 + 5 * j: 8 + 5 * j]
            phase = _PHASES.get(ph)
            if phase is None:
                raise CodecError(f"Estimate.axes[{i}].tendons[{j}].phase {ph} is not a Phase (0..{len(_PHASES) - 1})")
            td = _NEW(TendonState)          # every field checked here: made without the frozen __init__
            td.__dict__.update(T_in=T_in, x_in=x_in, T_out_hat=T_out, elongation_hat=el, phase=phase)
            tendons.append(td)
        axis = _NEW(AxisState)
        axis.__dict__.update(effort_hat=v[1], position_hat=v[2], tendons=tuple(tendons))
        if not math.isfinite(sum(v)):                 # the phases and k are small integers: finite
            _name_bad_axis(i, axis)
        axes.append(axis)
        m += k
    need = off + 4 * m * points
    if size != need:
        raise CodecError(f"Estimate with {n} axes, {m} tendons and {points} profile points needs {need} bytes, "
                         f"got {size}")
    profiles = []
    for k in range(m if points else 0):
        p = _floats(points, "f").unpack_from(buf, off)
        off += 4 * points
        _check_profile(f"Estimate.profiles[{k}]", p)
        profiles.append(p)
    return Estimate(seq, cmd_seq, t, tuple(axes), tuple(profiles))


def decode(buf: bytes | bytearray | memoryview) -> Message:
    """Parse bytes produced by :func:`encode` back into a message.

    Parameters
    ----------
    buf : bytes-like
        One whole message, exactly.

    Returns
    -------
    Command, Estimate or Heartbeat
        Every float finite; enums are :class:`Phase`, :class:`Side`, :class:`SideState`; targets and
        profiles are tuples of Python floats (profiles at float32 precision).

    Raises
    ------
    CodecError
        Shorter than a header, wrong magic, another wire version (the message names the version seen
        and the one expected), unknown message type, a length that does not match the counts (axes:
        1..16, tendons per axis: 1 or 2), a non-finite float, an unknown enum value.
    """
    if len(buf) < _HDR:
        raise CodecError(f"message truncated: {len(buf)} bytes, a header alone is {_HDR}")
    magic, version, mtype = _HEADER.unpack_from(buf)
    if magic != MAGIC:
        raise CodecError(f"not a teleop message: magic byte 0x{magic:02X}, expected 0x{MAGIC:02X}")
    if version != WIRE_VERSION:
        hint = (" (versions up to 2 had separate single-tendon and joint messages; upgrade the sender)"
                if version < WIRE_VERSION else " (upgrade this side)")
        raise CodecError(f"message version {version} refused: this build speaks wire version {WIRE_VERSION}{hint}")
    if mtype == TYPE_ESTIMATE:
        return _decode_estimate(buf)
    if mtype == TYPE_COMMAND:
        return _decode_command(buf)
    if mtype == TYPE_HEARTBEAT:
        _expect_len("Heartbeat", buf, _HDR + _HEARTBEAT.size)
        side, seq, t, state = _HEARTBEAT.unpack_from(buf, _HDR)
        _check_finite("Heartbeat", ("t_sender",), (t,))
        if side not in _SIDES:
            raise CodecError(f"Heartbeat.side {side} is not a Side (1 master, 2 slave)")
        if state not in _STATES:
            raise CodecError(f"Heartbeat.state {state} is not a SideState (0..{len(_STATES) - 1})")
        return Heartbeat(_SIDES[side], seq, t, _STATES[state])
    raise CodecError(f"unknown message type {mtype}: expected one of {sorted(_TYPE_NAMES)} "
                     f"({', '.join(_TYPE_NAMES.values())})")
