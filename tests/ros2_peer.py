"""An independent ROS 2 peer for the tests: REP 2011 type hashes, rmw_zenoh keys and attachments written
out from rmw_zenoh 0.2.5's docs/design.md, and CDR through mcap-ros2-support (not rosbags, which the
code under test uses).
"""
from __future__ import annotations

import hashlib
import json
import struct
import threading
import time

from mcap_ros2._dynamic import generate_dynamic, serialize_dynamic

from tests.zenoh_peer import raw_peer

JOINT_STATE = "sensor_msgs/msg/JointState"
WRENCH_STAMPED = "geometry_msgs/msg/WrenchStamped"
OPERATING_STATE = "crtk_msgs/msg/OperatingState"
STRING_STAMPED = "crtk_msgs/msg/StringStamped"

_IDS = {"nested": 1, "int32": 6, "uint32": 7, "float64": 11, "bool": 15, "string": 17}
_UNBOUNDED_SEQUENCE = 144            # type id offset of an unbounded sequence (rosidl type_description_interfaces)
DEFS = {
    "builtin_interfaces/msg/Time": [("sec", "int32"), ("nanosec", "uint32")],
    "std_msgs/msg/Header": [("stamp", "builtin_interfaces/msg/Time"), ("frame_id", "string")],
    "std_msgs/msg/String": [("data", "string")],
    "sensor_msgs/msg/JointState": [("header", "std_msgs/msg/Header"), ("name", "string[]"),
                                   ("position", "float64[]"), ("velocity", "float64[]"), ("effort", "float64[]")],
    "geometry_msgs/msg/Vector3": [("x", "float64"), ("y", "float64"), ("z", "float64")],
    "geometry_msgs/msg/Wrench": [("force", "geometry_msgs/msg/Vector3"), ("torque", "geometry_msgs/msg/Vector3")],
    "geometry_msgs/msg/WrenchStamped": [("header", "std_msgs/msg/Header"), ("wrench", "geometry_msgs/msg/Wrench")],
    "crtk_msgs/msg/OperatingState": [("header", "std_msgs/msg/Header"), ("state", "string"), ("is_homed", "bool"),
                                     ("is_busy", "bool")],
    "crtk_msgs/msg/StringStamped": [("header", "std_msgs/msg/Header"), ("string", "string")],
}


def _field(name: str, typ: str) -> dict:
    seq = typ.endswith("[]")
    base = typ.removesuffix("[]")
    nested = "/" in base
    tid = _IDS["nested" if nested else base] + (_UNBOUNDED_SEQUENCE if seq else 0)
    return {"name": name, "type": {"type_id": tid, "capacity": 0, "string_capacity": 0,
                                   "nested_type_name": base if nested else ""}}


def _referenced(name: str, seen: set[str]) -> None:
    for _, typ in DEFS[name]:
        base = typ.removesuffix("[]")
        if "/" in base and base not in seen:
            seen.add(base)
            _referenced(base, seen)


def rihs01(name: str) -> str:
    """REP 2011: sha256 of the type description (fields without default values, referenced types sorted by
    name) as JSON with ', ' and ': ' separators."""
    refs: set[str] = set()
    _referenced(name, refs)
    desc = {"type_description": {"type_name": name, "fields": [_field(*f) for f in DEFS[name]]},
            "referenced_type_descriptions": [{"type_name": r, "fields": [_field(*f) for f in DEFS[r]]}
                                             for r in sorted(refs)]}
    text = json.dumps(desc, separators=(", ", ": "))
    return "RIHS01_" + hashlib.sha256(text.encode()).hexdigest()


SCHEMAS = {
    JOINT_STATE: "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\nfloat64[] effort\n",
    WRENCH_STAMPED: "std_msgs/Header header\ngeometry_msgs/Wrench wrench\n",
    OPERATING_STATE: "std_msgs/Header header\nstring state\nbool is_homed\nbool is_busy\n",
    STRING_STAMPED: "std_msgs/Header header\nstring string\n",
}
DEPS = {
    "std_msgs/Header": "builtin_interfaces/Time stamp\nstring frame_id\n",
    "builtin_interfaces/Time": "int32 sec\nuint32 nanosec\n",
    "geometry_msgs/Wrench": "geometry_msgs/Vector3 force\ngeometry_msgs/Vector3 torque\n",
    "geometry_msgs/Vector3": "float64 x\nfloat64 y\nfloat64 z\n",
}


