"""SlaveNode.step with a FakeClock and an in-memory transport: calibration, watchdog, echo, recording."""
from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from estimator.errors import CalibrationError
from estimator.sheath import SheathModel
from slave.calibrate import CalStage, JointLimitCalibration
from slave.calibration_file import load_calibration
from slave.node import SlaveNode
from slave.node_base import SlaveLinks
from slave.rig import RigState
from slave.simulated import SimulatedRig
from slave.tendon_axis import CSV_COLUMNS, csv_columns
from teleop.config.schema import CalibrationConfig, Config, SlaveConfig
from teleop.timing.clock import FakeClock
from teleop.wire.messages import Command, Estimate, Heartbeat, Side, SideState
from tests.fakes import Rows, Topic

DT = 1e-3
MODEL = SheathModel(K=0.6, compliance=1e-4)


class Untouchable:
    """Ground truth that fails the test if anyone reads it."""

    def __getattr__(self, name):
        raise AssertionError(f"the slave node read the ground truth ({name})")


class EchoRig:
    """Follows the command exactly; T_in = 1000 N/m * x_in; truth present but forbidden."""

    def __init__(self):
        self.t, self.cmds = 0.0, []
        self.state = RigState(0.0, 0.0, 0.0, 0.0, Untouchable())

    def step(self, x_in_cmd, dt):
        self.t += dt
        self.cmds.append(x_in_cmd)
        self.state = RigState(self.t, x_in_cmd, 1000.0 * x_in_cmd, x_in_cmd, Untouchable())
        return self.state

    def set_load(self, *, tissue=None, force=None):
        pass

    def close(self):
        pass


#: The echo rig's commands step up to 0.1 mm a cycle (100 mm/s) and 3 mm at once: the command limits are loosened
#: for the tests that are not about them (test_commands_beyond_the_step_or_speed_limit_...).
LOOSE = {"max_step": 0.005, "max_speed": 1.0}


def make(rig=None, calibrate=False, watchdog_ms=50.0, slave=None, **kw):
    cfg = Config(slave=SlaveConfig(watchdog_ms=watchdog_ms, **{**LOOSE, **(slave or {})}))
    clock = FakeClock(10.0)
    links = SlaveLinks(*(Topic(clock) for _ in range(4)))
    node = SlaveNode(cfg, rig or EchoRig(), links, calibrate=calibrate, model=None if calibrate else MODEL, **kw)
    return node, links, clock


def tick(node, clock, n=1):
    for _ in range(n):
        clock.advance(DT)
        node.step(clock.now())


def command(links, seq, x, engaged=True, marker=0):
    links.command.put(Command(seq, 0.0, (x,), engaged, marker))


def test_no_command_is_safe_and_holds():
    node, links, clock = make()
    tick(node, clock, 5)
    assert node.state == SideState.SAFE
    assert node.rig.cmds == [0.0] * 5
    assert links.heartbeat.sent[0].state == SideState.SAFE and links.heartbeat.sent[0].side == Side.SLAVE


def test_engaged_command_is_applied_and_echoed_without_reading_truth():
    node, links, clock = make(slave={"max_step": 0.002, "max_speed": 2.0})   # 1 mm a cycle (limits: below)
    for k in range(10):
        command(links, 100 + k, 0.001 * k, marker=2)
        tick(node, clock)
    assert node.state == SideState.ENGAGED
    assert node.rig.cmds[-1] == pytest.approx(0.009)
    est = links.estimate.sent[-1]
    # the first cycle only moves the rig; each later one samples it as the previous cycle's command left it
    assert isinstance(est, Estimate) and est.cmd_seq == 109 and est.seq == 8 and len(links.estimate.sent) == 9
    (tendon,), (profile,) = est.tendons, est.profiles          # one axis of one tendon
    assert tendon.T_in == pytest.approx(8.0) and len(profile) == node.cfg.estimator.profile_points
    assert tendon.T_out_hat == pytest.approx(8.0 * math.exp(-0.6), rel=1e-6)   # full pull slip
    assert est.axes[0].effort_hat == tendon.T_out_hat
    assert profile[0] == pytest.approx(8.0, rel=1e-6)


def test_not_engaged_is_ready_and_holds_the_last_position():
    node, links, clock = make()
    command(links, 1, 0.002)
    tick(node, clock)
    command(links, 2, 0.005, engaged=False)
    tick(node, clock, 3)
    assert node.state == SideState.READY and node.rig.cmds[-3:] == [0.002] * 3


