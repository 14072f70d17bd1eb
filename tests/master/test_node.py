"""MasterNode.step with a FakeClock and an in-memory transport: engage, watchdog, force, latency echo; the helpers
the other master tests drive the node with."""
from __future__ import annotations

import numpy as np
import pytest

from estimator.phase import Phase
from master.device import DeviceState
from master.node import MasterNode
from master.node_base import MasterLinks
from teleop.config.schema import Config, MappingConfig, MasterConfig
from teleop.timing.clock import FakeClock
from teleop.wire.messages import Heartbeat, Side, SideState, tendon_estimate
from tests.fakes import Topic

DT = 1e-3


class Hand:
    """A device that stays where it is told and records the forces."""

    def __init__(self):
        self.position, self.forces, self.finished, self.marker, self.present = 0.0, [], False, 7, True
        self.buttons = 0

    def read(self, t):
        return DeviceState(t, self.position, self.buttons, operator_present=self.present)

    def set_force(self, force, t):
        self.forces.append(force)

    def close(self):
        pass


def make(watchdog_ms=50.0, **mapping):
    m = dict(motion_scale=0.5, force_scale=0.2, force_limit=4.0, ramp_time=0.0, force_rate_limit=1e6)
    m.update(mapping)
    cfg = Config(master=MasterConfig(watchdog_ms=watchdog_ms, mapping=MappingConfig(**m)))
    clock = FakeClock(100.0)
    links = MasterLinks(*(Topic(clock) for _ in range(4)))
    hand = Hand()
    return MasterNode(cfg, hand, links, stop_linger=0.01), hand, links, clock


def estimate(seq, cmd_seq=0, T_out=10.0, x_in=0.004, T_in=15.0):
    return tendon_estimate(seq, cmd_seq, 0.0, T_in, x_in, T_out, 1e-4, x_in - 1e-4, Phase.PULL, ())


def put_est(links, seq, cmd_seq=None, **kw):
    """An estimate echoing the last command sent (as a live slave does), unless cmd_seq is given."""
    if cmd_seq is None:
        cmd_seq = links.command.sent[-1].seq if links.command.sent else 0
    links.estimate.put(estimate(seq, cmd_seq, **kw))


def slave_beat(links, clock, state=SideState.READY):
    links.slave_heartbeat.put(Heartbeat(Side.SLAVE, 0, clock.now(), state))


def tick(node, clock, n=1):
    for _ in range(n):
        clock.advance(DT)
        node.step(clock.now())


def engage(node, links, clock):
    tick(node, clock)                     # a first command for the slave to echo
    slave_beat(links, clock)
    put_est(links, 1)
    tick(node, clock)
    assert node.state == SideState.ENGAGED


def run(node, links, clock, n, **est):
    for _ in range(n):
        slave_beat(links, clock)
        put_est(links, node._last_est_seq + 1 if node._last_est_seq is not None else 1, **est)
        tick(node, clock)


def test_commands_flow_but_not_engaged_until_the_slave_is_ready():
    node, hand, links, clock = make()
    tick(node, clock, 5)
    slave_beat(links, clock, SideState.CALIBRATING)
    put_est(links, 1)
    tick(node, clock, 5)
    cmds = links.command.sent
    assert len(cmds) == 10 and [c.seq for c in cmds] == list(range(10))
    assert not any(c.engaged for c in cmds) and node.state == SideState.READY
    assert set(hand.forces) == {0.0}
    assert node.last_reason == "slave CALIBRATING"


def test_engage_anchors_at_the_slave_position_and_marks_commands():
    node, hand, links, clock = make()
    hand.position = 0.3
    engage(node, links, clock)
    first = links.command.sent[-1]
    assert first.engaged and first.targets[0] == pytest.approx(0.004) and first.marker == 7
    hand.position = 0.32
    tick(node, clock)
    assert links.command.sent[-1].targets[0] == pytest.approx(0.004 + 0.5 * 0.02)


def test_force_is_minus_scale_times_the_estimate():
    node, hand, links, clock = make()
    engage(node, links, clock)
    for k in range(5):
        put_est(links, 2 + k, T_out=10.0)
        tick(node, clock)
    assert hand.forces[-1] == pytest.approx(-2.0)


def test_stale_estimate_trips_the_watchdog_after_watchdog_ms():
    node, hand, links, clock = make(watchdog_ms=50.0)
    engage(node, links, clock)            # estimate received at t0 = clock.now()
    for k in range(48):                   # estimate up to 49 ms old: still engaged
        if k % 10 == 0:
            slave_beat(links, clock)      # the heartbeat stays fresh: only the estimate is stale
        tick(node, clock)
        assert node.state == SideState.ENGAGED
    assert hand.forces[-1] == pytest.approx(-2.0)
    slave_beat(links, clock)
    tick(node, clock, 2)                  # 51 ms old
    assert node.state == SideState.SAFE and node.last_reason == "estimate stale"
    assert hand.forces[-1] == 0.0 and node.safe_events == 1
    assert not links.command.sent[-1].engaged


