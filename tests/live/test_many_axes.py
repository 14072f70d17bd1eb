"""Instruments of 8 and 16 joints (16 and 32 tendons) through every per-axis path: the config, the codec,
the master and slave nodes in one process, their CSV columns, the CRTK topics and the MCAP recording.

The joints are those of configs/instrument-3dof.yaml repeated under distinct names; the slave runs on a
calibration taken from the simulator's own K and M_e (what the power-up routine measures to ~1 %).
"""
from __future__ import annotations

import csv
from pathlib import Path

import pytest

from master.devices import make_device
from master.node import MasterNode
from master.node import csv_columns as master_columns
from master.node_base import MasterLinks
from slave.calibration_file import InstrumentCalibration, TendonCalibration
from slave.node import SlaveNode, recording
from slave.node_base import SlaveLinks
from slave.rigs import RIG_TYPES
from teleop.arms import repeated_joints
from teleop.config.load import load_config
from teleop.config.schema import Config
from teleop.recording.measured import CsvRecorder
from teleop.ros2.crtk import slave_messages
from teleop.timing.clock import FakeClock
from teleop.wire.messages import Estimate, SideState
from tests.fakes import Topic
from tests.ros2_peer import JOINT_STATE, WRENCH_STAMPED, independent_decoder

CONFIGS = Path(__file__).resolve().parents[2] / "configs"


def many_joints(n: int) -> Config:
    """configs/instrument-3dof.yaml with its joints repeated to ``n`` (names ``<joint><k>``), one device axis each."""
    return repeated_joints(load_config(CONFIGS / "instrument-3dof.yaml", {"recording.rerun": "off"}), n, f"many{n}")


def simulator_calibration(cfg: Config, rig) -> InstrumentCalibration:
    """Every tendon's K and M_e as the simulator has them, its compliance L/EA from the route."""
    def tendon(j, k, t):
        g = getattr(j.tendons, t).geometry()
        return TendonCalibration(K=float(rig.K[k, "ab".index(t)]), M_e=float(rig.M_e[k, "ab".index(t)]),
                                 compliance=g.length / getattr(j.tendons, t).EA, knee_x_in=0.0, knee_T_in=0.0,
                                 residual_rms=0.0, n_samples=1, tension_noise=cfg.rig.simulated.sensors.load_cell_noise)
    return InstrumentCalibration(cfg.instrument.id, "2026-01-01T00:00:00+00:00", 20.0, True,
                                 tuple((j.name, {t: tendon(j, k, t) for t in "ab"})
                                       for k, j in enumerate(cfg.instrument.joints)))


def _rows(path: Path) -> list[list[str]]:
    with open(path, newline="", encoding="utf-8") as fh:
        return [r for r in csv.reader(fh) if r and not r[0].startswith("#")]


@pytest.mark.parametrize("n", [8, 16])
def test_master_and_slave_of_many_joints_run_record_and_publish_every_axis(n, tmp_path):
    cfg = many_joints(n)
    clock = FakeClock(10.0)
    cmd, est, mhb, shb = (Topic(clock, codec=True, keep=False) for _ in range(4))
    rig = RIG_TYPES["simulated"](cfg, None)
    name, columns, meta = recording(cfg, rig)
    with CsvRecorder(tmp_path / name, columns, meta) as srec, \
            CsvRecorder(tmp_path / "master.csv", master_columns(cfg), {"source": "test"}) as mrec:
        slave = SlaveNode(cfg, rig, SlaveLinks(est, shb, cmd, mhb), recorder=srec,
                          calibration=simulator_calibration(cfg, rig))
        master = MasterNode(cfg, make_device(cfg, "short"), MasterLinks(cmd, mhb, est, shb), recorder=mrec)
        for _ in range(600):
            t = clock.advance(1e-3)
            master.step(t)
            slave.step(t)
    last = est.last.message
    assert isinstance(last, Estimate) and len(last.axes) == n and len(last.tendons) == 2 * n
    assert len(cmd.last.message.targets) == n and slave.state != SideState.SAFE
    assert cmd.last.message.marker > 0          # the scripted operator's tags fit the wire's uint32 marker
    for path, cols in ((tmp_path / name, columns), (tmp_path / "master.csv", master_columns(cfg))):
        rows = _rows(path)
        assert rows[0] == list(cols) and len(rows) > 500 and all(len(r) == len(cols) for r in rows[1:])
    assert len(columns) == 6 + n * (6 + 2 * 8) and f"{cfg.instrument.joints[-1].name}.b.T_out_hat" in columns
    head, body = _rows(tmp_path / name)[0], _rows(tmp_path / name)[-1]
    assert float(body[head.index(f"{cfg.instrument.joints[-1].name}.torque_hat")]) == \
        pytest.approx(last.axes[-1].effort_hat, rel=1e-9)

    msgs = dict(slave_messages(cfg, 1, SideState.ENGAGED, last, cmd.last.message.targets))
    js, wr = independent_decoder(JOINT_STATE), independent_decoder(WRENCH_STAMPED)
    arm = cfg.instrument.id
    assert list(js(msgs[f"/{arm}/measured_js"]).name) == [j.name for j in cfg.instrument.joints]
    act = js(msgs[f"/{arm}/actuators/measured_js"])
    assert len(act.name) == 2 * n and list(act.effort) == [t.T_in for t in last.tendons]
    last_joint = cfg.instrument.joints[-1].name
    assert wr(msgs[f"/{arm}/{last_joint}/measured_cf"]).wrench.torque.z == last.axes[-1].effort_hat


@pytest.mark.parametrize("n", [8, 16])
def test_the_mcap_recording_names_every_tendon_of_many_joints(n, tmp_path):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    from estimator.phase import Phase
    from live.record.mcap_file import McapRecording
    from teleop.wire.messages import AxisState, TendonState
    cfg = many_joints(n)
    axes = tuple(AxisState(0.01 * k, 0.1 * k, (TendonState(1.0 + k, 1e-3, 0.5, 1e-5, Phase.PULL),
                                                TendonState(2.0, -1e-3, 1.5, 1e-5, Phase.HOLD))) for k in range(n))
    mc = McapRecording(tmp_path / "s.mcap", cfg, 1.7e9)
    # seq 0: kept at any mcap_every
    mc.write(5.001, f"teleop/{cfg.instrument.id}/slave/estimate", Estimate(0, 1, 5.0, axes))
    mc.close()
    with open(tmp_path / "s.mcap", "rb") as fh:
        reader = make_reader(fh, decoder_factories=[DecoderFactory()])
        cdr = [c.topic for c in reader.get_summary().channels.values() if c.message_encoding == "cdr"]
        got = {x.channel.topic: x.decoded_message for x in reader.iter_decoded_messages(topics=cdr)}
    arm = cfg.instrument.id
    act = got[f"/{arm}/actuators/measured_js"]
    assert list(act.name) == [f"{j.name}_{t}" for j in cfg.instrument.joints for t in "ab"]
    assert list(act.effort) == [v for k in range(n) for v in (1.0 + k, 2.0)]
    assert list(got[f"/{arm}/measured_js"].position) == [0.1 * k for k in range(n)]
    assert sum(1 for topic in got if topic.endswith("/measured_cf")) == n