def test_stale_command_goes_safe_after_watchdog_ms_and_holds():
    node, links, clock = make(watchdog_ms=50.0, slave={"relax_speed": 0.0})   # hold only
    command(links, 1, 0.0015)
    tick(node, clock, 49)                 # command 49 ms old: still followed
    assert node.state == SideState.ENGAGED
    tick(node, clock, 2)                  # 51 ms
    assert node.state == SideState.SAFE and node.safe_events == 1
    tick(node, clock, 100)
    assert set(node.rig.cmds) == {0.0015}
    command(links, 2, 0.0025)             # commands come back: follows again
    tick(node, clock)
    assert node.state == SideState.ENGAGED and node.rig.cmds[-1] == 0.0025


class LagRig(EchoRig):
    """A motor slower than the commands: it moves toward the command at ``speed`` [m/s] at most."""

    def __init__(self, speed):
        super().__init__()
        self.speed, self.x = speed, 0.0

    def step(self, x_in_cmd, dt):
        self.t += dt
        self.cmds.append(x_in_cmd)
        self.x += max(-self.speed * dt, min(self.speed * dt, x_in_cmd - self.x))
        self.state = RigState(self.t, self.x, 1000.0 * self.x, self.x, Untouchable())
        return self.state


def test_a_stale_command_during_a_pull_stops_the_tendon_where_it_is():
    """The motor lags a fast pull; when the commands stop, SAFE holds the measured position: the tendon goes
    no further toward the last target (hold only: relax_speed 0)."""
    node, links, clock = make(rig=LagRig(0.005), slave={"relax_speed": 0.0})
    for k in range(1, 301):               # the command pulls at 20 mm/s to 6 mm; the motor follows at 5 mm/s
        command(links, k, 2e-5 * k)
        tick(node, clock)
    assert node.state == SideState.ENGAGED
    tick(node, clock, 51)                 # stale: SAFE
    assert node.state == SideState.SAFE and node.last_safe_reason == "command stale"
    x_safe = node.rig.x
    assert x_safe < 0.5 * 6e-3            # far behind the last target when SAFE begins
    tick(node, clock, 500)
    assert node.rig.x == pytest.approx(x_safe, abs=0.005 * DT)     # held: at most one motor step further
    assert max(node.rig.cmds[-500:]) <= x_safe + 0.005 * DT


def test_safe_relaxes_at_the_relax_speed_down_to_the_pretension_and_never_pulls():
    node, links, clock = make(slave={"relax_speed": 0.01})
    for k in range(1, 21):                # walk up to 2 mm (T_in = 2 N on the echo rig)
        command(links, k, 1e-4 * k)
        tick(node, clock)
    tick(node, clock, 400)                # stale after 50 ms, then relax at 10 mm/s
    cmds = np.array(node.rig.cmds[20:])
    assert node.state == SideState.SAFE and node.last_safe_reason == "command stale"
    assert np.all(np.diff(cmds) <= 0)                                  # release only
    assert np.max(-np.diff(cmds)) == pytest.approx(0.01 * DT)          # at most relax_speed dt per cycle
    assert cmds[48] == pytest.approx(0.002)                            # held first, for the watchdog time
    # stops once T_in (1000 N/m x_in on this rig) <= pretension (0) + RELAX_BAND: x = 0.2 mm
    assert cmds[-1] == pytest.approx(0.0002, abs=0.01 * DT) and cmds[-1] == cmds[-100]


def test_duplicates_old_and_out_of_range_commands_are_ignored_and_counted():
    node, links, clock = make()
    command(links, 10, 0.001)
    tick(node, clock)
    command(links, 10, 0.001)             # duplicate
    tick(node, clock)
    command(links, 9, 0.0005)             # reordered: older than the applied one
    tick(node, clock)
    command(links, 11, 1.0)               # impossible (slave.x_in_max 0.03 m)
    tick(node, clock)
    assert node.rig.cmds == [0.001] * 4 and node.state == SideState.ENGAGED
    assert (node.counts["commands_duplicate"], node.counts["commands_out_of_order"],
            node.counts["commands_rejected_range"]) == (1, 1, 1)
    command(links, 11, 0.0011)            # seq 11 again, now in range: accepted
    tick(node, clock)
    assert node.rig.cmds[-1] == 0.0011
    for _ in range(60):                   # only rejected commands from now on: the watchdog trips
        command(links, 50, float("1e3"))
        tick(node, clock)
    assert node.state == SideState.SAFE and node.stats()["commands_rejected_range"] == 61


def test_sequence_numbers_wrap():
    from teleop.wire.codec import seq_newer
    assert seq_newer(0, 2**32 - 1) and not seq_newer(2**32 - 1, 0) and seq_newer(5, None)
    assert not seq_newer(5, 5) and seq_newer(6, 5) and not seq_newer(4, 5)


