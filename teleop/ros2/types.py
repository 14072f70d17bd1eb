"""ROS 2 message types of the CRTK topics: CDR encoding, DDS type names and RIHS01 type hashes.

The CDR bytes and the type hashes come from rosbags' type store (:mod:`rosbags.typesys`), a maintained,
pure-Python library: it serialises ROS 2 messages to the CDR that ROS 2 itself puts on the wire (the
4-byte encapsulation header, little-endian), ships the standard message definitions of the ROS 2
distributions, and computes the RIHS01 type hash of REP 2011 from them (``hash_rihs01``). rosbags was
chosen over mcap-ros2-support and pycdr2 because it is the one of the three that does all of this from
message definitions alone: mcap-ros2-support decodes and encodes but computes no type hash, pycdr2
needs the types written out as IDL dataclasses. The tests decode the bytes with mcap-ros2-support's
independent decoder and recompute the hashes with their own implementation of REP 2011.

Types: ``sensor_msgs/msg/JointState``, ``geometry_msgs/msg/WrenchStamped`` (the Jazzy definitions),
``crtk_msgs/msg/OperatingState`` and ``crtk_msgs/msg/StringStamped`` (registered from the ``.msg``
text of collaborative-robotics/ros2_crtk_msgs, quoted below).
"""
from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from teleop.errors import CodecError

__all__ = ["JOINT_STATE", "WRENCH_STAMPED", "OPERATING_STATE", "STRING_STAMPED", "TYPES", "CRTK_MSGS",
           "typestore", "dds_type_name", "type_hash", "encode", "decode", "joint_state", "wrench_stamped",
           "operating_state", "string_stamped", "stamp_ns", "warm_up"]

JOINT_STATE = "sensor_msgs/msg/JointState"
WRENCH_STAMPED = "geometry_msgs/msg/WrenchStamped"
OPERATING_STATE = "crtk_msgs/msg/OperatingState"
STRING_STAMPED = "crtk_msgs/msg/StringStamped"
TYPES = (JOINT_STATE, WRENCH_STAMPED, OPERATING_STATE, STRING_STAMPED)

#: crtk_msgs definitions, verbatim from collaborative-robotics/ros2_crtk_msgs msg/*.msg (comments dropped)
CRTK_MSGS = {
    OPERATING_STATE: "std_msgs/Header header\nstring          state\nbool            is_homed\n"
                     "bool            is_busy\n",
    STRING_STAMPED: "std_msgs/Header header\nstring string\n",
}


@functools.lru_cache(maxsize=1)
def typestore() -> Any:
    """The type store: ROS 2 Jazzy's standard messages plus :data:`CRTK_MSGS` (built once)."""
    store = get_typestore(Stores.ROS2_JAZZY)
    for name, text in CRTK_MSGS.items():
        store.register(get_types_from_msg(text, name))
    return store


def dds_type_name(name: str) -> str:
    """The DDS type name rmw_zenoh puts in key expressions: ``sensor_msgs/msg/JointState`` ->
    ``sensor_msgs::msg::dds_::JointState_``.

    Raises
    ------
    CodecError
        ``name`` is not ``<package>/msg/<Type>``.
    """
    parts = name.split("/")
    if len(parts) != 3 or parts[1] != "msg" or not all(parts):
        raise CodecError(f"ROS 2 type name {name!r} is not <package>/msg/<Type>")
    return f"{parts[0]}::msg::dds_::{parts[2]}_"


@functools.cache
def type_hash(name: str) -> str:
    """The RIHS01 type hash of a registered type (REP 2011), ``RIHS01_<64 hex digits>``."""
    return str(typestore().hash_rihs01(name))


def encode(msg: Any, name: str) -> bytes:
    """CDR bytes (encapsulation header first) of a type-store message ``msg`` of type ``name``."""
    return bytes(typestore().serialize_cdr(msg, name))


def decode(data: bytes, name: str) -> Any:
    """The message of type ``name`` in the CDR bytes ``data``.

    Raises
    ------
    CodecError
        The bytes are not a CDR message of that type.
    """
    try:
        return typestore().deserialize_cdr(bytes(data), name)
    except Exception as e:  # noqa: BLE001 - rosbags raises several kinds; one clear error for the caller
        raise CodecError(f"not a CDR {name}: {e}") from None


