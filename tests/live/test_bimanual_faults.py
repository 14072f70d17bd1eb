"""Per-arm safety of the bimanual instrument, in process: both sides' node groups (teleop/node_group.py) on one
FakeClock with in-memory links that go through the codec, the shared foot pedal on the master (master/pedal.py).

A fault on the left arm (its estimate stream cut, its estimates carrying an impossible tension, its hand's device
lost, a tendon driven by the physics past the arm's ``master.max_tension``) makes the left arm safe within 100 ms,
while the right arm's master rows are those of the same run without any fault, cycle for cycle: its loop is
untouched. A tendon at its limit is not held there: the left slave relaxes. With the limit on the slave
(``slave.max_tension``) the left slave goes SAFE in the very cycle its measured tension passes it and the left master
latches. A lost master makes both arms' slaves safe. The process-level test is tests/integration/test_bimanual.py."""
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
from master.node import MasterNode
from master.node_base import MasterLinks
from master.pedal import FootPedal, PedalHand
from slave.calibration_file import InstrumentCalibration, TendonCalibration
from slave.node import SlaveNode
from slave.node_base import SlaveLinks
from slave.pair_axis import joint_csv_columns
from slave.pair_rig import SimulatedInstrument
from teleop.arms import Bimanual, load_arms
from teleop.node_group import NodeGroup
from teleop.session.transport import Received
from teleop.timing.clock import FakeClock
from teleop.wire.codec import decode
from teleop.wire.messages import Side, SideState
from tests.fakes import Rows, Topic

ROOT = Path(__file__).resolve().parents[2]
DT = 1e-3
T_FAULT, T_END = 0.6, 0.85        # [s] the fault starts once both hands move (0.5 s); the run ends 250 ms later
SAFE_WITHIN = 0.1                 # [s]
# [N] the left arm's master.max_tension in the "limit" run: above every tension of the arm's free motion (the
# bending sections and the elbow stay below 1.7 N), below what the grasp's tendon a pulls once the jaws close
# on the tissue
LEFT_LIMIT = 2.0


