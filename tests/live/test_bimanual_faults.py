"""Per-arm safety of the bimanual instrument, in process: both sides' node groups (teleop/node_group.py) on one
FakeClock with in-memory links that go through the codec, the shared foot pedal on the master (master/pedal.py).

A fault on the left arm (its estimate stream cut, its estimates carrying an impossible tension, its hand's device
lost) makes the left arm safe within 100 ms, while the right arm's master rows are those of the same run without
any fault, cycle for cycle: its loop is untouched. A lost master makes both arms' slaves safe. The process-level test is tests/integration/test_bimanual.py."""
from __future__ import annotations

import dataclasses
import functools
import tempfile
from pathlib import Path

import numpy as np
import pytest
import yaml

from live.faults import FaultInjector
from master.devices import make_device
from master.node import MasterLinks, MasterNode
from master.pedal import FootPedal, PedalHand
from slave.calibration_file import InstrumentCalibration, TendonCalibration
from slave.joint_rig import SimulatedInstrument
from slave.node import SlaveLinks, SlaveNode
from teleop.arms import Bimanual, load_arms
from teleop.clock import FakeClock
from teleop.codec import decode
from teleop.messages import Side, SideState
from teleop.node_group import NodeGroup
from teleop.transport import Received
from tests.fakes import Rows, Topic

ROOT = Path(__file__).resolve().parents[2]
DT = 1e-3
T_FAULT, T_END = 0.6, 0.75        # [s] the fault starts once both hands move (0.5 s); the run ends 150 ms later
SAFE_WITHIN = 0.1                 # [s]


@functools.lru_cache(maxsize=1)
def cheap_bimanual() -> Bimanual:
    """The shipped bimanual instrument with coarser sheaths (a short in-process run), same joints and loads."""
    data = yaml.safe_load((ROOT / "configs" / "notes-bimanual.yaml").read_text(encoding="utf-8"))
    data["rig"]["simulated"]["n_elements"] = 20
    data["estimator"] = {"n_nodes": 20}
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "bimanual.yaml"
        path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
        return load_arms(path)


def true_calibration(cfg, rig: SimulatedInstrument) -> InstrumentCalibration:
    """The simulator's own K and L/EA of every tendon as calibration data (the run skips the power-up pulls)."""
    joints = []
    for i, j in enumerate(cfg.instrument.joints):
        tend = {}
        for k, t in enumerate("ab"):
            tc = getattr(j.tendons, t)
            K, c = float(rig.K[i, k]), tc.geometry().length / tc.EA
            tend[t] = TendonCalibration(K=K, M_e=float(c * (1 - np.exp(-K)) / K), compliance=c, knee_x_in=0.005,
                                        knee_T_in=4.0, residual_rms=1e-6, n_samples=300)
        joints.append((j.name, tend))
    return InstrumentCalibration(instrument=cfg.instrument.id, date="2026-01-01T00:00:00+00:00",
                                 target_tension=cfg.calibration.target_tension, use_route=True, joints=tuple(joints))


class WireTopic(Topic):
    """A :class:`tests.fakes.Topic` that also takes the codec bytes a fault injector sends on."""

    def put_bytes(self, payload: bytes) -> None:
        self.last = Received(decode(payload), self.clock.now())
        self.count += 1


class LostAfter:
    """A hand's device that is lost (no operator reading: deadman off) from ``t_lost`` on."""

    def __init__(self, device, t_lost: float):
        self.inner, self.t_lost = device, t_lost

    def read(self, t):
        st = self.inner.read(t)
        return dataclasses.replace(st, operator_present=False) if t >= self.t_lost else st

    def __getattr__(self, name):
        if name == "inner":
            raise AttributeError(name)
        return getattr(self.inner, name)


