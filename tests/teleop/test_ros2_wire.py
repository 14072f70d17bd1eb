"""The ROS 2 side of the wire: RIHS01 hashes, rmw_zenoh key expressions and attachments, CDR of the CRTK topics.

Expected values come from outside the code under test: the RIHS01 hashes are recomputed here with
REP 2011's algorithm (sha256 over the type description JSON) from the message definitions written
out below, one is checked against the value rmw_zenoh's design document (release 0.2.5) quotes, the
key expressions against the document's examples, and the CDR bytes are decoded by mcap-ros2-support's
own decoder (``mcap_ros2._dynamic``), not by rosbags.
"""
from __future__ import annotations

import struct

import pytest

from estimator.phase import Phase
from teleop.config.schema import Config, JointConfig
from teleop.errors import CodecError, ConfigError
from teleop.ros2.crtk import OPERATING, servo_targets, slave_messages, slave_topics
from teleop.ros2.types import JOINT_STATE, OPERATING_STATE, STRING_STAMPED, WRENCH_STAMPED, decode, type_hash
from teleop.ros2.wire import decode_attachment, encode_attachment, entity_token, gid, node_token, ros_name, topic_key
from teleop.wire.messages import AxisState, Estimate, SideState, TendonState, tendon_estimate
from tests.ros2_peer import independent_decoder, rihs01

#: quoted in rmw_zenoh 0.2.5 docs/design.md ("chatter" topic example)
STRING_HASH_IN_DESIGN = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"


def test_the_independent_rep2011_hash_reproduces_the_design_documents_value():
    assert rihs01("std_msgs/msg/String") == STRING_HASH_IN_DESIGN


@pytest.mark.parametrize("name", [JOINT_STATE, WRENCH_STAMPED, OPERATING_STATE, STRING_STAMPED, "std_msgs/msg/String"])
def test_type_hashes_equal_rep2011_over_the_definitions(name):
    assert type_hash(name) == rihs01(name)


# ---- key expressions, liveliness tokens, attachment (rmw_zenoh 0.2.5 docs/design.md) ---------------------------

def test_key_expressions_and_tokens_are_the_design_documents_examples():
    assert topic_key(0, "/chatter", "std_msgs/msg/String") == \
        f"0/chatter/std_msgs::msg::dds_::String_/{STRING_HASH_IN_DESIGN}"
    assert topic_key(0, "/robot1/chatter", "std_msgs/msg/String") == \
        f"0/robot1/chatter/std_msgs::msg::dds_::String_/{STRING_HASH_IN_DESIGN}"
    assert node_token(2, "aac3178e146ba6f1fc6e6a4085e77f21", 0, "listener") == \
        "@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/0/NN/%/%/listener"
    assert entity_token(2, "8b20917502ee955ac4476e0266340d5c", 0, 10, "MP", "talker", "/chatter",
                        "std_msgs/msg/String", qos="::,7:,:,:,,") == \
        ("@ros2_lv/2/8b20917502ee955ac4476e0266340d5c/0/10/MP/%/%/talker/%chatter/std_msgs::msg::dds_::String_/"
         f"{STRING_HASH_IN_DESIGN}/::,7:,:,:,,")
    assert topic_key(3, "/tsm0/measured_js", JOINT_STATE) == \
        f"3/tsm0/measured_js/sensor_msgs::msg::dds_::JointState_/{rihs01(JOINT_STATE)}"


def test_the_attachment_is_seq_time_gid_length_and_gid_little_endian():
    g = gid("@ros2_lv/0/abc/0/1/MP/%/%/n/%t/std_msgs::msg::dds_::String_/h/::,10:,:,:,,")
    raw = encode_attachment(7, 1_700_000_000_123_456_789, g)
    assert len(raw) == 33 and len(g) == 16
    assert int.from_bytes(raw[0:8], "little", signed=True) == 7
    assert int.from_bytes(raw[8:16], "little", signed=True) == 1_700_000_000_123_456_789
    assert raw[16] == 16 and raw[17:] == g
    assert decode_attachment(raw) == (7, 1_700_000_000_123_456_789, g)
    with pytest.raises(CodecError, match="33"):
        decode_attachment(raw[:-1])
    with pytest.raises(CodecError, match="GID length"):
        decode_attachment(struct.pack("<qqB16s", 1, 2, 8, g))


def test_ros_names_of_instrument_ids():
    assert ros_name("tsm0") == "tsm0" and ros_name("my-tool") == "my_tool" and ros_name("7dof") == "arm_7dof"
    with pytest.raises(ConfigError, match="ROS 2 name"):
        ros_name("a/b")


# ---- CDR of the CRTK topics, read back by mcap-ros2-support's decoder ------------------------------------------

