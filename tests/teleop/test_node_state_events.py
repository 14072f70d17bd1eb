"""Every state change is published at once as a heartbeat (an event), however short the state; the log
gives the time since the loop started beside the clock's reading."""
from __future__ import annotations

import logging
from types import SimpleNamespace

from teleop.node import NodeBase
from teleop.wire.messages import Side, SideState


class _Sent:
    def __init__(self):
        self.sent = []

    def put(self, msg):
        self.sent.append(msg)


class _Node(NodeBase):
    side = Side.SLAVE
    log = logging.getLogger("tests.node")

    def __init__(self):
        super().__init__(heartbeat_hz=50.0)
        self.links = SimpleNamespace(heartbeat=_Sent())
        self._set_state(SideState.READY, None, "constructed")      # before the loop: no clock, no message

    def step(self, now: float) -> None:
        self._heartbeat(now)


def test_a_state_held_for_less_than_a_heartbeat_period_is_published():
    node = _Node()
    node.step(100.0)                                                   # the first periodic heartbeat
    node._set_state(SideState.SAFE, 100.004, "a short fault")          # 16 ms of SAFE between two periods
    node._set_state(SideState.READY, 100.005, "recovered at once")     # even two changes in one cycle
    node.step(100.005)
    node.step(100.020)
    states = [(hb.t_sender, hb.state) for hb in node.links.heartbeat.sent]
    assert states == [(100.0, SideState.READY), (100.004, SideState.SAFE), (100.005, SideState.READY),
                      (100.020, SideState.READY)]
    seqs = [hb.seq for hb in node.links.heartbeat.sent]
    assert seqs == list(range(seqs[0], seqs[0] + 4))                  # one sequence: nothing looks lost


def test_a_change_and_a_due_heartbeat_in_the_same_cycle_send_one_message():
    node = _Node()
    node.step(100.0)
    node._set_state(SideState.SAFE, 100.02, "fault")
    node.step(100.02)
    assert [hb.t_sender for hb in node.links.heartbeat.sent] == [100.0, 100.02]


def test_the_log_gives_loop_time_and_clock(caplog):
    node = _Node()
    node._t_origin = 1800.0                                            # the loop started at clock 1800 s
    with caplog.at_level(logging.INFO, logger="tests.node"):
        node._set_state(SideState.SAFE, 1812.5, "fault")
    assert "slave READY -> SAFE at t=12.500 s (clock 1812.500 s): fault" in caplog.text
