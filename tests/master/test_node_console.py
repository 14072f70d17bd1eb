"""MasterNode.step at the console and on what it receives: the clutch holds the instrument and re-anchors on
release, a re-engage after a fault needs alignment or a clutch, the operator letting go is safe with zero force, the
passivity controller in the force path, estimates out of order, duplicate, impossible or forged ignored, a late echo,
one recorded row per cycle, and the master's series in the live view. FakeClock and in-memory links."""
from __future__ import annotations

import math

import numpy as np
import pytest

from teleop.wire.messages import SideState
from tests.master.test_node import DT, engage, make, put_est, run, slave_beat, tick


def test_clutch_holds_the_instrument_and_re_anchors_on_release():
    node, hand, links, clock = make(motion_scale=0.5)
    hand.position = 0.10
    engage(node, links, clock)
    hand.position = 0.11
    run(node, links, clock, 5)
    assert links.command.sent[-1].targets[0] == pytest.approx(0.004 + 0.005)
    hand.buttons = 0b10                                  # clutch (bit 1) held: hand moves freely
    for p in np.linspace(0.11, 0.05, 30):
        hand.position = p
        run(node, links, clock, 1)
        assert not links.command.sent[-1].engaged and hand.forces[-1] == 0.0
    assert node.state == SideState.READY and node.last_reason == "clutch held"
    hand.buttons = 0                                     # release: re-anchored at the slave's x_in
    run(node, links, clock, 1, x_in=0.009)
    assert node.state == SideState.ENGAGED and node.consoles[0].clutches == 1 and node.engage_count == 2
    assert links.command.sent[-1].targets[0] == pytest.approx(0.009)       # no jump
    hand.position = 0.07
    run(node, links, clock, 1, x_in=0.009)
    assert links.command.sent[-1].targets[0] == pytest.approx(0.009 + 0.5 * 0.02)


def test_re_engage_after_a_fault_needs_alignment_or_a_clutch():
    node, hand, links, clock = make(motion_scale=0.5, align_tolerance=0.001)
    hand.position = 0.10
    engage(node, links, clock)
    tick(node, clock, 70)                                # links stale: SAFE
    assert node.state == SideState.SAFE
    hand.position = 0.104                                # the hand drifted: maps 2 mm away
    run(node, links, clock, 3)
    assert node.state == SideState.READY and node.consoles[0].status.name == "ALIGN"
    assert node.consoles[0].misalignment == pytest.approx(0.002) and "2.00 mm" in node.last_reason
    assert all(not c.engaged for c in links.command.sent[-3:]) and node.consoles[0].refusals == 1
    hand.position = 0.1015                               # back within 1 mm (0.75 mm): engages, no re-anchor
    run(node, links, clock, 1)
    assert node.state == SideState.ENGAGED and node.consoles[0].clutches == 0
    assert links.command.sent[-1].targets[0] == pytest.approx(0.004 + 0.5 * 0.0015)
    tick(node, clock, 70)
    hand.position = 0.2                                  # far away: clutch press + release realigns
    run(node, links, clock, 2)
    assert node.consoles[0].status.name == "ALIGN"
    hand.buttons = 0b10
    run(node, links, clock, 2)
    hand.buttons = 0
    run(node, links, clock, 1)
    assert node.state == SideState.ENGAGED and links.command.sent[-1].targets[0] == pytest.approx(0.004)


def test_operator_letting_go_is_safe_with_zero_force():
    node, hand, links, clock = make()
    engage(node, links, clock)
    run(node, links, clock, 10)
    assert hand.forces[-1] == pytest.approx(-2.0)
    hand.present = False
    run(node, links, clock, 1)
    assert node.state == SideState.SAFE and hand.forces[-1] == 0.0 and node.last_reason == "operator not present"


def test_passivity_controller_cuts_energy_generating_force_and_the_clamp_holds():
    node, hand, links, clock = make(force_limit=1.5, passivity=True)
    engage(node, links, clock)
    for k in range(300):                                 # the force pushes along the motion: active
        hand.position = 0.01 * math.sin(2 * math.pi * 5 * k * DT)
        v = math.cos(2 * math.pi * 5 * k * DT)
        run(node, links, clock, 1, T_out=-40.0 * v)      # force = -0.2 T_out = 8 v N: generates energy
    assert max(abs(f) for f in hand.forces) <= 1.5
    assert node.passivity[0].energy >= -1e-12 and node.passivity[0].stats.active_steps > 50
    off, hand2, links2, clock2 = make(force_limit=1.5, passivity=False)
    engage(off, links2, clock2)
    for k in range(300):
        hand2.position = 0.01 * math.sin(2 * math.pi * 5 * k * DT)
        run(off, links2, clock2, 1, T_out=-40.0 * math.cos(2 * math.pi * 5 * k * DT))
    assert off.passivity[0].energy < -1e-3 and max(abs(f) for f in hand2.forces) == pytest.approx(1.5)


