"""MasterNode.step with a FakeClock and an in-memory transport: engage, watchdog, force, latency echo."""
from __future__ import annotations

import math

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


# ---- console: clutch, alignment, passivity in the force path, estimate checks, recording ----------

def run(node, links, clock, n, **est):
    for _ in range(n):
        slave_beat(links, clock)
        put_est(links, node._last_est_seq + 1 if node._last_est_seq is not None else 1, **est)
        tick(node, clock)


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