@functools.lru_cache(maxsize=2)
def cheap_bimanual(left_max_tension: float | None = None) -> Bimanual:
    """The shipped bimanual instrument with coarser sheaths (a short in-process run), same joints and loads;
    ``left_max_tension`` [N]: the left arm's ``master.max_tension`` (its arms overlay), None: the shipped one."""
    data = yaml.safe_load((ROOT / "configs" / "notes-bimanual.yaml").read_text(encoding="utf-8"))
    data["rig"]["simulated"]["n_elements"] = 20
    data["estimator"] = {"n_nodes": 20}
    if left_max_tension is not None:
        left = next(a for a in data["arms"] if a["hand"] == "left")
        left.setdefault("master", {})["max_tension"] = left_max_tension
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
    """Both arms for T_END seconds with ``fault`` on the left arm from T_FAULT ("limit": the left arm's
    ``master.max_tension`` is LEFT_LIMIT throughout; "slave_limit": its ``slave.max_tension``, which both of its
    sides read, as from one config file); (arms, masters, master rows, states, slave rows)."""
    bim = cheap_bimanual(LEFT_LIMIT if fault == "limit" else None)
    clock = FakeClock(0.0)
    pedal = FootPedal([a.cfg.master.mapping.clutch_button for a in bim.arms])
    slaves, masters, rows, topics, slave_rows = [], [], [], [], []
    for i, arm in enumerate(bim.arms):
        if arm.hand == "left" and fault == "slave_limit":     # a slave setting: the arms overlay has none
            arm = dataclasses.replace(arm, cfg=dataclasses.replace(
                arm.cfg, slave=dataclasses.replace(arm.cfg.slave, max_tension=LEFT_LIMIT)))
        cmd, est, shb, mhb = (WireTopic(clock, codec=True, keep=False) for _ in range(4))
        rig = SimulatedInstrument.from_config(arm.cfg)
        est_out = est
        if arm.hand == "left" and fault == "range":     # every estimate with T_out_hat = 1e4 N from T_FAULT
            est_out = FaultInjector(f"corrupt=range,stream=estimate,at={T_FAULT}s", clock).wrap(est, "estimate")
        slave_rows.append(Rows())
        slaves.append(SlaveNode(arm.cfg, rig, SlaveLinks(estimate=est_out, heartbeat=shb, command=cmd,
                                                         master_heartbeat=mhb), recorder=slave_rows[-1],
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
    return bim, masters, [np.array(r.rows) for r in rows], states, [np.array(r.rows) for r in slave_rows]


@pytest.fixture(scope="module")
def baseline(tmp_path_factory):
    return run(tmp_path_factory.mktemp("bimanual_base"), None)


@pytest.mark.parametrize("fault", ["cut", "range", "device"])
def test_fault_on_left_arm_makes_it_safe_and_leaves_right_arm_untouched(tmp_path, baseline, fault):
    _, m0, rows0, states0, _ = baseline
    assert all(s[1] == SideState.ENGAGED and s[2] == SideState.ENGAGED for s in states0 if s[0] >= T_FAULT - 0.1), \
        "both arms track before the fault time"
    bim, masters, rows, states, _ = run(tmp_path, fault)
    safe_at = next((s[0] for s in states if s[0] >= T_FAULT and s[1] == SideState.SAFE), None)
    assert safe_at is not None and safe_at - T_FAULT <= SAFE_WITHIN
    assert masters[0].safe_events == 1
    assert_right_arm_untouched(masters, rows, states, rows0)


def assert_right_arm_untouched(masters, rows, states, rows0) -> None:
    """The right arm: engaged throughout, never a safe event, and cycle for cycle what it was without the fault."""
    assert all(s[2] == SideState.ENGAGED and s[3] == SideState.ENGAGED for s in states if s[0] >= T_FAULT)
    assert masters[1].safe_events == 0
    right = rows[1]
    assert (right[:, 0] >= T_FAULT).sum() >= int((T_END - T_FAULT) / DT) - 1
    np.testing.assert_array_equal(right, rows0[1])


def measured_tension(bim: Bimanual, slave_rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The left arm's slave rows as (node time [s], largest measured |T_in| of its tendons [N]), one per cycle."""
    cols = joint_csv_columns([j.name for j in bim.arms[0].cfg.instrument.joints], True)
    t_in = [k for k, c in enumerate(cols) if c.endswith(".T_in")]
    return slave_rows[:, cols.index("t_node")], np.abs(slave_rows[:, t_in]).max(axis=1)


def test_a_tendon_driven_past_its_limit_makes_its_arm_safe_and_relaxes_it(tmp_path, baseline):
    bim0, _, rows0, _, slave0 = baseline
    t0, free = measured_tension(bim0, slave0[0])
    assert free[t0 < T_FAULT].max() < LEFT_LIMIT < free.max(), "the free motion stays below, the grasp goes past"
    bim, masters, rows, states, slave_rows = run(tmp_path, "limit")
    t, peak = measured_tension(bim, slave_rows[0])
    over = peak > LEFT_LIMIT
    t_cross = t[np.argmax(over)]                       # the first cycle whose measured tension is past the limit
    assert over.any() and t_cross > T_FAULT
    assert all(s[1] == SideState.ENGAGED for s in states if T_FAULT - 0.1 <= s[0] < t_cross)
    safe_at = next((s[0] for s in states if s[0] >= t_cross and s[1] == SideState.SAFE), None)
    assert safe_at is not None and safe_at - t_cross <= SAFE_WITHIN
    assert masters[0].safe_events >= 1 and masters[0].counts["estimates_rejected_range"] > 0
    # the left slave relaxes: SAFE within the same time, its tendons back below the limit a few cycles later,
    # and no tendon is held past the limit longer than that (every run of cycles past it is short)
    relax_at = next((s[0] for s in states if s[0] >= t_cross and s[4] == SideState.SAFE), None)
    assert relax_at is not None and relax_at - t_cross <= SAFE_WITHIN
    assert peak[(t > relax_at) & (t <= relax_at + 0.01)].min() < LEFT_LIMIT
    edges = np.flatnonzero(np.diff(np.r_[0, over.astype(int), 0]))
    assert (edges[1::2] - edges[::2]).max() * DT <= SAFE_WITHIN
    assert_right_arm_untouched(masters, rows, states, rows0)


def test_lost_master_makes_both_arms_safe(tmp_path):
    _, _, _, states, _ = run(tmp_path, "peer")
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


def test_the_left_slave_trips_its_own_limit_in_the_cycle_its_tension_passes_it(tmp_path, baseline):
    """The left arm's slave.max_tension is LEFT_LIMIT (its master's limit the shipped 200 N): the slave goes SAFE
    in the very cycle its measured tension first passes it, the master still commanding; the left master goes
    SAFE on it and latches (its hand keeps its deadman pressed), so the tendon is not driven past it again."""
    bim, masters, rows, states, slave_rows = run(tmp_path, "slave_limit")
    t, peak = measured_tension(bim, slave_rows[0])
    cols = joint_csv_columns([j.name for j in bim.arms[0].cfg.instrument.joints], True)
    state = slave_rows[0][:, cols.index("state")]
    over = peak > LEFT_LIMIT
    k = int(np.argmax(over))
    assert over.any() and t[k] > T_FAULT and not over[:k].any()
    assert state[k] == int(SideState.SAFE) and state[k - 1] == int(SideState.ENGAGED)
    assert masters[0].counts["estimates_rejected_range"] == 0          # the master's own check never fired
    assert masters[0].tension_latched and masters[0].safe_events == 1 and masters[0].engage_count == 1
    # relaxing brings the tendon back below within a few cycles, and the latched master never drives it past again
    edges = np.flatnonzero(np.diff(np.r_[0, over.astype(int), 0]))
    assert len(edges) == 2 and (edges[1] - edges[0]) * DT <= 0.01
    assert_right_arm_untouched(masters, rows, states, rows0=baseline[2])
