"""The SlaveNode and the MasterNode of a joint instrument on one FakeClock, talking through in-memory topics that go
through the codec: calibration at power-up, the paper protocol on all three joints, watchdog."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from master.node import MasterNode, csv_columns
from master.node_base import MasterLinks
from master.protocols import joint_marker, paper_protocol
from master.simulated import ScriptedOperator
from slave.calibration_file import load_calibration, sheath_models
from slave.node import SlaveNode
from slave.node_base import SlaveLinks
from slave.pair_axis import joint_csv_columns
from slave.pair_calibrate import set_tension
from slave.pair_rig import SimulatedInstrument
from teleop.config.load import load_config
from teleop.timing.clock import FakeClock
from teleop.wire.messages import Command, SideState
from tests.fakes import Rows, Topic

CONFIG = Path(__file__).resolve().parents[2] / "configs" / "instrument-3dof.yaml"
DT = 1e-3


def build(tmp_path, calibration=None, **overrides):
    cfg = load_config(CONFIG, {"calibration.speed": 0.01, **overrides})
    clock = FakeClock(0.0)
    cmd, est, shb, mhb = (Topic(clock, codec=True, keep=False) for _ in range(4))
    inst = SimulatedInstrument.from_config(cfg)
    rec = Rows()
    slave = SlaveNode(cfg, inst, SlaveLinks(estimate=est, heartbeat=shb, command=cmd, master_heartbeat=mhb),
                      recorder=rec, calibration=calibration, calibration_file=tmp_path / "flex3.yaml",
                      run_dir=tmp_path, stop_on_master_stop=True)
    op = ScriptedOperator([paper_protocol(set_tension(cfg, j)) for j in cfg.instrument.joints])
    master = MasterNode(cfg, op, MasterLinks(command=cmd, heartbeat=mhb, estimate=est, slave_heartbeat=shb),
                        recorder=Rows())
    return cfg, clock, slave, master, op, rec, (cmd, est, shb, mhb)


def run(clock, slave, master, seconds, until=None):
    for _ in range(int(seconds / DT)):
        clock.advance(DT)
        now = clock.now()
        slave.step(now)
        master.step(now)
        if until is not None and until():
            break


def _columns(cfg, rec) -> dict:
    """The slave's recorded rows by column name."""
    data = np.array(rec.rows)
    return {name: data[:, k] for k, name in enumerate(joint_csv_columns([j.name for j in cfg.instrument.joints], True))}


def _pulls(cfg, c: dict):
    """(joint name, tag, rows) of every joint's protocol on tendon a (tag 1), then on b (2)."""
    for j, joint in enumerate(cfg.instrument.joints):
        tags = np.array([joint_marker(int(m), j) for m in c["marker"]])
        for tag in (1, 2):
            yield joint.name, tag, tags == tag


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    tmp_path = tmp_path_factory.mktemp("joint_nodes")
    cfg, clock, slave, master, op, rec, topics = build(tmp_path)
    run(clock, slave, master, 60.0, until=lambda: master.done and slave.done)
    return cfg, slave, master, op, rec, tmp_path


def test_power_up_calibration_is_saved_and_reloadable(demo):
    cfg, slave, master, op, rec, tmp_path = demo
    cal = load_calibration(tmp_path / "flex3.yaml", cfg)
    assert [n for n, _ in cal.joints] == ["bend_ud", "bend_lr", "grasp"]
    assert (tmp_path / "calibration.json").is_file()
    inst = SimulatedInstrument.from_config(cfg)
    sigma = cfg.rig.simulated.sensors.load_cell_noise
    for i, (_, tend) in enumerate(cal.joints):
        for k, t in enumerate("ab"):
            assert tend[t].K == pytest.approx(inst.K[i, k], rel=0.05)
            # the pull's load-cell noise, measured and saved: the joint estimator's noise band
            assert tend[t].tension_noise == pytest.approx(sigma, rel=0.2)
            assert slave.axes[i].estimator.tendons[k].tension_noise == tend[t].tension_noise


def test_paper_protocol_on_every_joint_within_5_percent_full_scale(demo):
    cfg, slave, master, op, rec, _ = demo
    assert op.finished and op.timeouts == 0 and master.done and slave.done
    assert master.safe_events == 0 and slave.safe_events == 0 and master.engage_count == 1
    c = _columns(cfg, rec)
    for n, tag, sel in _pulls(cfg, c):                      # tendon a's protocol, then b's, per joint
        assert sel.sum() > 1000
        true, hat = c[f"{n}.torque"][sel], c[f"{n}.torque_hat"][sel]
        assert np.ptp(true) > 0.01
        assert np.abs(hat - true).max() / np.ptp(true) <= 0.05, (n, tag)
        pulled = "a" if tag == 1 else "b"
        # the operator anticipates its hand's lag and stops its intention early (as on one tendon)
        assert c[f"{n}.{pulled}.T_in"][sel].max() > 19.0
    for joint in cfg.instrument.joints:
        n = joint.name
        assert np.abs(c[f"{n}.angle_hat"] - c[f"{n}.angle"]).max() < 0.02
    assert set(slave.stats()["side_switches"]) != {0}
    assert master.latency_stats()["n"] > 1000 and master.max_abs_force <= cfg.master.mapping.force_limit