def stamp_ns(msg: Any) -> int:
    """The header stamp of a decoded message [ns since the UNIX epoch]; 0 marks invalid data (CRTK)."""
    s = msg.header.stamp
    return int(s.sec) * 1_000_000_000 + int(s.nanosec)


def _header(t_ns: int, frame_id: str) -> Any:
    t = typestore().types
    sec, nsec = divmod(int(t_ns), 1_000_000_000)
    return t["std_msgs/msg/Header"](stamp=t["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec), frame_id=frame_id)


def _array(values: Sequence[float] | None, n: int) -> np.ndarray:
    vals = () if values is None else tuple(map(float, values))
    if len(vals) not in (0, n) or not math.isfinite(sum(vals)):   # one sum catches NaN and inf
        raise CodecError(f"joint state: {len(vals)} values for {n} joints, or a non-finite one")
    return np.array(vals, dtype=np.float64)


def joint_state(t_ns: int, names: Sequence[str], position: Sequence[float] | None = None,
                velocity: Sequence[float] | None = None, effort: Sequence[float] | None = None,
                frame_id: str = "") -> bytes:
    """CDR bytes of a ``sensor_msgs/msg/JointState``: stamp ``t_ns`` [ns, UNIX epoch; 0 = invalid], one
    name per joint, positions [m or rad], velocities, efforts [N or N m] (each list empty or one per joint).

    Raises
    ------
    CodecError
        A non-empty list of another length than ``names``, or a non-finite value.
    """
    n = len(names)
    js = typestore().types[JOINT_STATE](header=_header(t_ns, frame_id), name=list(names),
                                        position=_array(position, n), velocity=_array(velocity, n),
                                        effort=_array(effort, n))
    return encode(js, JOINT_STATE)


def wrench_stamped(t_ns: int, force: Sequence[float], torque: Sequence[float], frame_id: str = "") -> bytes:
    """CDR bytes of a ``geometry_msgs/msg/WrenchStamped``: force [N] and torque [N m] as (x, y, z).

    Raises
    ------
    CodecError
        A non-finite component.
    """
    if not all(math.isfinite(v) for v in (*force, *torque)):
        raise CodecError("wrench: a non-finite component")
    t = typestore().types
    v3 = t["geometry_msgs/msg/Vector3"]
    wrench = t["geometry_msgs/msg/Wrench"](force=v3(*map(float, force)), torque=v3(*map(float, torque)))
    return encode(t[WRENCH_STAMPED](header=_header(t_ns, frame_id), wrench=wrench), WRENCH_STAMPED)


def operating_state(t_ns: int, state: str, is_homed: bool, is_busy: bool) -> bytes:
    """CDR bytes of a ``crtk_msgs/msg/OperatingState`` (``state``: DISABLED, ENABLED, PAUSED or FAULT)."""
    msg = typestore().types[OPERATING_STATE](header=_header(t_ns, ""), state=state, is_homed=bool(is_homed),
                                             is_busy=bool(is_busy))
    return encode(msg, OPERATING_STATE)


def string_stamped(t_ns: int, text: str) -> bytes:
    """CDR bytes of a ``crtk_msgs/msg/StringStamped`` (the CRTK ``state_command``: enable, disable, pause, resume)."""
    return encode(typestore().types[STRING_STAMPED](header=_header(t_ns, ""), string=text), STRING_STAMPED)


def warm_up() -> None:
    """Build the type store and rosbags' serialisers and deserialisers of :data:`TYPES` now.

    rosbags generates them on first use; a process builds them before its loop starts, so that the loop's
    garbage collector freezes them with the rest of the set-up (:meth:`teleop.node.NodeBase.run`) instead
    of scanning them in its collections.
    """
    for name, data in ((JOINT_STATE, joint_state(0, ("warm",), (0.0,), None, (0.0,))),
                       (WRENCH_STAMPED, wrench_stamped(0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))),
                       (OPERATING_STATE, operating_state(0, "DISABLED", False, False)),
                       (STRING_STAMPED, string_stamped(0, "enable"))):
        decode(data, name)
        type_hash(name)
