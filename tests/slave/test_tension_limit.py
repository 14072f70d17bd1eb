"""The slave's own tension limit (``slave.max_tension``): SAFE in the cycle a measured ``|T_in|`` passes it,
whatever the master commands; READY again only on a not-engaged command once every tension is back below.

A single tendon on a rig whose load cell reads a spring, and the joint (pair) and spindle instruments in closed
loop with a master node on one FakeClock: the scripted operator pulls past the limit and keeps pushing."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from estimator.sheath import SheathModel
from master.node import MasterNode
from master.node_base import MasterLinks
from master.protocols import paper_protocol
from master.simulated import ScriptedOperator
from slave.node import SlaveNode
from slave.node_base import SlaveLinks
from slave.pair_calibrate import set_tension
from slave.rig import RigState
from slave.rigs import make_rig
from teleop.config.bounds import REARM_FRACTION
from teleop.config.load import load_config
from teleop.config.schema import Config, SlaveConfig
from teleop.timing.clock import FakeClock
from teleop.wire.messages import Command, SideState
from tests.fakes import Rows, Topic

ROOT = Path(__file__).resolve().parents[2]
DT = 1e-3
STIFFNESS = 1000.0          # [N/m] the spring rig's load cell: T_in = STIFFNESS x_in
LIMIT = 5.0                 # [N] slave.max_tension of the single-tendon runs (x_in = 5 mm)


class SpringRig:
    """Follows the motor command exactly; its load cell reads ``STIFFNESS * x_in`` [N]."""

    def __init__(self):
        self.t, self.cmds = 0.0, []
        self.state = RigState(0.0, 0.0, 0.0, 0.0, None)

    def step(self, x_in_cmd, dt):
        self.t += dt
        self.cmds.append(x_in_cmd)
        self.state = RigState(self.t, x_in_cmd, STIFFNESS * x_in_cmd, x_in_cmd, None)
        return self.state

    def close(self):
        pass


def tendon_node(relax_speed: float = 0.005):
    # the pulls step 0.1 mm a cycle (100 mm/s): above slave.max_speed, which tests/slave/test_node.py tests
    cfg = Config(slave=SlaveConfig(max_tension=LIMIT, relax_speed=relax_speed, max_speed=1.0))
    clock = FakeClock(10.0)
    links = SlaveLinks(*(Topic(clock) for _ in range(4)))
    rec = Rows()
    node = SlaveNode(cfg, SpringRig(), links, calibrate=False, model=SheathModel(K=0.6, compliance=1e-4),
                     recorder=rec)
    return node, links, clock, rec


def step(node, links, clock, seq: int, x: float, engaged: bool = True) -> None:
    """A fresh command (the master keeps commanding), then one slave cycle."""
    links.command.put(Command(seq, 0.0, (x,), engaged, 0))
    clock.advance(DT)
    node.step(clock.now())


def pull_past_the_limit(node, links, clock) -> int:
    """Engaged commands 0.1 mm further each cycle until the slave trips; the seq of the last command. A cycle
    samples the load cell as the previous cycle's motor command left it."""
    for seq in range(1, 200):
        x = 1e-4 * (seq - 1)
        step(node, links, clock, seq, x)
        if node.state == SideState.SAFE:
            return seq
        assert node.state == SideState.ENGAGED and STIFFNESS * (x - 1e-4) <= LIMIT
    raise AssertionError("the slave never tripped its tension limit")


def test_single_tendon_goes_safe_in_the_cycle_the_tension_passes_the_limit_and_relaxes():
    node, links, clock, rec = tendon_node()
    seq = pull_past_the_limit(node, links, clock)
    state_col = -3                                          # recording: ..., state, t_node, t_cmd_recv
    x_trip = node.rig.cmds[-2]                              # the position the trip cycle sampled
    assert STIFFNESS * x_trip > LIMIT >= STIFFNESS * node.rig.cmds[-3]    # the first sample past the limit
    assert node.rig.cmds[-1] < x_trip                                     # and that cycle's motor already releases
    assert rec.rows[-1][state_col] == int(SideState.SAFE) and rec.rows[-2][state_col] == int(SideState.ENGAGED)
    assert links.heartbeat.sent[-1].state == SideState.SAFE and links.heartbeat.sent[-1].t_sender == clock.now()
    assert node.safe_events == 1 and node.counts["tension_trips"] == 1
    assert "slave.max_tension" in node.last_safe_reason and "tendon" in node.last_safe_reason
    # the master goes on commanding deeper into the limit: the slave stays SAFE and only releases
    n = 200                                                 # 5 um a cycle at slave.relax_speed 5 mm/s
    for k in range(1, n):
        step(node, links, clock, seq + k, x_trip + 1e-4 * k)
        assert node.state == SideState.SAFE
    motor = np.array(node.rig.cmds[-n:])
    assert np.all(np.diff(motor) <= 0) and motor[-1] < x_trip
    # back below REARM_FRACTION of the limit and still SAFE: the commands are engaged
    assert STIFFNESS * motor[-1] < REARM_FRACTION * LIMIT
    assert node.counts["tension_trips"] == 1
    assert node.stats()["last_safe_reason"] == node.last_safe_reason == node.stats()["last_tension_trip"]
    # the master lets go (engaged=False): READY, holding the relaxed position; engaging follows the usual rules
    seq += n
    step(node, links, clock, seq, motor[-1], engaged=False)
    assert node.state == SideState.READY and node.rig.cmds[-1] == motor[-1]
    step(node, links, clock, seq + 1, motor[-1] + 1e-5)
    assert node.state == SideState.ENGAGED and node.rig.cmds[-1] == pytest.approx(motor[-1] + 1e-5)


