"""The CRTK side on real Zenoh (127.0.0.1): topics a ROS 2 peer finds and decodes, servo_jp driving the
simulated instrument, state_command, and the master's topics. The peer is :mod:`tests.ros2_peer`
(keys, hashes and CDR of its own); waits poll a condition under a deadline."""
from __future__ import annotations

import dataclasses
import time

import pytest

from estimator.sheath import SheathModel
from master.node_base import MasterLinks
from slave.node import SlaveNode
from slave.node_base import SlaveLinks
from slave.simulated import SimulatedRig
from teleop.config.schema import Config, Ros2Config, TransportConfig
from teleop.errors import CodecError
from teleop.ros2 import types as ros2_types
from teleop.ros2.side import CommandMerge, attach_master, attach_slave
from teleop.session.transport import Session, free_tcp_port, loopback_endpoint
from teleop.timing.clock import FakeClock
from teleop.wire.messages import Command, SideState
from tests.fakes import Topic
from tests.ros2_peer import (
    JOINT_STATE,
    OPERATING_STATE,
    STRING_STAMPED,
    WRENCH_STAMPED,
    RosPeer,
    joint_state,
    string_stamped,
)

DT = 1e-3


def wait_for(predicate, timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return
        time.sleep(0.005)
    raise AssertionError(f"gave up waiting {timeout:g} s for {what}")


@pytest.fixture
def wire():
    """A teleop session listening on a free loopback port (on a FakeClock) and a ROS 2 peer connected to it."""
    ep = loopback_endpoint(free_tcp_port())
    clock = FakeClock(10.0)
    session = Session(TransportConfig(listen=(ep,), connect=()), clock=clock)
    peer = RosPeer(ep)
    yield session, peer, clock
    peer.close()
    session.close()


def slave_setup(session, clock, **ros2):
    cfg = Config(ros2=Ros2Config(enabled=True, **{"accept_commands": True, **ros2}))
    links = SlaveLinks(*(Topic(clock) for _ in range(4)))
    crtk = attach_slave(session, cfg, links)
    rig = SimulatedRig.from_config(cfg)
    node = SlaveNode(cfg, rig, links, calibrate=False, model=SheathModel(K=rig.K, compliance=rig.M_e))
    return cfg, links, crtk, node


def tick(node, clock, n: int) -> None:
    for _ in range(n):
        clock.advance(DT)
        node.step(clock.now())


def test_disabled_attaches_nothing(wire):
    session, _, clock = wire
    links = SlaveLinks(*(Topic(clock) for _ in range(4)))
    before = [getattr(links, f.name) for f in dataclasses.fields(links)]
    assert attach_slave(session, Config(), links) is None and attach_master(session, Config(), links) is None
    assert [getattr(links, f.name) for f in dataclasses.fields(links)] == before and links.crtk is None


def test_a_ros2_peer_sees_the_tokens_and_decodes_the_slaves_topics(wire):
    session, peer, clock = wire
    for topic, typ in (("/tsm0/distal/measured_js", JOINT_STATE), ("/tsm0/measured_cf", WRENCH_STAMPED),
                       ("/tsm0/operating_state", OPERATING_STATE)):
        peer.subscribe(topic, typ)
    cfg, links, crtk, node = slave_setup(session, clock)
    expected = ("/NN/%/%/teleop_tsm0_slave",
                "/MP/%/%/teleop_tsm0_slave/%tsm0%measured_cf/geometry_msgs::msg::dds_::WrenchStamped_/RIHS01_",
                "/MS/%/%/teleop_tsm0_slave/%tsm0%servo_jp/sensor_msgs::msg::dds_::JointState_/")

    def missing() -> list[str]:     # a token declared a moment ago may not have reached the peer yet
        tokens = peer.tokens()
        return [e for e in expected if not any(e in t for t in tokens)]
    wait_for(lambda: not missing(), 5, "the slave's node, publisher and subscriber tokens")
    assert any(t.endswith("/NN/%/%/teleop_tsm0_slave") for t in peer.tokens())
    tick(node, clock, 5)
    wait_for(lambda: peer.messages("/tsm0/measured_cf") and peer.messages("/tsm0/distal/measured_js"), 5,
             "the estimate on ROS 2")
    est = links.estimate.sent
    att, js = peer.messages("/tsm0/distal/measured_js")[-1]
    match = [e for e in est if [e.axes[0].position_hat] == list(js.position)
             and [e.axes[0].effort_hat] == list(js.effort)]
    assert match and js.header.stamp.sec > 1_600_000_000
    _, cf = peer.messages("/tsm0/measured_cf")[-1]
    assert any(e.axes[0].effort_hat == cf.wrench.force.z for e in est)
    assert len(att) == 33 and att[16] == 16 and int.from_bytes(att[:8], "little") >= 1
    wait_for(lambda: peer.messages("/tsm0/operating_state"), 5, "the slave's operating_state")
    _, state = peer.messages("/tsm0/operating_state")[-1]
    assert state.state == "PAUSED" and node.state == SideState.SAFE


def test_servo_jp_from_a_ros2_node_moves_the_simulated_instrument(wire):
    session, peer, clock = wire
    cfg, links, crtk, node = slave_setup(session, clock)
    assert isinstance(links.command, CommandMerge)
    tick(node, clock, 5)
    assert node.state == SideState.SAFE                   # no master and no ROS 2 driver yet
    servo = peer.publisher("/tsm0/servo_jp", JOINT_STATE)
    wait_for(crtk.driver_alive, 5, "the driver's liveliness token")
    x0 = node.rig_state.x_in
    targets = [x0 + 0.0005 * k for k in range(1, 11)]     # 5 mm in 0.5 mm steps, each within the engage tolerance
    for k, x in enumerate(targets):
        servo(joint_state(1_700_000_000 + k, ["tendon"], [x]))
        wait_for(lambda x=x: crtk.servo is not None and crtk.servo.message.targets == (x,), 5, f"servo_jp {k}")
        tick(node, clock, 30)
        assert node.state == SideState.ENGAGED
    assert node.rig_state.x_in == pytest.approx(targets[-1], abs=2e-4)
    assert node.commands_applied > 250 and node.counts["commands_rejected_range"] == 0
    # pause: servo_jp refused, the stream goes stale and the watchdog makes the slave SAFE
    peer.publisher("/tsm0/state_command", STRING_STAMPED, eid=11)(string_stamped("pause"))
    wait_for(lambda: not crtk.servo_admitted, 5, "state_command pause")
    refused = crtk.servo_refused
    servo(joint_state(1_700_000_100, ["tendon"], [targets[-1] + 0.001]))
    wait_for(lambda: crtk.servo_refused > refused, 5, "the refused servo_jp")
    tick(node, clock, 80)
    assert node.state == SideState.SAFE


def test_without_accept_commands_a_ros2_node_cannot_move_or_pause_the_instrument(wire):
    session, peer, clock = wire
    cfg, links, crtk, node = slave_setup(session, clock, accept_commands=False)
    assert not isinstance(links.command, CommandMerge) and not crtk.driver_alive()
    servo = peer.publisher("/tsm0/servo_jp", JOINT_STATE)
    peer.publisher("/tsm0/state_command", STRING_STAMPED, eid=11)(string_stamped("pause"))
    for k in range(20):
        servo(joint_state(1_700_000_000 + k, ["tendon"], [node.rig_state.x_in + 1e-4 * k]))
        time.sleep(0.01)
        tick(node, clock, 5)
    assert crtk.servo is None and crtk.servo_admitted and node.state == SideState.SAFE
    assert node.commands_applied == 0 and not any("servo_jp" in t for t in peer.tokens() if "/MS/" in t)


def test_the_masters_measured_js_and_state(wire):
    session, peer, clock = wire
    peer.subscribe("/tsm0_master/measured_js", JOINT_STATE)
    peer.subscribe("/tsm0_master/operating_state", OPERATING_STATE)
    cfg = Config(ros2=Ros2Config(enabled=True, rate_hz=200.0))
    links = MasterLinks(*(Topic(clock) for _ in range(4)))
    crtk = attach_master(session, cfg, links)
    links.crtk.offer(SideState.READY, [0.0125], (0.75,))
    wait_for(lambda: peer.messages("/tsm0_master/measured_js"), 5, "the master's measured_js")
    _, js = peer.messages("/tsm0_master/measured_js")[-1]
    assert list(js.position) == [0.0125] and list(js.effort) == [0.75] and js.header.stamp.sec > 0
    crtk.offer(SideState.ENGAGED, [float("nan")], (0.0,))
    wait_for(lambda: peer.messages("/tsm0_master/measured_js")[-1][1].header.stamp.sec == 0, 5,
             "an invalid measured_js")
    assert list(peer.messages("/tsm0_master/measured_js")[-1][1].position) == []
    # the last operating_state, once one has arrived (on a loaded machine none may have yet)
    wait_for(lambda: any(m.is_busy for _, m in peer.messages("/tsm0_master/operating_state")[-1:]), 5,
             "ENGAGED as busy")


def test_servo_jp_commands_follow_the_masters_numbering_and_the_newest_wins(wire):
    session, _, clock = wire
    cfg, links, crtk, node = slave_setup(session, clock)
    master = links.command.primary
    master.put(Command(41, 0.0, (0.0,), True, 0))
    assert links.command.latest() is master.latest()
    clock.advance(DT)
    crtk._on_servo(ros2_types.joint_state(1, ["tendon"], [0.001]), None)
    assert crtk.servo.message.seq == 42 and crtk.servo.message.targets == (0.001,) and crtk.servo.message.engaged
    assert links.command.latest() is crtk.servo                       # the newer of the two
    clock.advance(DT)
    master.put(Command(43, 0.0, (0.0,), True, 0))
    assert links.command.latest() is master.latest()
    with pytest.raises(CodecError):
        crtk._on_servo(ros2_types.joint_state(1, ["wrist"], [0.001]), None)
    assert crtk.servo_refused == 1 and crtk.servo.message.seq == 42


def test_a_tension_trip_is_a_fault_and_a_stale_link_a_pause():
    from teleop.ros2.crtk import slave_messages
    cfg = Config(ros2=Ros2Config(enabled=True))

    def state(**kw):
        topic, cdr = next(iter(slave_messages(cfg, 1, SideState.SAFE, None, None, **kw)))
        msg = ros2_types.decode(cdr, OPERATING_STATE)
        return topic, msg.state, msg.is_homed, msg.is_busy
    assert state() == ("/tsm0/operating_state", "PAUSED", True, False)
    assert state(fault=True) == ("/tsm0/operating_state", "FAULT", True, False)