def independent_decoder(name: str):
    text = SCHEMAS[name] + "".join(f"{'=' * 80}\nMSG: {k}\n{v}" for k, v in DEPS.items())
    return generate_dynamic(name, text)[name]




def _schema(name: str) -> str:
    return SCHEMAS[name] + "".join(f"{'=' * 80}\nMSG: {k}\n{v}" for k, v in DEPS.items())


def independent_encoder(name: str):
    return serialize_dynamic(name, _schema(name))[name]


def dds(name: str) -> str:
    pkg, _, typ = name.split("/")
    return f"{pkg}::msg::dds_::{typ}_"


def key(domain: int, topic: str, name: str) -> str:
    """<domain_id>/<fully_qualified_name>/<type_name>/<type_hash> (design.md), the name without its leading '/'."""
    return f"{domain}/{topic.strip('/')}/{dds(name)}/{rihs01(name)}"


class RosPeer:
    """A ROS 2 node as rmw_zenoh makes one, on its own Zenoh session connected to ``endpoint`` (one or a list)."""

    def __init__(self, endpoint: str | list[str], domain: int = 0, node: str = "peer", credentials: str | None = None):
        self.z = raw_peer(endpoint, role=credentials)    # a live session admits only the installation's users
        self.domain, self.node, self.zid = domain, node, str(self.z.info.zid())
        self.received: dict[str, list] = {}
        self._lock = threading.Lock()
        self._keep = [self.z.liveliness().declare_token(f"@ros2_lv/{domain}/{self.zid}/0/0/NN/%/%/{node}")]
        self._seq = 0

    def subscribe(self, topic: str, name: str) -> None:
        """Collect (attachment bytes, decoded message) of every message on ``topic``."""
        decoder = independent_decoder(name)
        self.received[topic] = []

        def on(sample):
            att = sample.attachment
            with self._lock:
                self.received[topic].append((None if att is None else att.to_bytes(),
                                             decoder(sample.payload.to_bytes())))
        self._keep.append(self.z.declare_subscriber(key(self.domain, topic, name), on))

    def messages(self, topic: str) -> list:
        with self._lock:
            return list(self.received[topic])

    def publisher(self, topic: str, name: str, eid: int = 10):
        """Declare a publisher (its MP token, the demo talker's QoS) and return ``put(msg)``."""
        token = (f"@ros2_lv/{self.domain}/{self.zid}/0/{eid}/MP/%/%/{self.node}/{topic.replace('/', '%')}/"
                 f"{dds(name)}/{rihs01(name)}/::,10:,:,:,,")
        self._keep.append(self.z.liveliness().declare_token(token))
        pub = self.z.declare_publisher(key(self.domain, topic, name))
        self._keep.append(pub)
        encoder = independent_encoder(name)
        gid = hashlib.md5(token.encode()).digest()        # any 16 bytes identify the publisher

        def put(msg) -> None:
            self._seq += 1
            pub.put(encoder(msg), attachment=struct.pack("<qqB16s", self._seq, time.time_ns(), 16, gid))
        return put

    def tokens(self) -> list[str]:
        """Every rmw_zenoh liveliness token of the domain present now."""
        return [str(r.ok.key_expr) for r in self.z.liveliness().get(f"@ros2_lv/{self.domain}/**", timeout=2.0)
                if r.ok is not None]

    def close(self) -> None:
        self.z.close()


def joint_state(sec: int, names, position) -> dict:
    return {"header": {"stamp": {"sec": sec, "nanosec": 0}, "frame_id": ""}, "name": list(names),
            "position": list(position), "velocity": [], "effort": []}


def string_stamped(text: str) -> dict:
    return {"header": {"stamp": {"sec": 1, "nanosec": 0}, "frame_id": ""}, "string": text}