def test_a_not_engaged_command_does_not_end_the_safe_while_the_tension_is_past_the_limit():
    node, links, clock, _ = tendon_node(relax_speed=0.0)          # holds: the tension stays past the limit
    seq = pull_past_the_limit(node, links, clock)
    for k in range(1, 30):
        step(node, links, clock, seq + k, 0.0, engaged=False)
        assert node.state == SideState.SAFE
    assert node.counts["tension_trips"] == 1 and node.safe_events == 1


def test_a_stale_command_and_a_tension_trip_both_hold_safe_until_the_master_lets_go():
    node, links, clock, _ = tendon_node()
    seq = pull_past_the_limit(node, links, clock)
    for _ in range(200):                                     # silence: the watchdog's SAFE, relaxing meanwhile
        clock.advance(DT)
        node.step(clock.now())
    assert node.state == SideState.SAFE and STIFFNESS * node.rig.cmds[-1] < REARM_FRACTION * LIMIT
    step(node, links, clock, seq + 1, node.rig.cmds[-1])     # engaged again, close, tension below: still SAFE
    assert node.state == SideState.SAFE
    step(node, links, clock, seq + 2, node.rig.cmds[-1], engaged=False)
    assert node.state == SideState.READY


# ---- joint and spindle instruments, in closed loop with the master ----------------------------------------------

@pytest.mark.parametrize("config,limit", [("instrument-3dof.yaml", 15.0), ("instrument-spindle.yaml", 16.0)])
def test_a_pushing_hand_trips_the_slave_once_and_the_master_latches(config, limit):
    """The paper's protocol pulls every tendon to 20 N; the slave's limit is below that. The slave goes SAFE in
    the cycle its measured tension first passes the limit (the master still commanding, engaged); the master
    goes SAFE on it and latches with the deadman held: the hand never drives the tendon past the limit again."""
    cfg = load_config(ROOT / "configs" / config, {"slave.max_tension": limit, "calibration.target_tension": 10.0,
                                                  "calibration.speed": 0.01, "rig.simulated.n_elements": 20,
                                                  "estimator.n_nodes": 20})
    clock = FakeClock(0.0)
    cmd, est, shb, mhb = (Topic(clock, codec=True, keep=False) for _ in range(4))
    slave = SlaveNode(cfg, make_rig(cfg),
                      SlaveLinks(estimate=est, heartbeat=shb, command=cmd, master_heartbeat=mhb))
    op = ScriptedOperator([paper_protocol(set_tension(cfg, j)) for j in cfg.instrument.joints])
    master = MasterNode(cfg, op, MasterLinks(command=cmd, heartbeat=mhb, estimate=est, slave_heartbeat=shb))
    cycles = []             # (slave state, master state, engaged command, largest measured |T_in| [N]) per cycle
    trip = None
    for _ in range(40_000):
        clock.advance(DT)
        commanding = cmd.last is not None and cmd.last.message.engaged     # what the slave reads this cycle
        slave.step(clock.now())
        master.step(clock.now())
        if est.last is None or est.last.message.t_slave != clock.now():     # calibrating: no estimate
            continue
        peak = max(abs(t.T_in) for a in est.last.message.axes for t in a.tendons)
        cycles.append((slave.state, master.state, commanding, peak))
        trip = len(cycles) - 1 if trip is None and slave.counts["tension_trips"] else trip
        if trip is not None and len(cycles) - trip > 300:
            break
    assert trip is not None, "the protocol never reached the slave's limit"
    peaks = np.array([c[3] for c in cycles])
    assert peaks[trip] > limit and peaks[:trip].max() <= limit       # the first cycle past the limit
    assert cycles[trip][0] == SideState.SAFE and cycles[trip - 1][0] == SideState.ENGAGED
    assert cycles[trip - 1][1] == SideState.ENGAGED and cycles[trip][2], "the master was engaged and commanding"
    assert "slave.max_tension" in slave.stats()["last_tension_trip"] and slave.safe_events == 1
    after = cycles[trip + 50:]
    assert all(c[1] == SideState.SAFE for c in after) and master.tension_latched and master.tension_latches == 1
    assert after[-1][0] == SideState.READY and peaks[trip + 50:].max() <= limit
    assert slave.counts["tension_trips"] == 1 and master.engage_count == 1


def test_a_limit_whose_rearm_level_is_not_above_the_rest_tension_is_refused():
    from teleop.config.load import config_from_dict
    from teleop.errors import ConfigError
    with pytest.raises(ConfigError, match=r"^<dict>: slave.max_tension = 10: .*sheath.pretension = 9.5 N"):
        config_from_dict({"slave": {"max_tension": 10.0}, "sheath": {"pretension": 9.5}})
    with pytest.raises(ConfigError, match=r"instrument.joints\[0\].pretension = 12 N"):
        config_from_dict({"slave": {"max_tension": 13.0}, "pair_control": {"axes": []},
                          "instrument": {"joints": [{"name": "j", "pretension": 12.0}]}})
    assert config_from_dict({"slave": {"max_tension": 10.0}, "sheath": {"pretension": 8.9}}).slave.max_tension == 10.0
