"""ROS 2 on Zenoh with no bridge: key expressions, attachments and liveliness tokens as rmw_zenoh spells them.

The format followed is that of rmw_zenoh release 0.2.5 (Jazzy, 2025-06-18), ``docs/design.md`` of
github.com/ros2/rmw_zenoh, sections "Topic and Service name mapping to Zenoh key expressions", "Graph
Cache" and "Publishers" (the attachment layout there is the one of ``attachment_helpers.cpp`` since
0.2.4). In short:

* a message is a Zenoh ``put`` on ``<domain_id>/<topic>/<dds type name>/<RIHS01 type hash>``, the topic
  without its leading ``/`` (``0/tsm0/measured_js/sensor_msgs::msg::dds_::JointState_/RIHS01_...``),
  its payload the CDR bytes (:mod:`teleop.ros2.types`);
* its attachment: sequence number (int64), source timestamp (int64, ns since the UNIX epoch), the
  length of the publisher GID (one byte, 16) and the GID (16 bytes), integers little-endian;
* every node and every publisher or subscription declares a liveliness token (``ros2 topic list``
  and ``ros2 node list`` read the graph from them)::

      @ros2_lv/<domain>/<session id>/<node id>/<node id>/NN/<enclave>/<namespace>/<node name>
      @ros2_lv/<domain>/<session id>/<node id>/<entity id>/MP|MS/<enclave>/<namespace>/<node name>/
          <mangled topic>/<dds type name>/<type hash>/<qos>

  a mangled name has every ``/`` replaced by ``%`` (``%`` alone for an empty name); ``<qos>`` is
  ``qos_to_keyexpr`` of rmw_zenoh (empty fields where the QoS is rmw_zenoh's default; here reliable,
  volatile, keep-last 10: ``::,10:,:,:,,``);
* the GID of an entity is the 128-bit XXH3 hash of its liveliness key, low 64 bits first (both
  little-endian), as ``liveliness_utils.cpp`` computes it.
"""
from __future__ import annotations

import re
import struct
import time
from collections.abc import Callable
from typing import Any, NamedTuple

import xxhash
import zenoh

from teleop.errors import CodecError, ConfigError
from teleop.ros2.types import dds_type_name, type_hash

__all__ = ["RMW_ZENOH_RELEASE", "ADMIN_SPACE", "DEFAULT_QOS", "ATTACHMENT", "Attachment", "ros_name", "mangle",
           "topic_key", "node_token", "entity_token", "gid", "encode_attachment", "decode_attachment", "RosNode",
           "RosPublisher", "RosSubscriber"]

#: the rmw_zenoh release whose docs/design.md this module follows
RMW_ZENOH_RELEASE = "0.2.5"
ADMIN_SPACE = "@ros2_lv"
#: qos_to_keyexpr of reliable, volatile, keep-last depth 10 (rmw_zenoh's defaults but the depth, which is 42)
DEFAULT_QOS = "::,10:,:,:,,"
ATTACHMENT = struct.Struct("<qqB16s")
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


class Attachment(NamedTuple):
    """The rmw_zenoh attachment of one message: sequence number, source time [ns, UNIX epoch], GID (16 bytes)."""

    seq: int
    t_ns: int
    gid: bytes


def ros_name(text: str) -> str:
    """A valid ROS 2 name token for ``text`` (an instrument id): ``-`` becomes ``_``, a leading digit gets
    ``arm_`` in front (``tsm0`` -> ``tsm0``, ``7-dof`` -> ``arm_7_dof``).

    Raises
    ------
    ConfigError
        Empty, or with characters other than letters, digits, ``_`` and ``-``.
    """
    name = str(text).replace("-", "_")
    name = f"arm_{name}" if name[:1].isdigit() else name
    if not _NAME.fullmatch(name):
        raise ConfigError(f"ros2: {text!r} cannot be a ROS 2 name (letters, digits, '_' or '-' only)")
    return name


def mangle(name: str) -> str:
    """``/`` -> ``%`` (a name of a liveliness token; ``%`` for the empty name)."""
    return name.replace("/", "%") if name else "%"


def topic_key(domain_id: int, topic: str, type_name: str) -> str:
    """The key expression of a topic: ``<domain_id>/<topic without the outer slashes>/<dds type>/<hash>``."""
    return f"{int(domain_id)}/{topic.strip('/')}/{dds_type_name(type_name)}/{type_hash(type_name)}"


def node_token(domain_id: int, zid: str, node_id: int, node: str, namespace: str = "") -> str:
    """The liveliness key of a node (``NN``)."""
    return f"{ADMIN_SPACE}/{int(domain_id)}/{zid}/{node_id}/{node_id}/NN/%/{mangle(namespace)}/{node}"


def entity_token(domain_id: int, zid: str, node_id: int, entity_id: int, kind: str, node: str, topic: str,
                 type_name: str, namespace: str = "", qos: str = DEFAULT_QOS) -> str:
    """The liveliness key of a publisher (``kind`` ``MP``) or subscription (``MS``) of ``topic`` (a fully
    qualified name, ``/tsm0/measured_js``)."""
    if kind not in ("MP", "MS"):
        raise ValueError(f"entity kind {kind!r} is not MP or MS")
    return (f"{ADMIN_SPACE}/{int(domain_id)}/{zid}/{node_id}/{entity_id}/{kind}/%/{mangle(namespace)}/{node}/"
            f"{mangle(topic)}/{dds_type_name(type_name)}/{type_hash(type_name)}/{qos}")


