"""The master's tension latch: a SAFE caused by a tension (an estimate beyond ``master.max_tension``, or the slave
going SAFE on a measured ``|T_in|`` beyond ``slave.max_tension``) holds while the deadman stays pressed, and ends
when the operator releases the deadman (then presses it again) or clutches. Other faults re-engage as before."""
from __future__ import annotations

from master.node import MasterNode
from teleop.config.schema import Config, SlaveConfig
from teleop.wire.messages import SideState
from tests.master.test_node import engage, make, put_est, run, slave_beat, tick


def tension_safe(node, links, clock) -> None:
    """Engaged, then only estimates beyond master.max_tension (200 N): SAFE on them, latched."""
    engage(node, links, clock)
    run(node, links, clock, 5)
    n = node._last_est_seq
    for _ in range(60):
        slave_beat(links, clock)
        put_est(links, n + 1, T_out=1e4)
        tick(node, clock)
    assert node.state == SideState.SAFE and node.tension_latched and node.tension_latches == 1


def test_the_latch_holds_while_the_deadman_stays_pressed_and_ends_on_release_and_press():
    node, hand, links, clock = make()
    tension_safe(node, links, clock)
    run(node, links, clock, 300)                 # the tension is back below, links fresh, hand aligned, deadman held
    assert node.state == SideState.SAFE and node.engage_count == 1 and node.tension_latched
    assert not any(c.engaged for c in links.command.sent[-300:]) and hand.forces[-1] == 0.0
    assert "deadman" in node.last_reason
    hand.present = False                         # the operator lets go of the deadman
    run(node, links, clock, 3)
    assert node.state == SideState.SAFE and not node.tension_latched
    hand.present = True                          # and presses it again: engages (aligned) as after any fault
    run(node, links, clock, 1)
    assert node.state == SideState.ENGAGED and node.engage_count == 2 and links.command.sent[-1].engaged
    assert node.stats()["tension_latches"] == 1


def test_the_clutch_ends_the_latch_too():
    node, hand, links, clock = make()
    tension_safe(node, links, clock)
    run(node, links, clock, 20)
    assert node.state == SideState.SAFE
    hand.buttons = 0b10                          # clutch (bit 1) pressed and released: re-anchored, engaged
    run(node, links, clock, 2)
    assert not node.tension_latched
    hand.buttons = 0
    run(node, links, clock, 1)
    assert node.state == SideState.ENGAGED and node.consoles[0].clutches == 1


def test_a_slave_safe_on_its_tension_limit_latches_even_when_its_estimate_comes_a_cycle_late():
    node, hand, links, clock = make()
    assert node.slave_limit == Config().slave.max_tension
    engage(node, links, clock)
    run(node, links, clock, 5)
    slave_beat(links, clock, SideState.SAFE)     # the slave's heartbeat first, its estimate of the trip after it
    tick(node, clock)
    assert node.state == SideState.SAFE and not node.tension_latched
    put_est(links, node._last_est_seq + 1, T_in=node.slave_limit + 1.0)
    tick(node, clock)
    assert node.tension_latched
    for _ in range(100):                         # the slave relaxes and is READY again; the hand stays pressed
        slave_beat(links, clock)
        put_est(links, node._last_est_seq + 1, T_in=0.5 * node.slave_limit)
        tick(node, clock)
    assert node.state == SideState.SAFE and node.engage_count == 1


def test_other_faults_re_engage_without_letting_go():
    node, hand, links, clock = make()
    engage(node, links, clock)
    run(node, links, clock, 5)
    slave_beat(links, clock, SideState.SAFE)     # a slave SAFE (its watchdog) below every tension limit
    put_est(links, node._last_est_seq + 1)
    tick(node, clock)
    assert node.state == SideState.SAFE
    run(node, links, clock, 3)                   # READY again: the master engages (aligned), no latch
    assert node.state == SideState.ENGAGED and node.engage_count == 2 and node.tension_latches == 0
    tick(node, clock, 70)                        # links stale: SAFE, and back
    run(node, links, clock, 3)
    assert node.state == SideState.ENGAGED and node.engage_count == 3 and not node.tension_latched


def test_the_slave_limit_is_read_from_the_config():
    cfg = Config(slave=SlaveConfig(max_tension=42.0))
    node = MasterNode(cfg, make()[1], make()[2])
    assert node.slave_limit == 42.0