def test_engage_needs_the_command_close_to_x_in_and_liveliness_loss_is_safe_at_once():
    node, links, clock = make()
    alive = [True]
    node.links.master_alive = lambda: alive[0]
    command(links, 1, 0.005)              # 5 mm from x_in = 0: refused, stays SAFE, rig holds
    tick(node, clock, 3)
    assert node.state == SideState.SAFE and node.rig.cmds == [0.0] * 3 and node.counts["engage_refused"] == 1
    command(links, 2, 0.001)
    tick(node, clock)
    assert node.state == SideState.ENGAGED
    alive[0] = False                      # the master's token disappears: SAFE in the same cycle
    command(links, 3, 0.0012)
    tick(node, clock)
    assert node.state == SideState.SAFE and node.last_safe_reason == "master liveliness token gone"


def test_records_one_row_per_cycle_in_the_recording_columns():
    rows = Rows()
    node, links, clock = make(rig=SimulatedRig(Config().sheath, Config().rig.simulated), recorder=rows)
    for k in range(20):
        command(links, k, 1e-4 * k, marker=1)
        tick(node, clock)
    # a row per cycle after the first (which only moves the rig), each of the state its estimate came from
    assert len(rows.rows) == 19 and all(len(r) == len(CSV_COLUMNS) for r in rows.rows)
    r = dict(zip(CSV_COLUMNS, rows.rows[-1], strict=False))
    assert r["marker"] == 1 and r["cmd_seq"] == 19 and r["state"] == int(SideState.ENGAGED)
    assert r["x_in_cmd"] == pytest.approx(19e-4)                      # the motor command the cycle gave
    assert np.all(np.diff([row[0] for row in rows.rows]) > 0)
    assert csv_columns(False) == tuple(c for c in CSV_COLUMNS if c not in ("x_out", "T_out", "elongation"))


def test_stops_when_the_master_announces_stopping():
    node, links, clock = make(stop_on_master_stop=True)
    links.master_heartbeat.put(Heartbeat(Side.MASTER, 0, 0.0, SideState.ENGAGED))
    tick(node, clock, 3)
    assert not node.done
    links.master_heartbeat.put(Heartbeat(Side.MASTER, 1, 0.0, SideState.STOPPING))
    tick(node, clock)
    assert node.done and node.master_stopped
    n = len(links.estimate.sent)
    tick(node, clock, 3)
    assert len(links.estimate.sent) == n


def test_power_up_calibration_against_the_simulator(tmp_path):
    cfg = Config(calibration=CalibrationConfig(speed=0.02))          # a quick pull for the test
    rig = SimulatedRig.from_config(cfg)
    clock = FakeClock(0.0)
    links = SlaveLinks(*(Topic(clock) for _ in range(4)))
    node = SlaveNode(cfg, rig, links, run_dir=tmp_path, calibration_file=tmp_path / "cal" / "tendon0.yaml")
    assert node.state == SideState.CALIBRATING
    command(links, 1, 0.05)                                          # ignored while calibrating
    tissue_seen = []
    for _ in range(20000):
        tick(node, clock)
        tissue_seen.append(rig.tissue)
        if node.state != SideState.CALIBRATING:
            break
    assert node.state == SideState.SAFE                              # calibrated, no fresh command
    assert not links.estimate.sent                                   # nothing estimated while calibrating
    states = [h.state for h in links.heartbeat.sent]
    assert set(states[:-1]) == {SideState.CALIBRATING} and states[-1] == SideState.SAFE   # the change: at once
    assert tissue_seen[0] is False and rig.tissue is True            # tissue off for the pull, back after
    cal = json.loads((tmp_path / "calibration.json").read_text())
    assert cal["K"] == pytest.approx(rig.K, rel=0.05)
    assert cal["M_e_m_per_N"] == pytest.approx(rig.M_e, rel=0.02)
    assert node.axes[0].estimator.model.K == cal["K"]
    assert rig.state.truth.T_in < 0.5                                # released back to (near) zero tension
    # the estimator's memory matches the tendon after the replay of the routine
    est = node.axes[0].estimator
    assert est.T_out == pytest.approx(rig.state.truth.T_out, abs=0.3)
    # the calibration life cycle of every instrument: saved, reloaded by the next power-up (no routine)
    saved = load_calibration(tmp_path / "cal" / "tendon0.yaml", cfg)
    assert saved.tendon.K == pytest.approx(cal["K"]) and saved.tendon.M_e == pytest.approx(cal["M_e_m_per_N"])
    again = SimulatedRig.from_config(cfg)
    node2 = SlaveNode(cfg, again, SlaveLinks(*(Topic(clock) for _ in range(4))), run_dir=tmp_path / "second",
                      calibration=saved, calibration_file=tmp_path / "cal" / "tendon0.yaml")
    assert node2.state == SideState.SAFE and node2.routine is None               # no routine runs
    assert (node2.axes[0].estimator.model.K == saved.tendon.K
            and node2.axes[0].estimator.model.compliance == saved.tendon.compliance)
    cal2 = json.loads((tmp_path / "second" / "calibration.json").read_text())
    assert cal2["K"] == saved.tendon.K and cal2["loaded_from"].endswith("tendon0.yaml")
    assert node2.stats()["calibration"] == "loaded" and node.stats()["calibration"] == "power-up"
    # the pull's T_in noise, measured by the routine, is the estimator's noise band, saved and reloaded with it
    sigma = cfg.rig.simulated.sensors.load_cell_noise
    assert cal["tension_noise_N"] == pytest.approx(sigma, rel=0.2) and est.tension_noise == cal["tension_noise_N"]
    assert saved.tendon.tension_noise == pytest.approx(cal["tension_noise_N"])
    assert node2.axes[0].estimator.tension_noise == saved.tendon.tension_noise
    # the config overrides it (0: the envelope rule without a band), and a file from before it has none: 0
    off = dataclasses.replace(cfg, estimator=dataclasses.replace(cfg.estimator, tension_noise=0.0))
    node3 = SlaveNode(off, SimulatedRig.from_config(off), SlaveLinks(*(Topic(clock) for _ in range(4))),
                      run_dir=tmp_path / "third", calibration=saved, calibration_file=tmp_path / "cal" / "tendon0.yaml")
    assert node3.axes[0].estimator.tension_noise == 0.0
    old = tmp_path / "old.yaml"
    old.write_text((tmp_path / "cal" / "tendon0.yaml").read_text().replace("tension_noise:", "# tension_noise:"))
    assert load_calibration(old, cfg).tendon.tension_noise == 0.0