def gid(token: str) -> bytes:
    """The 16-byte GID of the entity whose liveliness key is ``token`` (XXH3-128, low 64 bits first)."""
    return xxhash.xxh3_128_intdigest(token.encode()).to_bytes(16, "little")


def encode_attachment(seq: int, t_ns: int, gid_bytes: bytes) -> bytes:
    """The 33 attachment bytes of one message (module docstring)."""
    return ATTACHMENT.pack(int(seq), int(t_ns), len(gid_bytes), gid_bytes)


def decode_attachment(data: bytes) -> Attachment:
    """The attachment in ``data``.

    Raises
    ------
    CodecError
        Not 33 bytes, or a GID length other than 16.
    """
    if len(data) != ATTACHMENT.size:
        raise CodecError(f"rmw_zenoh attachment: {len(data)} bytes, expected {ATTACHMENT.size}")
    seq, t_ns, n, g = ATTACHMENT.unpack(data)
    if n != 16:
        raise CodecError(f"rmw_zenoh attachment: GID length {n}, expected 16")
    return Attachment(seq, t_ns, g)


class RosNode:
    """One ROS 2 node on a Zenoh session: its ``NN`` token, and its publishers and subscriptions.

    Parameters
    ----------
    session : zenoh.Session
    domain_id : int
        ROS_DOMAIN_ID.
    name : str
        The node name (a ROS name token).
    node_id : int
        The node's id within the session's context.
    """

    def __init__(self, session: zenoh.Session, domain_id: int, name: str, node_id: int = 0):
        self.session, self.domain_id, self.name, self.node_id = session, int(domain_id), name, node_id
        self.zid = str(session.info.zid())
        self._next_id = 1
        self._owned: list[Any] = [session.liveliness().declare_token(
            node_token(self.domain_id, self.zid, node_id, name))]

    def _entity(self, kind: str, topic: str, type_name: str) -> str:
        eid, self._next_id = self._next_id, self._next_id + 1
        return entity_token(self.domain_id, self.zid, self.node_id, eid, kind, self.name, topic, type_name)

    def publisher(self, topic: str, type_name: str) -> RosPublisher:
        """A publisher of ``type_name`` on ``topic`` (its ``MP`` token declared)."""
        pub = RosPublisher(self, topic, type_name, self._entity("MP", topic, type_name))
        self._owned.append(pub)
        return pub

    def subscription(self, topic: str, type_name: str, callback: Callable[[bytes, Attachment | None], None]) \
            -> RosSubscriber:
        """A subscription of ``type_name`` on ``topic`` calling ``callback(cdr_bytes, attachment)`` on
        Zenoh's thread (its ``MS`` token declared)."""
        sub = RosSubscriber(self, topic, type_name, self._entity("MS", topic, type_name), callback)
        self._owned.append(sub)
        return sub

    def close(self) -> None:
        """Undeclare every entity and the node's token (idempotent; errors of a closed session ignored)."""
        owned, self._owned = self._owned, []
        for ent in reversed(owned):
            try:
                ent.undeclare() if hasattr(ent, "undeclare") else ent.close()
            except zenoh.ZError:
                pass


class RosPublisher:
    """Puts CDR messages on a topic's key with the rmw_zenoh attachment. Attribute ``seq``: the last
    sequence number sent (the first message carries 1)."""

    def __init__(self, node: RosNode, topic: str, type_name: str, token: str):
        self.topic, self.type_name, self.token, self.gid = topic, type_name, token, gid(token)
        self.key = topic_key(node.domain_id, topic, type_name)
        self.seq = 0
        self._pub = node.session.declare_publisher(self.key, congestion_control=zenoh.CongestionControl.DROP,
                                                   reliability=zenoh.Reliability.RELIABLE)
        self._token = node.session.liveliness().declare_token(token)

    def put(self, cdr: bytes, t_ns: int | None = None) -> None:
        """Send the CDR bytes ``cdr``; the attachment's source time is ``t_ns`` [ns] or now."""
        self.seq += 1
        self._pub.put(cdr, attachment=encode_attachment(self.seq, time.time_ns() if t_ns is None else t_ns,
                                                        self.gid))

    def close(self) -> None:
        self._token.undeclare()
        self._pub.undeclare()


class RosSubscriber:
    """Receives a topic's messages; ``count`` messages handed to the callback, ``errors`` callbacks that raised."""

    def __init__(self, node: RosNode, topic: str, type_name: str, token: str,
                 callback: Callable[[bytes, Attachment | None], None]):
        self.topic, self.type_name, self.token = topic, type_name, token
        self.key = topic_key(node.domain_id, topic, type_name)
        self.callback = callback
        self.count = self.errors = 0
        self._sub = node.session.declare_subscriber(self.key, self._on_sample)
        self._token = node.session.liveliness().declare_token(token)

    def _on_sample(self, sample: zenoh.Sample) -> None:
        try:
            raw = sample.attachment
            att = None if raw is None else decode_attachment(raw.to_bytes())
            self.callback(sample.payload.to_bytes(), att)
            self.count += 1
        except Exception:  # noqa: BLE001 - a bad message must never kill Zenoh's callback thread
            self.errors += 1

    def close(self) -> None:
        self._token.undeclare()
        self._sub.undeclare()