def test_reloaded_calibration_starts_safe_and_the_watchdog_relaxes_the_joints(demo, tmp_path):
    cfg = demo[0]
    cal = load_calibration(demo[5] / "flex3.yaml", cfg)
    cfg2, clock, slave, master, op, rec, (cmd, est, shb, mhb) = build(tmp_path, calibration=cal)
    assert slave.state == SideState.SAFE
    run(clock, slave, master, 3.0)                          # engage and pull for a while
    assert slave.state == SideState.ENGAGED and master.state == SideState.ENGAGED
    theta = slave.rig_state.truth.theta.copy()
    assert np.abs(theta).max() > 0.2
    cmd.cut = True                                          # master -> slave link cut
    run(clock, slave, master, 0.15)
    assert slave.state == SideState.SAFE and master.state == SideState.SAFE   # echo stale on the master too
    run(clock, slave, master, 3.0)
    tr = slave.rig_state.truth
    assert np.abs(tr.theta).max() < 0.5 * np.abs(theta).max()              # relaxing toward rest
    assert np.all(tr.T_in < 2.0) and np.all(tr.T_in > 0.05)                # both tendons loose, none slack
    assert all(a.controller.mode == 0 for a in slave.axes)


def test_commands_for_another_instrument_or_out_of_range_are_refused(demo, tmp_path):
    cal = load_calibration(demo[5] / "flex3.yaml", demo[0])
    cfg, clock, slave, master, op, rec, (cmd, est, shb, mhb) = build(tmp_path, calibration=cal)
    for _k, c in enumerate((Command(1, 0.0, (0.0, 0.0)), Command(2, 0.0, (0.0, 0.0, 20.0)),
                           Command(3, 0.0, (0.0, 0.0, 0.0)), Command(3, 0.0, (0.0, 0.0, 0.0)))):
        cmd.put(c)
        clock.advance(DT)
        slave.step(clock.now())
    s = slave.stats()
    assert s["commands_wrong_axes"] == 1 and s["commands_rejected_range"] == 1 and s["commands_duplicate"] == 1
    assert slave.state == SideState.READY or slave.state == SideState.ENGAGED


def test_the_joint_master_reports_its_console_and_records_every_cycle(demo):
    cfg, slave, master, op, rec, _ = demo
    s = master.stats()
    assert s["axes"] == [j.name for j in cfg.instrument.joints] and s["console"] == "STOPPING"
    assert s["engage_count"] == 1 and s["clutches"] == 0 and s["align_refusals"] == 0
    cols = csv_columns(cfg)
    data = np.array(master.recorder.rows)
    assert data.shape == (master.pacer_stats.get("ticks", data.shape[0]), len(cols))
    c = {name: data[:, k] for k, name in enumerate(cols)}
    engaged = c["state"] == SideState.ENGAGED
    assert engaged.sum() > 5000                         # seconds of teleoperation at 1 kHz
    for j in cfg.instrument.joints:
        assert np.abs(c[f"{j.name}.force"]).max() <= cfg.master.mapping.force_limit + 1e-12
        cmd, angle = c[f"{j.name}.cmd"][engaged], c[f"{j.name}.slave"][engaged]
        assert np.ptp(cmd) > 0.1 and np.corrcoef(cmd, angle)[0, 1] > 0.9      # the joint follows (with its lag)


def test_backlash_compensation_runs_the_paper_protocol_from_the_calibrated_bands(tmp_path):
    cfg, clock, slave, master, op, rec, _ = build(tmp_path, **{"pair_control.backlash_compensation": True})
    run(clock, slave, master, 60.0, until=lambda: master.done and slave.done)
    assert op.finished and op.timeouts == 0 and master.safe_events == 0 and slave.safe_events == 0
    cal = load_calibration(tmp_path / "flex3.yaml", cfg)
    for ax, models in zip(slave.axes, sheath_models(cal, cfg), strict=False):
        ctl = ax.controller
        assert ctl is not None and ctl._bank is not None                # stepped by the compiled bank
        for k, m in enumerate(models):                                   # c_rev of the calibrated models
            assert ctl.band_compliance[k] == pytest.approx(m.reversal_compliance) and 0 < m.reversal_compliance
            assert m.reversal_compliance < m.M_e                         # a share of the pull's elongation
    c = _columns(cfg, rec)
    for n, tag, sel in _pulls(cfg, c):
        true, hat = c[f"{n}.torque"][sel], c[f"{n}.torque_hat"][sel]
        assert np.abs(hat - true).max() / np.ptp(true) <= 0.05, (n, tag)
        assert np.abs(c[f"{n}.angle_hat"][sel] - c[f"{n}.angle"][sel]).max() < 0.02     # the tendons never slack
