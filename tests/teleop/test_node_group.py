"""NodeGroup (teleop/node_group.py): each arm's node stepped in one paced loop, every arm's message sent before
any arm's second phase, done arms left alone, stats per arm."""
from __future__ import annotations

import logging

import pytest

from teleop.node import NodeBase
from teleop.node_group import NodeGroup
from teleop.timing.clock import FakeClock
from teleop.wire.messages import Side, SideState


class Arm(NodeBase):
    side = Side.SLAVE
    log = logging.getLogger("teleop.slave")

    def __init__(self, steps: int, name: str = "", events: list | None = None):
        super().__init__(heartbeat_hz=50.0)
        self.left, self.times, self.ended = steps, [], 0
        self.name, self.events = name, events if events is not None else []

    @property
    def rate_hz(self) -> float:
        return 1000.0

    def step_send(self, now: float) -> None:
        self.state = SideState.ENGAGED if len(self.times) == 1 else SideState.READY
        self.times.append(now)
        self.events.append(("send", self.name))
        self.left -= 1
        self.done = self.left <= 0

    def step_after(self, now: float) -> None:
        self.events.append(("after", self.name))

    def _run_ended(self, clock) -> None:
        self.ended += 1

    def stats(self):
        return {"steps": len(self.times), "pacer": self.pacer_stats}


def test_group_steps_every_arm_with_one_time_until_all_are_done():
    a, b = Arm(3), Arm(5)
    group = NodeGroup([a, b], ["left", "right"], Side.SLAVE, 1000.0)
    group.run(FakeClock(10.0), max_duration=1.0)
    assert group.done and len(a.times) == 3 and len(b.times) == 5
    assert a.times == b.times[:3]                       # the same cycle time for both arms
    assert b.times[1] - b.times[0] == pytest.approx(1e-3)
    st = group.stats()
    assert set(st["arms"]) == {"left", "right"} and st["arms"]["right"]["steps"] == 5
    assert st["arm_steps"]["left"]["cycles"] == 3 and st["arm_steps"]["right"]["cycles"] == 5
    assert st["pacer"]["ticks"] == 5
    assert st["pacer"]["cycles_by_state"] == {"STARTING": 1, "ENGAGED": 1, "READY": 3}   # state before each step
    # each arm gets the loop's figures and its end-of-run call
    assert a.ended == b.ended == 1 and a.pacer_stats["ticks"] == 5


def test_group_needs_one_name_per_node():
    with pytest.raises(ValueError, match="one name per node"):
        NodeGroup([Arm(1)], ["left", "right"], Side.MASTER, 1000.0)
    with pytest.raises(ValueError):
        NodeGroup([], [], Side.MASTER, 1000.0)


def test_every_arm_sends_before_any_arm_records():
    events: list = []
    a, b = Arm(2, "left", events), Arm(1, "right", events)
    group = NodeGroup([a, b], ["left", "right"], Side.MASTER, 1000.0)
    group.run(FakeClock(10.0), max_duration=1.0)
    assert events == [("send", "left"), ("send", "right"), ("after", "left"), ("after", "right"),
                      ("send", "left"), ("after", "left")]      # the right arm is done after its one cycle
    a.events.clear()
    a.step(0.0)                                                 # a node alone: both phases in one step
    assert events == [("send", "left"), ("after", "left")]


def test_each_arm_logs_under_its_name(caplog):
    a, b = Arm(1), Arm(1)
    NodeGroup([a, b], ["left", "right"], Side.SLAVE, 1000.0)
    with caplog.at_level(logging.INFO, logger="teleop.slave"):
        b._set_state(SideState.SAFE, None, "estimate stale")
        a._warn(1.0, "slave: %s", "a tendon at its limit")
    assert [r.getMessage() for r in caplog.records] == [
        "right slave STARTING -> SAFE at start-up: estimate stale",
        "left slave: a tendon at its limit"]
    assert Arm.log.name == "teleop.slave" and not isinstance(Arm.log, logging.LoggerAdapter)   # the class's own