def test_missing_slave_heartbeat_goes_safe_even_with_fresh_estimates():
    node, hand, links, clock = make(watchdog_ms=50.0)
    engage(node, links, clock)
    for k in range(200):
        put_est(links, 10 + k)
        tick(node, clock)
        if node.state == SideState.SAFE:
            break
    assert node.state == SideState.SAFE and node.last_reason == "slave heartbeat missing"
    # timeout = max(watchdog, 3 heartbeat periods at 50 Hz) = 60 ms
    assert clock.now() - links.slave_heartbeat.last.t_recv == pytest.approx(0.061, abs=1.5e-3)
    assert hand.forces[-1] == 0.0


def test_slave_going_safe_or_liveliness_lost_disengages():
    node, hand, links, clock = make()
    engage(node, links, clock)
    slave_beat(links, clock, SideState.SAFE)
    put_est(links, 2)
    tick(node, clock)
    assert node.state == SideState.SAFE and node.last_reason == "slave SAFE"
    alive = [True]
    node.links.slave_alive = lambda: alive[0]
    slave_beat(links, clock)
    put_est(links, 3)
    tick(node, clock)
    assert node.state == SideState.ENGAGED and node.engage_count == 2   # recovers, re-anchored
    alive[0] = False
    tick(node, clock)
    assert node.state == SideState.SAFE and node.last_reason == "slave liveliness token gone"


def test_recovery_restarts_the_ramp():
    node, hand, links, clock = make(ramp_time=0.1)
    engage(node, links, clock)
    for k in range(150):
        put_est(links, 2 + k)
        slave_beat(links, clock)
        tick(node, clock)
    assert hand.forces[-1] == pytest.approx(-2.0)
    tick(node, clock, 70)                  # everything stale -> SAFE
    assert hand.forces[-1] == 0.0
    slave_beat(links, clock)
    put_est(links, 500)
    tick(node, clock)
    assert node.state == SideState.ENGAGED and hand.forces[-1] == 0.0
    for k in range(50):
        put_est(links, 501 + k)
        slave_beat(links, clock)
        tick(node, clock)
    assert hand.forces[-1] == pytest.approx(-1.0, rel=0.05)      # half-way up the 0.1 s ramp


def test_round_trip_latency_from_the_echo():
    node, hand, links, clock = make()
    engage(node, links, clock)
    delay = 3                               # the fake slave echoes the command sent 3 cycles ago
    for k in range(100):
        slave_beat(links, clock)
        seq = links.command.sent[-1].seq
        put_est(links, 10 + k, cmd_seq=max(0, seq - delay))
        tick(node, clock)
    lat = node.latency_stats()
    assert lat["n"] >= 95
    assert lat["p50_ms"] == pytest.approx(delay, abs=1e-6) and lat["p99_ms"] == pytest.approx(delay, abs=1e-6)


def test_repeated_echo_is_counted_once():
    node, hand, links, clock = make()
    slave_beat(links, clock)
    put_est(links, 1, cmd_seq=99)               # echo of a command never sent: ignored
    tick(node, clock, 2)
    for k in range(10):
        slave_beat(links, clock)
        put_est(links, 10 + k, cmd_seq=0)    # the slave keeps echoing command 0
        tick(node, clock)
    assert node.latency_stats()["n"] == 1


def test_heartbeat_rate_and_stopping_when_the_device_finishes():
    node, hand, links, clock = make()
    tick(node, clock, 1000)
    beats = links.heartbeat.sent
    assert len(beats) == 50 and all(b.side == Side.MASTER for b in beats)
    assert np.allclose(np.diff([b.t_sender for b in beats]), 0.02)
    hand.finished = True
    tick(node, clock)
    assert node.state == SideState.STOPPING and not node.done
    tick(node, clock, 11)
    assert node.done and links.heartbeat.sent[-1].state == SideState.STOPPING
    n = len(links.command.sent)
    tick(node, clock, 5)
    assert len(links.command.sent) == n     # done: nothing more is sent


def test_operator_absent_does_not_engage():
    node, hand, links, clock = make()
    hand.present = False
    tick(node, clock)
    slave_beat(links, clock)
    put_est(links, 1)
    tick(node, clock, 3)
    assert node.state != SideState.ENGAGED and node.last_reason == "operator not present"


def test_stats_are_json_ready(tmp_path):
    node, hand, links, clock = make()
    engage(node, links, clock)
    node.write_stats(tmp_path / "m.json")
    import json
    s = json.loads((tmp_path / "m.json").read_text())
    assert s["commands_sent"] == 2 and s["engage_count"] == 1 and s["state"] == "ENGAGED"
