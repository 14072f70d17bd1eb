"""The recorder's MCAP file: every message of a session in one ``recorder/session.mcap``.

Every message the recorder writes (received, or recovered from a side's journal) goes to the MCAP
file as well: the whole message as JSON on the channel of its key, and, where a standard ROS 2 type
exists, the same content under the slave's CRTK names (:mod:`teleop.ros2.crtk`, ``<arm>`` the instrument id
as a ROS name; docs/reference/crtk.md):

==================================  ==================================  ==========================================
topic                               schema (encoding)                   content
==================================  ==================================  ==========================================
``/teleop/<id>/<side>/<stream>``    ``teleop.<Type>`` (jsonschema,      the whole decoded message (command,
                                    json)                               estimate, heartbeat, rig messages)
``/<arm>/measured_js``              ``sensor_msgs/msg/JointState``      per axis: a tendon's ``x_in`` [m] and ``T_in``
                                    (ros2msg, cdr)                      [N]; a pair's angle [rad] and proximal torque
                                                                        ``r (T_in,a - T_in,b)`` [N m]
``/<arm>/actuators/measured_js``    ``sensor_msgs/msg/JointState``      per tendon: ``x_in`` [m], ``T_in`` [N]
``/<arm>/distal/measured_js``       ``sensor_msgs/msg/JointState``      per axis: ``position_hat`` [m or rad],
                                                                        ``effort_hat`` [N or N m]
``/<arm>/measured_cf``              ``geometry_msgs/msg/WrenchStamped``  single tendon: the estimated distal tension
                                                                        as ``force.z`` [N]
``/<arm>/<joint>/measured_cf``      ``geometry_msgs/msg/WrenchStamped``  joint: the estimated torque as ``torque.z``
                                                                        [N m]
``/<arm>/servo_jp``                 ``sensor_msgs/msg/JointState``      the master's command: one target per axis
                                                                        [m or rad]
==================================  ==================================  ==========================================

A 1 kHz stream (every stream but the heartbeats) is kept at ``recording.mcap_every``: its messages whose
``seq`` is a multiple of it, on every channel (default 20: 50 Hz, the view a reader browses); ``messages.bin``
holds every message, and with ``recording.mcap_every: 1`` so does this file. The heartbeats (50 Hz), the state
changes they carry and messages without a ``seq`` are all kept.

Times: ``log_time`` is the recorder's time of the message (its receive time; a message recovered from a
journal: its publish time), ``publish_time`` the sender's own stamp (``t_slave``, ``t_master``,
``t_sender``, ``t``), both as Unix nanoseconds: the monotonic clocks are mapped with the offset
``time.time() - time.monotonic()`` taken when the recorder starts (kept in the ``teleop`` metadata
record, with the instrument, so that a reader can go back to the monotonic times of the CSVs). The
ROS 2 header stamp is the publish time. A sender's stamp is comparable with the log time only when
both ran on one machine (one monotonic clock).

Chunks are zstd-compressed and closed every :data:`CHUNK_INTERVAL` seconds, so a SIGKILL of the recorder
leaves a file readable up to its last closed chunk (``rerun mcap convert --recover``); ``teleop record
--repair RUN`` (:mod:`live.record.mcap_read`) rebuilds the whole file from ``messages.bin`` and the
sides' journals. A message recovered into a gap has an older log time than the one written before it:
at the end the file is rewritten in log-time order (the CSVs are sorted the same way).
"""
from __future__ import annotations

import dataclasses
import enum
import json
import os
import time
import typing
from collections.abc import Callable
from pathlib import Path
from typing import Any

from mcap.reader import make_reader
from mcap.writer import CompressionType, IndexType, Writer
from mcap_ros2._dynamic import serialize_dynamic  # the CDR encoder mcap_ros2.writer.Writer uses

from live.record.budget import is_low_rate

__all__ = ["MCAP_NAME", "CHUNK_INTERVAL", "McapRecording", "to_json", "json_schema", "sender_stamp", "sort_mcap",
           "ROS2_SCHEMAS"]

