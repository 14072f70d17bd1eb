"""The ``zenoh`` rig and ``teleop bridge`` in one process, over an in-memory session that goes through
the rig byte format; the rig and device registries."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from live.bridge import RigBridge
from master.devices import DEVICE_TYPES, make_device
from master.simulated import ScriptedOperator
from slave.pair_rig import SimulatedInstrument
from slave.rig import RigInputError
from slave.rigs import RIG_TYPES, make_rig
from slave.simulated import SimulatedRig
from slave.zenoh_rig import ZenohInstrument, ZenohRig
from teleop.config.load import load_config
from teleop.errors import ConfigError, DeviceError, TransportError
from teleop.session.transport import Received
from teleop.timing.clock import FakeClock
from teleop.wire.keys import rig_key
from teleop.wire.rig import decode_rig, encode_rig

JOINTS = Path(__file__).resolve().parents[2] / "configs" / "instrument-3dof.yaml"
DT = 1e-3


class Wire:
    """One key: what is put is encoded, decoded and kept as the latest (receive time = the fake clock)."""

    def __init__(self, clock):
        self.clock, self.last, self.count, self.cut = clock, None, 0, False

    def latest(self):
        return self.last

    def age(self, now):
        return math.inf if self.last is None else now - self.last.t_recv

    def wait(self, count=1, timeout=None):
        return self.count >= count

    def close(self):
        pass


class Pub:
    def __init__(self, wire, encoder, decoder):
        self.wire, self.encoder, self.decoder = wire, encoder, decoder

    def put(self, msg):
        if not self.wire.cut:
            self.wire.last = Received(self.decoder(self.encoder(msg)), self.wire.clock.now())
            self.wire.count += 1

    def close(self):
        pass


class FakeSession:
    def __init__(self, clock):
        self.clock, self.wires = clock, {}

    def _wire(self, key):
        return self.wires.setdefault(key, Wire(self.clock))

    def publisher(self, key, *, encoder):
        return Pub(self._wire(key), encoder, decode_rig)

    def subscriber(self, key, expect=None, *, decoder):
        return self._wire(key)


def build(**overrides):
    cfg = load_config(None, {"instrument.id": "zr", "rig.type": "zenoh", "rig.simulated.n_elements": 50,
                             "rig.simulated.sensors.load_cell_noise": 0.0, **overrides})
    clock = FakeClock(5.0)
    session = FakeSession(clock)
    sim = SimulatedRig.from_config(cfg)
    bridge = RigBridge(sim, session._wire(rig_key("zr", "setpoint")),
                       Pub(session._wire(rig_key("zr", "sample")), encode_rig, decode_rig),
                       cfg.rig.rate_hz, cfg.rig.zenoh.timeout_ms * 1e-3)
    return cfg, clock, session, sim, bridge


def cycle(clock, rig, bridge, cmd):
    clock.advance(DT)
    st = rig.step(cmd, DT)
    bridge.step(clock.now())
    return st


def test_the_slave_sees_the_simulated_rig_through_the_interface_one_cycle_behind():
    cfg, clock, session, sim, bridge = build()
    with pytest.raises(TransportError, match="no sample on teleop/zr/rig/sample"):
        ZenohRig(session, cfg)                              # nothing serves the rig yet
    bridge.step(clock.now())                                # the bridge publishes its first sample
    rig = make_rig(cfg, session)
    assert isinstance(rig, ZenohRig) and rig.state.truth is not None
    cmds = 0.004 * np.sin(np.linspace(0.0, 3.0, 400)) ** 2
    prev = None
    for c in cmds:
        st = cycle(clock, rig, bridge, c)
        if prev is not None:                                # the sample read is the bridge's previous one
            assert st.x_in_cmd == pytest.approx(prev.x_in_cmd) and st.T_in == prev.T_in
            assert st.truth.T_out == prev.truth.T_out and st.truth.elongation == prev.truth.elongation
        prev = sim.state
    assert np.ptp(cmds) > 0.003 and sim.state.x_in_cmd == pytest.approx(cmds[-1])
    # the first step reads the sample seen at start
    assert bridge.followed == len(cmds) and rig.stale == 0 and rig.repeats == 1
    rig.set_load(tissue=False)                              # forwarded with the next set-point
    cycle(clock, rig, bridge, cmds[-1])
    assert sim.tissue is False
    with pytest.raises(RigInputError, match="finite"):
        rig.step(math.nan, DT)
    with pytest.raises(RigInputError, match="distal set force"):
        rig.set_load(force=1.0)


def test_stale_set_points_hold_the_motor_and_stale_samples_are_counted():
    cfg, clock, session, sim, bridge = build()
    bridge.step(clock.now())
    rig = ZenohRig(session, cfg)
    for _ in range(100):
        cycle(clock, rig, bridge, 0.003)
    session.wires[rig_key("zr", "setpoint")].cut = True     # the slave's set-points stop arriving
    x = sim.state.truth.x_in
    for _ in range(100):
        clock.advance(DT)
        bridge.step(clock.now())
    assert bridge.held > 40 and abs(sim.state.truth.x_in - x) < 1e-4     # held (after the 50 ms timeout)
    session.wires[rig_key("zr", "sample")].cut = True       # and the samples stop
    times, faults = [], []
    for _ in range(60):
        clock.advance(DT)
        st = rig.step(0.003, DT)
        times.append(st.t)
        faults.append(st.fault)
    assert rig.stale > 0 and rig.repeats >= 60 and np.all(np.diff(times) > 0)     # time still increases
    # a sample past rig.zenoh.timeout_ms is flagged: the slave goes SAFE on it (tests/slave/test_sensor_fault.py)
    flagged = [f for f in faults if f is not None]
    assert len(flagged) == rig.stale and "rig.zenoh.timeout_ms 50" in flagged[-1] and faults[0] is None


def test_registries_choose_by_type_only():
    assert {"simulated", "zenoh"} <= set(RIG_TYPES) and {"simulated", "hid"} <= set(DEVICE_TYPES)
    one, joints = load_config(), load_config(JOINTS)
    assert isinstance(make_rig(one), SimulatedRig) and isinstance(make_rig(joints), SimulatedInstrument)
    assert isinstance(make_device(one, "paper"), ScriptedOperator)
    op = make_device(joints, "paper")
    assert isinstance(op, ScriptedOperator) and op.n_axes == 3
    with pytest.raises(ConfigError, match="session"):
        make_rig(load_config(None, {"rig.type": "zenoh"}))
    with pytest.raises(ConfigError, match="session"):
        make_rig(load_config(JOINTS, {"rig.type": "zenoh"}))
    one_axis = str(JOINTS.parent / "devices" / "vendor_report_example.yaml")
    with pytest.raises(DeviceError, match="needs 3"):        # a one-axis HID device for three joints
        make_device(load_config(JOINTS, {"master.device.type": "hid", "master.device.file": one_axis}))
    with pytest.raises(ConfigError, match="protocol"):
        make_device(joints, "minor")


def test_a_joint_instrument_through_the_interface():
    cfg = load_config(JOINTS, {"instrument.id": "zj", "rig.type": "zenoh", "rig.simulated.n_elements": 30,
                               "rig.simulated.sensors.load_cell_noise": 0.0})
    clock = FakeClock(1.0)
    session = FakeSession(clock)
    sim = SimulatedInstrument.from_config(cfg)
    bridge = RigBridge(sim, session._wire(rig_key("zj", "setpoint")),
                       Pub(session._wire(rig_key("zj", "sample")), encode_rig, decode_rig),
                       cfg.rig.rate_hz, cfg.rig.zenoh.timeout_ms * 1e-3)
    bridge.step(clock.now())
    inst = make_rig(cfg, session)
    assert isinstance(inst, ZenohInstrument) and inst.joint_names == ("bend_ud", "bend_lr", "grasp")
    x0 = inst.state.x_in_cmd.copy()
    pull = np.array([[1.0, -0.5]] * 3) * 1e-3               # tendon a drawn, b let out: every joint turns +
    prev = None
    for k in range(300):
        st = cycle(clock, inst, bridge, x0 + pull * min(1.0, k / 100))
        if prev is not None:                                # one cycle behind the bridge's instrument
            assert np.array_equal(st.T_in, prev.T_in) and np.array_equal(st.x_in_cmd, prev.x_in_cmd)
            assert np.allclose(st.truth.theta, prev.truth.theta) and np.allclose(st.truth.torque, prev.truth.torque)
        prev = sim.state
    assert st.x_in.shape == (3, 2) and np.all(st.truth.theta > 0.02)
    inst.set_load(tissue=False)
    cycle(clock, inst, bridge, x0 + pull)
    assert sim.tissue == (False, False, False)
    with pytest.raises(RigInputError, match="shape"):
        inst.step(np.zeros((2, 2)), DT)