def test_estimates_out_of_order_duplicate_or_impossible_are_ignored():
    node, hand, links, clock = make()
    engage(node, links, clock)
    run(node, links, clock, 5)
    n = node._last_est_seq
    put_est(links, n - 3)
    tick(node, clock)
    put_est(links, n - 3)                                # the same old one again: still older than accepted
    tick(node, clock)
    put_est(links, n + 1, T_out=1e4)                     # impossible: master.max_tension 200 N
    tick(node, clock)
    assert node.counts == {"estimates_rejected_range": 1, "estimates_out_of_order": 2, "estimates_duplicate": 0,
                           "estimates_wrong_instrument": 0}
    assert node.stats()["refusals"] == {"decode_error": 0, "wrong_instrument": 0, "out_of_range": 1,
                                        "out_of_order": 2, "duplicate": 0}
    assert hand.forces[-1] == pytest.approx(-2.0) and node._last_est_seq == n
    for _ in range(60):                                  # only impossible estimates: stale, SAFE
        slave_beat(links, clock)
        put_est(links, n + 1, T_out=float("1e5"))
        tick(node, clock)
    assert node.state == SideState.SAFE and hand.forces[-1] == 0.0
    assert node.tension_latched and node.last_reason.startswith("tension latch")   # a tension's SAFE latches


def test_a_forged_sequence_far_ahead_resynchronises_within_three_estimates():
    node, hand, links, clock = make()
    engage(node, links, clock)
    run(node, links, clock, 5)
    n = node._last_est_seq
    slave_beat(links, clock)
    put_est(links, n + 4_000_000)                        # one estimate with a seq far ahead of the stream
    tick(node, clock)
    for k in range(1, 30):                               # the real stream goes on
        slave_beat(links, clock)
        put_est(links, n + k)
        tick(node, clock)
    assert node.counts["estimates_out_of_order"] == 2 and node.counts["estimates_resync"] == 1
    assert node._last_est_seq == n + 29 and node.state == SideState.ENGAGED


def test_a_late_echo_trips_the_round_trip_watchdog():
    node, hand, links, clock = make(watchdog_ms=50.0)
    engage(node, links, clock)
    for k in range(95):                                  # echoes of commands sent 90 ms ago: within 2 x 50 ms
        slave_beat(links, clock)
        put_est(links, 10 + k, cmd_seq=max(1, links.command.sent[-1].seq - 90))
        tick(node, clock)
    assert node.state == SideState.ENGAGED
    for k in range(20):                                  # 110 ms ago: beyond the round-trip budget
        slave_beat(links, clock)
        put_est(links, 200 + k, cmd_seq=links.command.sent[-1].seq - 110)
        tick(node, clock)
    assert node.state == SideState.SAFE and node.last_reason == "command echo stale"


def test_one_csv_row_per_cycle_with_force_and_state():
    rows = []
    node, hand, links, clock = make()
    node.recorder = type("R", (), {"write": lambda self, r: rows.append(tuple(r))})()
    engage(node, links, clock)
    run(node, links, clock, 20)
    from master.axes import TENDON_CSV_COLUMNS as CSV_COLUMNS
    assert len(rows) == 22 and all(len(r) == len(CSV_COLUMNS) for r in rows)
    last = dict(zip(CSV_COLUMNS, rows[-1], strict=False))
    assert last["state"] == int(SideState.ENGAGED) and last["force"] == pytest.approx(-2.0)
    assert last["time"] == pytest.approx(clock.now()) and 0 <= last["echo_age"] < 0.01


def test_scripted_operator_clutches_when_asked_to_align_and_control_resumes():
    from master.protocols import build_protocol
    from master.simulated import ScriptedOperator
    node, _, links, clock = make(motion_scale=0.5, align_tolerance=0.001)
    op = ScriptedOperator(build_protocol("short"), start_delay=0.0)
    node.device = op
    engage(node, links, clock)
    run(node, links, clock, 100, T_in=0.5)                # pulling: the hand moves
    tick(node, clock, 70)                                 # link lost: SAFE, force gone
    run(node, links, clock, 1, x_in=0.0)                  # the slave relaxed to 0: 2.5+ mm away
    assert node.consoles[0].status.name == "ALIGN" and node.state == SideState.READY
    run(node, links, clock, 80, x_in=0.0, T_in=0.5)
    assert op.clutches == 1 and node.consoles[0].clutches == 1
    assert node.state == SideState.ENGAGED and node.engage_count == 2


def test_master_side_series_go_to_the_live_view():
    class View:
        def __init__(self):
            self.calls = []

        def log_master(self, t, **kw):
            self.calls.append((t, kw))

    node, hand, links, clock = make()
    node.rerun = view = View()
    engage(node, links, clock)
    run(node, links, clock, 50)
    assert view.calls and all(set(kw) == {"x_in_cmd", "force", "force_cmd", "rtt", "console", "experiment"}
                              for _, kw in view.calls)
    assert view.calls[-1][1]["console"] == "ENGAGED" and view.calls[-1][1]["force"] == node.force[0]