MCAP_NAME = "session.mcap"
CHUNK_INTERVAL = 1.0        # [s] a chunk is closed (compressed, written) at least this often
# no message index records (16 B per message, uncompressed: 40 % of the file): readers find the messages
# through the chunk indexes, each chunk holding about CHUNK_INTERVAL of them
INDEXES = IndexType.CHUNK | IndexType.ATTACHMENT | IndexType.METADATA
_SEP = "=" * 80 + "\n"
_TIME = "int32 sec\nuint32 nanosec\n"
_HEADER = "builtin_interfaces/Time stamp\nstring frame_id\n"
_DEPS = f"{_SEP}MSG: std_msgs/Header\n{_HEADER}{_SEP}MSG: builtin_interfaces/Time\n{_TIME}"
_VECTOR3 = "float64 x\nfloat64 y\nfloat64 z\n"
#: ROS 2 message definitions (ros2msg: the .msg text, then each dependency after a separator line)
ROS2_SCHEMAS = {
    "sensor_msgs/msg/JointState": ("std_msgs/Header header\nstring[] name\nfloat64[] position\n"
                                   "float64[] velocity\nfloat64[] effort\n" + _DEPS),
    "geometry_msgs/msg/WrenchStamped": ("std_msgs/Header header\ngeometry_msgs/Wrench wrench\n" + _DEPS
                                        + f"{_SEP}MSG: geometry_msgs/Wrench\ngeometry_msgs/Vector3 force\n"
                                        f"geometry_msgs/Vector3 torque\n{_SEP}MSG: geometry_msgs/Vector3\n{_VECTOR3}"),
}
_STAMPS = ("t_slave", "t_master", "t_sender", "t")


_FIELDS: dict[type, tuple[str, ...]] = {}


def to_json(x: Any) -> Any:
    """A decoded message as plain JSON values: dataclasses -> objects, tuples -> arrays, enums -> ints."""
    kind = type(x)
    if kind is float or kind is int:
        return x
    names = _FIELDS.get(kind)
    if names is None and dataclasses.is_dataclass(x):
        names = _FIELDS[kind] = tuple(f.name for f in dataclasses.fields(x))
    if names is not None:
        return {n: to_json(getattr(x, n)) for n in names}
    if isinstance(x, (tuple, list)):
        return list(x) if all(type(v) is float for v in x) else [to_json(v) for v in x]
    if isinstance(x, enum.Enum):
        return int(x.value)
    return x


def json_schema(x: Any) -> dict:
    """A JSON Schema (draft 2020-12) of a message class or instance, from its dataclass field types."""
    kind = x if isinstance(x, type) else type(x)
    return _type_schema(kind)


def _type_schema(tp: Any) -> dict:
    if dataclasses.is_dataclass(tp) and isinstance(tp, type):
        hints = typing.get_type_hints(tp)
        names = [f.name for f in dataclasses.fields(tp)]
        return {"type": "object", "title": tp.__name__, "required": names,
                "properties": {n: _type_schema(hints[n]) for n in names}}
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin in (tuple, list):
        items = [a for a in args if a is not Ellipsis]
        if len(items) > 1 and len(set(items)) == 1:      # a fixed-length tuple of one type
            return {"type": "array", "items": _type_schema(items[0]), "minItems": len(items),
                    "maxItems": len(items)}
        return {"type": "array", "items": _type_schema(items[0]) if items else {}}
    if tp is bool:
        return {"type": "boolean"}
    if isinstance(tp, type) and issubclass(tp, enum.Enum):
        return {"type": "integer", "enum": [int(m.value) for m in tp], "description": ", ".join(
            f"{int(m.value)} = {m.name}" for m in tp)}
    if tp is int:
        return {"type": "integer"}
    return {"type": "number"}


def sender_stamp(msg: Any) -> float | None:
    """The sender's own time stamp of a decoded message [s, its monotonic clock], None when it has none."""
    return next((getattr(msg, n) for n in _STAMPS if isinstance(getattr(msg, n, None), float)), None)


def _ns(t: float, offset_ns: int) -> int:
    """Monotonic ``t`` [s] as Unix nanoseconds (>= 0); the offset is added in integers (a double near 1.7e9 s
    resolves only 0.2 us)."""
    return max(0, round(t * 1e9) + offset_ns)


def _stamp(ns: int) -> dict:
    return {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000}


_JS = "sensor_msgs/msg/JointState"


def _joint_state(ns: int, names, position, effort) -> dict:
    return {"header": {"stamp": _stamp(ns), "frame_id": ""}, "name": list(names), "position": list(position),
            "velocity": [], "effort": list(effort)}


