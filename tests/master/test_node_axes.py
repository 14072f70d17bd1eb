"""The one MasterNode on a three-joint instrument: every axis gets the console (deadman, clutch,
alignment), the force map and the recorder; FakeClock and in-memory links."""
from __future__ import annotations

from pathlib import Path

import pytest

from estimator.phase import Phase
from master.node import MasterNode, csv_columns
from master.node_base import MasterLinks
from teleop.config.load import load_config
from teleop.timing.clock import FakeClock
from teleop.wire.messages import AxisState, Command, Estimate, Heartbeat, Side, SideState, TendonState
from tests.fakes import Rows, Topic

CONFIG = Path(__file__).resolve().parents[2] / "configs" / "instrument-3dof.yaml"
DT = 1e-3
ANGLES = (0.1, -0.05, 0.2)          # the slave's joint angles [rad]
TORQUES = (0.02, -0.01, 0.004)      # the slave's torques [N m]


class Hands:
    """A three-axis device that stays where it is told and records the forces."""

    def __init__(self):
        self.positions, self.buttons, self.present, self.forces = [0.0, 0.0, 0.0], 0, True, []

    def read(self, t):
        from master.device import MultiAxisState
        return MultiAxisState(t, tuple(self.positions), self.buttons, self.present)

    def set_forces(self, forces, t):
        self.forces.append(list(forces))


def make():
    cfg = load_config(CONFIG, {"master.mapping.ramp_time": 0.0, "master.mapping.force_rate_limit": 1e6,
                               "safety.override": ["master.mapping.force_rate_limit"]})
    clock = FakeClock(10.0)
    links = MasterLinks(*(Topic(clock) for _ in range(4)))
    hands, rec = Hands(), Rows()
    return cfg, MasterNode(cfg, hands, links, recorder=rec), hands, links, clock, rec


def estimate(seq, cmd_seq, angles=ANGLES):
    t = TendonState(10.0, 0.004, 9.0, 1e-4, Phase.PULL)
    return Estimate(seq, cmd_seq, 0.0, tuple(AxisState(tq, a, (t, t)) for tq, a in zip(TORQUES, angles, strict=False)))


def run(node, links, clock, n, seq=None):
    if seq is None:
        seq = [0]
    for _ in range(n):
        links.slave_heartbeat.put(Heartbeat(Side.SLAVE, 0, clock.now(), SideState.READY))
        seq[0] += 1
        links.estimate.put(estimate(seq[0], links.command.sent[-1].seq if links.command.sent else 0))
        clock.advance(DT)
        node.step(clock.now())


def test_every_axis_is_anchored_commanded_and_rendered_through_its_pulley():
    cfg, node, hands, links, clock, rec = make()
    hands.positions = [0.05, -0.02, 0.01]
    run(node, links, clock, 3)
    assert node.state == SideState.ENGAGED and node.engage_count == 1
    cmd = links.command.sent[-1]
    assert isinstance(cmd, Command) and cmd.engaged and cmd.targets == pytest.approx(ANGLES)
    r = [j.pulley_radius for j in cfg.instrument.joints]
    m = cfg.master.mapping
    # rendered with the hands still: -force_scale torque / r, within the clamp
    expected = [max(-m.force_limit, min(m.force_limit, -m.force_scale * tq / rk))
                for tq, rk in zip(TORQUES, r, strict=False)]
    assert hands.forces[-1] == pytest.approx(expected, abs=1e-9) and max(map(abs, expected)) > 0.3
    hands.positions[1] += 0.01                          # 10 mm on axis 1 (bend_lr, r = 3.5 mm)
    run(node, links, clock, 1)
    assert links.command.sent[-1].targets[1] == pytest.approx(ANGLES[1] + m.motion_scale * 0.01 / r[1])
    cols = csv_columns(cfg)
    assert len(rec.rows[-1]) == len(cols) and "grasp.force" in cols
    row = dict(zip(cols, rec.rows[-1], strict=False))
    assert row["bend_lr.cmd"] == pytest.approx(links.command.sent[-1].targets[1])
    assert row["grasp.slave"] == pytest.approx(ANGLES[2]) and row["state"] == SideState.ENGAGED


def test_deadman_alignment_per_axis_and_clutch():
    cfg, node, hands, links, clock, rec = make()
    run(node, links, clock, 3)
    assert node.state == SideState.ENGAGED
    hands.present = False                               # deadman released: SAFE, forces 0 at once
    run(node, links, clock, 1)
    assert node.state == SideState.SAFE and hands.forces[-1] == [0.0, 0.0, 0.0]
    assert not links.command.sent[-1].engaged
    hands.positions[2] += 0.01                          # the grasp axis drifted while released
    hands.present = True
    run(node, links, clock, 3)
    s = node.stats()
    assert node.state == SideState.READY and s["console"] == "ALIGN" and s["align_refusals"] == 1
    assert node.last_reason.startswith("grasp: align") and hands.forces[-1] == [0.0, 0.0, 0.0]
    hands.buttons = 1 << cfg.master.mapping.clutch_button       # clutch: hand free, re-anchor on release
    run(node, links, clock, 2)
    assert node.stats()["console"] == "CLUTCH"
    hands.buttons = 0
    run(node, links, clock, 1)
    assert node.state == SideState.ENGAGED and node.engage_count == 2 and node.stats()["clutches"] == 1
    assert links.command.sent[-1].targets == pytest.approx(ANGLES)   # re-anchored: no joint jumps


def test_an_estimate_of_another_instrument_is_counted_and_ignored():
    cfg, node, hands, links, clock, rec = make()
    links.estimate.put(Estimate(1, 0, 0.0, estimate(1, 0).axes[:2]))
    clock.advance(DT)
    node.step(clock.now())
    assert node.counts["estimates_wrong_instrument"] == 1 and node.state != SideState.ENGAGED


def test_every_axis_goes_to_the_live_view():
    class View:
        def __init__(self):
            self.calls = []

        def log_master(self, t, **kw):
            self.calls.append((t, kw))

    cfg, node, hands, links, clock, rec = make()
    node.rerun = view = View()
    hands.positions = [0.05, -0.02, 0.01]
    run(node, links, clock, 2 * cfg.recording.log_every)
    last = [kw for t, kw in view.calls if t == view.calls[-1][0]]
    assert [kw["axis"] for kw in last] == ["bend_ud", "bend_lr", "grasp"]
    assert [kw["force"] for kw in last] == node.force and [kw["x_in_cmd"] for kw in last] == pytest.approx(
        links.command.sent[-1].targets)
    assert last[0]["rtt"] is not None and last[1]["rtt"] is None and last[2]["console"] == "ENGAGED"
