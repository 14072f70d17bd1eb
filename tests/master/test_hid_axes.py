"""A HID device with several position axes: one per joint of an instrument, one force report map per
axis; through the device registry and the one MasterNode (fake hidapi handle)."""
from __future__ import annotations

import dataclasses
import struct
from pathlib import Path

import pytest
import yaml

from master.device import MultiAxisState
from master.devices import device_axes_needed, make_device
from master.hid import HidDevice, load_device_file, parse_device
from master.node import MasterNode
from master.node_base import MasterLinks
from teleop.config.load import load_config
from teleop.errors import ConfigError, DeviceError
from teleop.timing.clock import FakeClock
from teleop.wire.messages import Heartbeat, Side, SideState
from tests.fakes import Topic
from tests.master.test_hid import FakeHandle
from tests.master.test_node_axes import ANGLES, TORQUES, estimate

ROOT = Path(__file__).resolve().parents[2]
THREE = ROOT / "configs" / "devices" / "vendor_3axis_example.yaml"


def report(x_um, y_um, z_um, status=0x00):
    return struct.pack("<Biiib", 2, x_um, y_um, z_um, status) + bytes(2)


def test_three_axes_read_as_one_multi_axis_state_and_force_goes_out_per_axis():
    fake = FakeHandle()
    dev = HidDevice(load_device_file(THREE), lambda: fake)
    assert dev.n_axes == 3 and [d[1][:1] for d in fake.sent] == [b"\x03"] * 3      # zero force on every axis
    fake.inbox.append(report(1000, -2000, 3000))
    st = dev.read(0.0)
    assert isinstance(st, MultiAxisState) and st.positions == pytest.approx((1e-3, -2e-3, 3e-3))
    assert st.operator_present                                 # status bit 0x80 low: touched (active low)
    fake.sent.clear()
    dev.set_forces([1.5, -0.25, 9.0], 0.001)
    assert [struct.unpack_from("<hB", d[1], 1) for d in fake.sent] == [(1500, 0), (-250, 1), (3000, 2)]
    assert dev.forces == [1.5, -0.25, 3.0]                     # clamped to force.limit 3 N
    dev.close()
    assert [struct.unpack_from("<h", d[1], 1)[0] for d in fake.sent[-3:]] == [0, 0, 0]


def test_device_files_with_several_axes_are_checked():
    data = yaml.safe_load(THREE.read_text())
    bad = dict(data, force=dict(data["force"], report=data["force"]["report"][:2]))
    with pytest.raises(ConfigError, match="one report map per position axis"):
        parse_device(bad, "three.yaml")
    pid = dict(data, force={"limit": 3.0, "backend": "pid", "pid": {}})
    with pytest.raises(ConfigError, match="PID backend drives one axis"):
        parse_device(pid, "three.yaml")
    wrong = dict(data, input=dict(data["input"], position_axes=["x", "w"]))
    with pytest.raises(ConfigError, match="position_axes"):
        parse_device(wrong, "three.yaml")


def test_the_registry_matches_device_axes_to_the_instrument():
    joints = load_config(ROOT / "configs" / "instrument-3dof.yaml",
                         {"master.device.type": "hid", "master.device.file": str(ROOT / "configs" / "devices" /
                                                                               "vendor_report_example.yaml")})
    assert device_axes_needed(joints) == 3 and device_axes_needed(load_config()) == 1
    with pytest.raises(DeviceError, match="1 position axis.*needs 3"):
        make_device(joints)


def test_the_master_node_drives_a_three_axis_hid_device():
    cfg = load_config(ROOT / "configs" / "instrument-3dof.yaml",
                      {"master.mapping.ramp_time": 0.0, "master.mapping.force_rate_limit": 1e6,
                       "safety.override": ["master.mapping.force_rate_limit"]})
    fake = FakeHandle()
    dev = HidDevice(load_device_file(THREE), lambda: fake)
    clock = FakeClock(1.0)
    links = MasterLinks(*(Topic(clock) for _ in range(4)))
    node = MasterNode(cfg, dev, links)
    for k in range(5):
        fake.inbox.append(report(100 * k, 0, 0))
        links.slave_heartbeat.put(Heartbeat(Side.SLAVE, 0, clock.now(), SideState.READY))
        links.estimate.put(estimate(k + 1, links.command.sent[-1].seq if links.command.sent else 0))
        clock.advance(1e-3)
        node.step(clock.now())
    assert node.state == SideState.ENGAGED
    r = [j.pulley_radius for j in cfg.instrument.joints]
    m = cfg.master.mapping
    want = [max(-3.0, min(3.0, -m.force_scale * tq / rk)) for tq, rk in zip(TORQUES, r, strict=False)]
    assert dev.forces[1:] == pytest.approx(want[1:]) and links.command.sent[-1].targets[1:] == pytest.approx(ANGLES[1:])


def test_the_registry_names_a_missing_device_file_of_a_config_built_in_code():
    cfg = load_config()
    device = dataclasses.replace(cfg.master.device, type="hid", file=None)   # load_config would refuse this
    cfg = dataclasses.replace(cfg, master=dataclasses.replace(cfg.master, device=device))
    with pytest.raises(ConfigError, match=r"master\.device\.file: a device file .* required"):
        make_device(cfg)