def _pair_config() -> Config:
    return Config(instrument=Config().instrument.__class__(id="wrist-tool", joints=(
        JointConfig(name="pitch", pulley_radius=0.004), JointConfig(name="yaw", pulley_radius=0.005))))


def test_the_slave_topics_decode_independently_to_the_estimate():
    cfg = Config()
    est = tendon_estimate(5, 4, 1.5, T_in=12.25, x_in=0.0031, T_out_hat=9.5, elongation_hat=0.0004,
                          x_out_hat=0.0027, phase=Phase.PULL)
    t_ns = 1_700_000_000_250_000_000
    msgs = dict(slave_messages(cfg, t_ns, SideState.ENGAGED, est, (0.003,)))
    assert set(msgs) == set(slave_topics(cfg))
    js, wr, op = (independent_decoder(n) for n in (JOINT_STATE, WRENCH_STAMPED, OPERATING_STATE))
    measured = js(msgs["/tsm0/measured_js"])
    assert (measured.header.stamp.sec, measured.header.stamp.nanosec) == (1_700_000_000, 250_000_000)
    assert list(measured.name) == ["tendon"]
    assert list(measured.position) == [0.0031] and list(measured.effort) == [12.25]
    distal = js(msgs["/tsm0/distal/measured_js"])
    assert list(distal.position) == [0.0027] and list(distal.effort) == [9.5]
    assert list(js(msgs["/tsm0/setpoint_js"]).position) == [0.003]
    cf = wr(msgs["/tsm0/measured_cf"])
    assert (cf.wrench.force.x, cf.wrench.force.y, cf.wrench.force.z) == (0.0, 0.0, 9.5)
    assert cf.wrench.torque.z == 0.0 and cf.header.frame_id == "tsm0_distal"
    state = op(msgs["/tsm0/operating_state"])
    assert (state.state, state.is_homed, state.is_busy) == ("ENABLED", True, True)


def test_a_joint_instrument_publishes_one_wrench_per_joint_and_an_invalid_setpoint_has_stamp_zero():
    cfg = _pair_config()
    axes = tuple(AxisState(effort_hat=0.01 * k, position_hat=0.1 * k,
                           tendons=(TendonState(5.0 + k, 0.001, 4.0, 1e-4, Phase.PULL),
                                    TendonState(3.0, -0.001, 2.5, 1e-4, Phase.RELEASE))) for k in (1, 2))
    msgs = dict(slave_messages(cfg, 123, SideState.SAFE, Estimate(1, 1, 0.0, axes), None))
    js, wr, op = (independent_decoder(n) for n in (JOINT_STATE, WRENCH_STAMPED, OPERATING_STATE))
    assert wr(msgs["/wrist_tool/yaw/measured_cf"]).wrench.torque.z == 0.02
    measured = js(msgs["/wrist_tool/measured_js"])
    assert list(measured.name) == ["pitch", "yaw"] and list(measured.position) == [0.1, 0.2]
    assert list(measured.effort) == [0.004 * (6.0 - 3.0), 0.005 * (7.0 - 3.0)]
    act = js(msgs["/wrist_tool/actuators/measured_js"])
    assert list(act.name) == ["pitch_a", "pitch_b", "yaw_a", "yaw_b"] and list(act.effort) == [6.0, 3.0, 7.0, 3.0]
    setpoint = js(msgs["/wrist_tool/setpoint_js"])
    assert (setpoint.header.stamp.sec, setpoint.header.stamp.nanosec) == (0, 0) and list(setpoint.position) == []
    assert op(msgs["/wrist_tool/operating_state"]).state == "PAUSED"


def test_every_side_state_has_a_crtk_operating_state():
    assert set(OPERATING) == set(SideState)
    assert {s for s, _, _ in OPERATING.values()} <= {"DISABLED", "ENABLED", "PAUSED", "FAULT"}


def test_servo_jp_targets_by_name_or_in_order_and_refusals():
    cfg = _pair_config()
    msg = decode(dict(slave_messages(cfg, 1, SideState.ENGAGED, None, (0.3, -0.2)))["/wrist_tool/setpoint_js"],
                 JOINT_STATE)
    assert servo_targets(msg, ("pitch", "yaw")) == (0.3, -0.2)
    assert servo_targets(msg, ("yaw", "pitch")) == (-0.2, 0.3)
    msg.name = []
    assert servo_targets(msg, ("yaw", "pitch")) == (0.3, -0.2)
    with pytest.raises(CodecError, match="expected 1"):
        servo_targets(msg, ("tendon",))
    msg.name = ["pitch", "roll"]
    with pytest.raises(CodecError, match="expected one for each"):
        servo_targets(msg, ("pitch", "yaw"))