def test_a_command_for_another_number_of_axes_is_counted_and_ignored():
    node, links, clock = make()
    links.command.put(Command(1, 0.0, (0.001, 0.002), True, 0))      # two targets: not a single tendon
    tick(node, clock)
    assert node.counts["commands_wrong_axes"] == 1 and node.commands_applied == 0
    assert node.state == SideState.SAFE


def test_calibration_without_a_joint_limit_fails_with_a_message():
    cfg = Config(calibration=CalibrationConfig(speed=0.05, target_tension=1e4))
    rig = SimulatedRig.from_config(cfg)
    cal = JointLimitCalibration(cfg, rig, max_travel=0.01)
    state = rig.state
    with pytest.raises(CalibrationError, match="no joint limit found"):
        for _ in range(10000):
            state = rig.step(cal.command(state, DT), DT)
            cal.observe(state)
    assert cal.stage == CalStage.PULL


def test_commands_beyond_the_step_or_speed_limit_are_refused_or_slowed_and_counted():
    node, links, clock = make(slave={"max_step": 0.001, "max_speed": 0.05})
    command(links, 1, 0.0005)
    tick(node, clock)
    assert node.state == SideState.ENGAGED and node.rig.cmds[-1] == 0.0005
    command(links, 2, 0.0025)                  # a 2 mm jump: refused, the last accepted target still followed
    tick(node, clock)
    assert node.counts["commands_step_refused"] == 1 and node.rig.cmds[-1] == 0.0005
    for k in range(3, 23):                     # 0.5 mm a cycle (500 mm/s): each step accepted, the motion slowed
        command(links, k, 0.0005 + 0.0005 * (k - 2))
        tick(node, clock)
    cmds = np.diff(node.rig.cmds[-21:])
    assert node.counts["commands_step_refused"] == 1 and node.counts["commands_speed_limited"] == 20
    assert np.all(cmds <= 0.05 * DT * (1 + 1e-9)) and cmds[-1] == pytest.approx(0.05 * DT)
    refusals = node.stats()["refusals"]
    assert set(refusals) == {"foreign_source", "decode_error", "wrong_axes", "out_of_range", "step", "out_of_order",
                             "duplicate", "engage_too_far", "stale", "ros2_servo", "ros2_state_command",
                             "no_credentials"}
    assert refusals["step"] == 1 and sum(refusals.values()) == 1
    tick(node, clock, 60)                      # the commands stop: stale, counted once
    assert node.stats()["refusals"]["stale"] == 1


def test_a_sequence_number_far_ahead_holds_the_real_commands_back_for_two_messages_only():
    node, links, clock = make()
    for k in range(1, 6):
        command(links, k, 0.0001 * k)
        tick(node, clock)
    command(links, 4_000_000, 0.0006)          # forged (or corrupt) seq far ahead, a plausible target
    tick(node, clock)
    for k in range(6, 12):                     # the real stream goes on
        command(links, k, 0.0001 * k)
        tick(node, clock)
    assert node.counts["commands_out_of_order"] == 2 and node.counts["commands_resync"] == 1
    assert node.cmd_seq == 11 and node.rig.cmds[-1] == pytest.approx(0.0011)