class McapRecording:
    """Write the recorder's messages to one MCAP file (module docstring).

    Parameters
    ----------
    path : Path
        The file (created, truncated).
    cfg : Config
        ``instrument``: its id, and its joints (names, pulley radii) for the CRTK channels.
    clock_offset : float
        Unix time minus the recorder's monotonic clock [s].
    t_start : float
        The recorder's start [s, monotonic] (kept in the metadata: journals before it are not this session's).
    every : int, optional
        ``recording.mcap_every`` (default: the config's): a 1 kHz stream's messages kept, by ``seq`` (module docstring).
    """

    def __init__(self, path: Path, cfg: Any, clock_offset: float, t_start: float = 0.0, every: int | None = None):
        from teleop.ros2.crtk import axis_names, slave_arm, tendon_names
        self.every = max(1, int(cfg.recording.mcap_every if every is None else every))
        self.path, self.offset = Path(path), float(clock_offset)
        self._offset_ns = round(self.offset * 1e9)
        instrument = cfg.instrument.id
        self.arm = "/" + slave_arm(cfg)
        self.axis_names, self.tendon_names = axis_names(cfg), tendon_names(cfg)
        self.radii = tuple(j.pulley_radius for j in cfg.instrument.joints)
        self._fh = open(self.path, "wb")
        self._w = Writer(self._fh, compression=CompressionType.ZSTD, index_types=INDEXES)
        self._w.start(profile="ros2", library="tsm-teleop (mcap, mcap-ros2-support)")
        self._w.add_metadata("teleop", {"instrument": instrument, "clock_offset_s": repr(self.offset),
                                        "t_start_s": repr(float(t_start)), "mcap_every": str(self.every),
                                        "time": "log: recorder time; publish: sender stamp (Unix ns)"})
        self._schemas: dict[str, int] = {}
        self._encoders: dict[str, Callable[[Any], bytes]] = {}
        self._channels: dict[str, int] = {}
        self._seqs: dict[int, int] = {}
        self.messages = 0
        self._last_log: dict[str, int] = {}
        self._last_pub: dict[str, int] = {}
        self.unsorted = False
        self._last_flush = time.monotonic()

    # ---- channels ------------------------------------------------------------------------------------
    def _ros_channel(self, topic: str, datatype: str) -> int:
        cid = self._channels.get(topic)
        if cid is None:
            sid = self._schemas.get(datatype)
            if sid is None:
                text = ROS2_SCHEMAS[datatype]
                sid = self._schemas[datatype] = self._w.register_schema(datatype, "ros2msg", text.encode())
                self._encoders[datatype] = serialize_dynamic(datatype, text)[datatype]
            cid = self._channels[topic] = self._w.register_channel(topic, "cdr", sid, {"datatype": datatype})
        return cid

    def _json_channel(self, key: str, msg: Any) -> int:
        topic = "/" + key
        cid = self._channels.get(topic)
        if cid is None:
            name = f"teleop.{type(msg).__name__}"
            sid = self._schemas.get(name)
            if sid is None:
                schema = {"$schema": "https://json-schema.org/draft/2020-12/schema", **json_schema(msg)}
                sid = self._schemas[name] = self._w.register_schema(name, "jsonschema", json.dumps(schema).encode())
            cid = self._channels[topic] = self._w.register_channel(topic, "json", sid, {"key": key})
        return cid

    def _add(self, cid: int, log: int, pub: int, data: bytes) -> None:
        seq = self._seqs.get(cid, 0)
        self._seqs[cid] = seq + 1
        self._w.add_message(cid, log_time=log, publish_time=pub, data=data, sequence=seq)
        self.messages += 1

    def _ros(self, topic: str, datatype: str, log: int, pub: int, msg: dict) -> None:
        cid = self._ros_channel(topic, datatype)
        self._add(cid, log, pub, self._encoders[datatype](msg))

    # ---- messages ------------------------------------------------------------------------------------
    def write(self, t: float, key: str, msg: Any, recovered: bool = False) -> None:
        """Write one decoded message of ``key`` logged at ``t`` [s, recorder's monotonic clock].

        A message ``recovered`` from its sender's journal (``t`` its journal time) that was published after
        every message written on its key is logged no earlier than the last of them: its journal time
        precedes the receive time of a message published just before it, and the log and publish times
        of a topic must order its messages alike (``rerun mcap check``). A 1 kHz stream's message whose ``seq``
        is not a multiple of :attr:`every` is left out (module docstring)."""
        if self.every > 1 and not is_low_rate(key) and getattr(msg, "seq", 0) % self.every:
            return
        log = _ns(t, self._offset_ns)
        stamp = sender_stamp(msg)
        pub = log if stamp is None else _ns(stamp, self._offset_ns)
        last, last_pub = self._last_log.get(key, -1), self._last_pub.get(key, -1)
        if recovered and pub >= last_pub:
            log = max(log, last)
        if log < last:
            self.unsorted = True                  # a message older than one before it on its key
        self._last_log[key], self._last_pub[key] = max(last, log), max(last_pub, pub)
        self._add(self._json_channel(key, msg), log, pub,
                  json.dumps(to_json(msg), separators=(",", ":"), allow_nan=False).encode())
        kind = type(msg).__name__
        if kind == "Estimate":
            self._estimate(key, log, pub, msg)
        elif kind == "Command":
            self._ros(f"{self.arm}/servo_jp", _JS, log, pub,
                      _joint_state(pub, self._names(self.axis_names, len(msg.targets)), msg.targets, ()))

    @staticmethod
    def _names(names: tuple[str, ...], n: int) -> tuple[str, ...]:
        return names if len(names) == n else tuple(f"axis{i}" for i in range(n))

    def _estimate(self, key: str, log: int, pub: int, msg: Any) -> None:
        axes = self._names(self.axis_names, len(msg.axes))
        tendons = msg.tendons
        pair = len(self.radii) == len(msg.axes) and all(len(a.tendons) == 2 for a in msg.axes)
        if pair:                              # a pair's angle and proximal torque r (T_in,a - T_in,b)
            pos = [a.position_hat for a in msg.axes]
            eff = [r * (a.tendons[0].T_in - a.tendons[1].T_in) for a, r in zip(msg.axes, self.radii, strict=False)]
        else:
            pos, eff = [a.tendons[0].x_in for a in msg.axes], [a.tendons[0].T_in for a in msg.axes]
        self._ros(f"{self.arm}/measured_js", _JS, log, pub, _joint_state(pub, axes, pos, eff))
        self._ros(f"{self.arm}/actuators/measured_js", _JS, log, pub,
                  _joint_state(pub, self._names(self.tendon_names, len(tendons)), [t.x_in for t in tendons],
                               [t.T_in for t in tendons]))
        self._ros(f"{self.arm}/distal/measured_js", _JS, log, pub,
                  _joint_state(pub, axes, [a.position_hat for a in msg.axes], [a.effort_hat for a in msg.axes]))
        frame = f"{self.arm[1:]}_distal"
        for n, a in zip(axes, msg.axes, strict=False):
            force = {"x": 0.0, "y": 0.0, "z": 0.0 if pair else a.effort_hat}
            torque = {"x": 0.0, "y": 0.0, "z": a.effort_hat if pair else 0.0}
            topic = f"{self.arm}/{n}/measured_cf" if pair else f"{self.arm}/measured_cf"
            self._ros(topic, "geometry_msgs/msg/WrenchStamped", log, pub,
                      {"header": {"stamp": _stamp(pub), "frame_id": frame},
                       "wrench": {"force": force, "torque": torque}})

    # ---- flushing and the end ------------------------------------------------------------------------
    def flush(self, now: float | None = None) -> None:
        """Close the chunk under way and hand it to the OS, when :data:`CHUNK_INTERVAL` has passed since the
        last one (``now`` [s, :func:`time.monotonic`]) or always (``now`` None)."""
        now_ = time.monotonic() if now is None else now
        if now is not None and now_ - self._last_flush < CHUNK_INTERVAL:
            return
        self._w.flush()
        self._last_flush = now_

    def close(self) -> dict:
        """Finish the file (summary, indexes), rewrite it in log-time order when needed; returns
        ``{"path", "messages", "channels", "sorted_at_end"}``. Idempotent."""
        if not self._fh.closed:
            self._w.finish()
            self._fh.close()
            if self.unsorted:
                sort_mcap(self.path)
        return {"path": str(self.path), "messages": self.messages, "channels": len(self._channels),
                "sorted_at_end": self.unsorted}


def sort_mcap(path: Path) -> None:
    """Rewrite the MCAP file at ``path`` with its messages in log-time order (records copied, not re-encoded)."""
    tmp = Path(str(path) + ".sorting")
    with open(path, "rb") as src, open(tmp, "wb") as dst:
        reader = make_reader(src)
        header = reader.get_header()
        w = Writer(dst, compression=CompressionType.ZSTD, index_types=INDEXES)
        w.start(profile=header.profile, library=header.library)
        for meta in reader.iter_metadata():
            w.add_metadata(meta.name, meta.metadata)
        summary = reader.get_summary()
        if summary is None:
            raise OSError(f"{path}: no MCAP summary to sort by")
        sids = {s.id: w.register_schema(s.name, s.encoding, s.data) for s in summary.schemas.values()}
        ids = {c.id: w.register_channel(c.topic, c.message_encoding, sids[c.schema_id], dict(c.metadata))
               for c in summary.channels.values()}
        for _, channel, m in reader.iter_messages(log_time_order=True):
            w.add_message(ids[channel.id], log_time=m.log_time, publish_time=m.publish_time, data=m.data,
                          sequence=m.sequence)
        w.finish()
    os.replace(tmp, path)