def run(tmp_path: Path, fault: str | None):
    """Both arms for T_END seconds with ``fault`` on the left arm from T_FAULT; (arms, master rows, states)."""
    bim = cheap_bimanual()
    clock = FakeClock(0.0)
    pedal = FootPedal([a.cfg.master.mapping.clutch_button for a in bim.arms])
    slaves, masters, rows, topics = [], [], [], []
    for i, arm in enumerate(bim.arms):
        cmd, est, shb, mhb = (WireTopic(clock, codec=True, keep=False) for _ in range(4))
        rig = SimulatedInstrument.from_config(arm.cfg)
        est_out = est
        if arm.hand == "left" and fault == "range":     # every estimate with T_out_hat = 1e4 N from T_FAULT
            est_out = FaultInjector(f"corrupt=range,stream=estimate,at={T_FAULT}s", clock).wrap(est, "estimate")
        slaves.append(SlaveNode(arm.cfg, rig, SlaveLinks(estimate=est_out, heartbeat=shb, command=cmd,
                                                         master_heartbeat=mhb),
                                calibration=true_calibration(arm.cfg, rig), run_dir=tmp_path / arm.ident))
        dev = make_device(arm.cfg, "paper")
        if arm.hand == "left" and fault == "device":
            dev = LostAfter(dev, T_FAULT)
        rec = Rows()
        masters.append(MasterNode(arm.cfg, PedalHand(dev, pedal, i),
                                  MasterLinks(command=cmd, heartbeat=mhb, estimate=est, slave_heartbeat=shb),
                                  recorder=rec))
        rows.append(rec)
        topics.append(est)
    names = [a.name for a in bim.arms]
    sg = NodeGroup(slaves, names, Side.SLAVE, 1000.0)
    mg = NodeGroup(masters, names, Side.MASTER, 1000.0)
    states = []
    for _ in range(int(round(T_END / DT))):
        clock.advance(DT)
        now = clock.now()
        if fault == "cut" and now >= T_FAULT:
            topics[0].cut = True                         # the left arm's estimates no longer arrive
        sg.step(now)
        if fault != "peer" or now < T_FAULT:            # "peer": the master process is gone
            mg.step(now)
        states.append((now, masters[0].state, masters[1].state, slaves[1].state, slaves[0].state))
    return bim, masters, [np.array(r.rows) for r in rows], states


@pytest.fixture(scope="module")
def baseline(tmp_path_factory):
    return run(tmp_path_factory.mktemp("bimanual_base"), None)


@pytest.mark.parametrize("fault", ["cut", "range", "device"])
def test_fault_on_left_arm_makes_it_safe_and_leaves_right_arm_untouched(tmp_path, baseline, fault):
    _, m0, rows0, states0 = baseline
    assert all(s[1] == SideState.ENGAGED and s[2] == SideState.ENGAGED for s in states0 if s[0] >= T_FAULT - 0.1), \
        "both arms track before the fault time"
    bim, masters, rows, states = run(tmp_path, fault)
    safe_at = next((s[0] for s in states if s[0] >= T_FAULT and s[1] == SideState.SAFE), None)
    assert safe_at is not None and safe_at - T_FAULT <= SAFE_WITHIN
    assert masters[0].safe_events == 1
    # the right arm: engaged throughout, never a safe event, and cycle for cycle what it was without the fault
    assert all(s[2] == SideState.ENGAGED and s[3] == SideState.ENGAGED for s in states if s[0] >= T_FAULT)
    assert masters[1].safe_events == 0
    right = rows[1]
    assert (right[:, 0] >= T_FAULT).sum() >= int((T_END - T_FAULT) / DT) - 1
    np.testing.assert_array_equal(right, rows0[1])


def test_lost_master_makes_both_arms_safe(tmp_path):
    _, _, _, states = run(tmp_path, "peer")
    for k in (3, 4):                                      # the right and the left arm's slave
        assert states[int(T_FAULT / DT) - 2][k] == SideState.ENGAGED
        safe_at = next((s[0] for s in states if s[0] >= T_FAULT and s[k] == SideState.SAFE), None)
        assert safe_at is not None and safe_at - T_FAULT <= SAFE_WITHIN


def test_shared_pedal_clutches_both_hands_and_deadman_stays_per_hand():
    class Dev:
        def __init__(self, buttons=0, present=True):
            self.buttons, self.present = buttons, present

        def read(self, t):
            from master.device import MultiAxisState
            return MultiAxisState(t=t, positions=(0.0,), buttons=self.buttons, operator_present=self.present)

    pedal = FootPedal([1, 2])
    left, right = Dev(), Dev(buttons=1 << 0, present=False)
    hl, hr = PedalHand(left, pedal, 0), PedalHand(right, pedal, 1)
    assert hl.read(0.0).buttons == 0 and hr.read(0.0).buttons == 1 << 0
    left.buttons = 1 << 1                                  # the left hand's pedal bit: both clutch, each in its bit
    assert hl.read(0.001).buttons == 1 << 1
    st = hr.read(0.001)
    assert st.buttons == (1 << 0) | (1 << 2) and not st.operator_present   # the right's deadman stays its own
    left.buttons = 0
    assert hl.read(0.002).buttons == 0 and hr.read(0.002).buttons == 1 << 0
    assert pedal.presses == 1 and not pedal.pressed
