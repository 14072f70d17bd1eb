"""A sensor the slave cannot trust (a reading that is not finite, or a sample the rig flags, such as a Zenoh rig's
sample older than its timeout): the slave holds its motors, sends no estimate, goes SAFE, and stays SAFE until the
readings are good and the operator lets go. It never steps its estimators on the bad sample."""
from __future__ import annotations

import dataclasses
import math

import pytest

from estimator.sheath import SheathModel
from slave.node import SlaveNode
from slave.node_base import SlaveLinks
from slave.rig import RigState, sensor_fault
from teleop.config.schema import Config, SlaveConfig
from teleop.timing.clock import FakeClock
from teleop.wire.messages import Command, SideState
from tests.fakes import Rows, Topic

DT = 1e-3
STIFFNESS = 1000.0          # [N/m] the load cell reads a spring: T_in = STIFFNESS x_in


class FaultyRig:
    """Follows the motor command exactly; while ``bad`` is set its samples carry that fault: ``"nan"`` a load
    cell reading NaN, any other string the rig's own flag (``RigState.fault``)."""

    def __init__(self):
        self.t, self.cmds, self.bad = 0.0, [], None
        self.state = RigState(0.0, 0.0, 0.0, 0.0, None)

    def step(self, x_in_cmd, dt):
        self.t += dt
        self.cmds.append(x_in_cmd)
        T = math.nan if self.bad == "nan" else STIFFNESS * x_in_cmd
        self.state = RigState(self.t, x_in_cmd, T, x_in_cmd, None,
                              self.bad if self.bad not in (None, "nan") else None)
        return self.state

    def close(self):
        pass


def _node():
    cfg = Config(slave=SlaveConfig(max_tension=20.0, relax_speed=0.005, max_speed=1.0))
    clock = FakeClock(10.0)
    links = SlaveLinks(*(Topic(clock) for _ in range(4)))
    node = SlaveNode(cfg, FaultyRig(), links, calibrate=False, model=SheathModel(K=0.6, compliance=1e-4),
                     recorder=Rows())
    return node, links, clock


def _step(node, links, clock, seq: int, x: float, engaged: bool = True) -> None:
    links.command.put(Command(seq, 0.0, (x,), engaged, 0))
    clock.advance(DT)
    node.step(clock.now())


def test_sensor_fault_names_the_reading_or_the_rigs_flag():
    good = RigState(0.0, 0.001, 1.0, 0.001, None)
    assert sensor_fault(good) is None
    assert "T_in not finite" in sensor_fault(dataclasses.replace(good, T_in=math.nan))
    assert "x_in not finite" in sensor_fault(dataclasses.replace(good, x_in=math.inf))
    assert sensor_fault(dataclasses.replace(good, fault="rig sample 80.0 ms old")) == "rig sample 80.0 ms old"


@pytest.mark.parametrize("fault", ["nan", "rig sample 80.0 ms old (rig.zenoh.timeout_ms 50)"])
def test_a_faulty_sample_holds_the_motors_and_safe_until_the_operator_lets_go(fault):
    node, links, clock = _node()
    for seq in range(1, 40):                               # engaged, pulling 0.1 mm a cycle
        _step(node, links, clock, seq, 1e-4 * seq)
    assert node.state == SideState.ENGAGED
    sent = len(links.estimate.sent)
    node.rig.bad = fault
    seq = 40
    _step(node, links, clock, seq, 1e-4 * seq)             # this cycle's motor step returns the faulty sample
    held = node.rig.cmds[-1]
    for k in range(1, 50):                                 # the master keeps commanding deeper
        _step(node, links, clock, seq + k, 1e-4 * (seq + k))
        assert node.state == SideState.SAFE
        assert node.rig.cmds[-1] == held, "the motors hold while the readings cannot be trusted"
    assert len(links.estimate.sent) <= sent + 1, "no estimate from a faulty sample"
    assert node.counts["sensor_faults"] == 1 and node.last_safe_reason == sensor_fault(node.rig.state)
    # the readings come back; the operator is still engaged: SAFE holds (relaxing from the measured position)
    node.rig.bad = None
    seq += 50
    for k in range(30):
        _step(node, links, clock, seq + k, 1e-4 * (seq + k))
        assert node.state == SideState.SAFE
    assert node.rig.cmds[-1] <= held and all(math.isfinite(c) for c in node.rig.cmds)
    assert len(links.estimate.sent) > sent + 20, "estimates again once the readings are good"
    # the operator lets go: READY; the fault counted once
    seq += 30
    _step(node, links, clock, seq, node.rig.cmds[-1], engaged=False)
    assert node.state == SideState.READY and node.counts["sensor_faults"] == 1
