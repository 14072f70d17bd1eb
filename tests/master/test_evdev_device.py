"""The evdev force-feedback device (master/evdev_device.py) through a fake of python-evdev: discovery, position and
buttons from events, force -> FF_CONSTANT level and direction, the replay hold, loss and close; and the master's
console and fault behaviour (engage, clamp, stale estimate, deadman, unplug) with the device in the loop."""
from __future__ import annotations

import math

import pytest

from master.device import HapticDevice
from master.evdev_device import LEVEL_MAX, EvdevConfig, EvdevDevice, parse_evdev
from master.node import MasterNode
from master.node_base import MasterLinks
from teleop.config.schema import Config, MappingConfig, MasterConfig
from teleop.errors import ConfigError, DeviceError
from teleop.timing.clock import FakeClock
from teleop.wire.messages import SideState
from tests.fakes import Topic
from tests.master.fake_evdev import FakeEvdev, FakeInput, ecodes
from tests.master.test_node import put_est, slave_beat, tick

EV_ABS, EV_KEY, EV_FF = ecodes.EV_ABS, ecodes.EV_KEY, ecodes.EV_FF
TRIGGER = ecodes.BTN_TRIGGER


def rig(cfg: EvdevConfig | None = None, **input_kw):
    kbd = FakeInput("/dev/input/event0", "keyboard", ff_codes=())
    joy = FakeInput("/dev/input/event7", "FF joystick", **input_kw)
    dev = EvdevDevice(cfg or EvdevConfig(presence_button="BTN_TRIGGER"), FakeEvdev(kbd, joy))
    return dev, joy


def test_opens_the_first_constant_force_device_with_autocenter_off_and_a_zero_effect():
    dev, joy = rig()
    assert isinstance(dev, HapticDevice) and dev.dev is joy
    assert joy.writes[:2] == [(EV_FF, ecodes.FF_AUTOCENTER, 0), (EV_FF, ecodes.FF_GAIN, 0xFFFF)]
    assert joy.uploads == [(3, 0, 0xC000, 200)] and dev.effect_id == 3


def test_position_buttons_and_deadman_from_events():
    dev, joy = rig(EvdevConfig(travel=0.04, presence_button="BTN_TRIGGER", buttons=("BTN_THUMB", "BTN_TRIGGER")))
    assert dev.read(0.0).operator_present is False            # deadman not pressed yet
    joy.push(EV_ABS, ecodes.ABS_X, 16000)
    joy.push(EV_ABS, ecodes.ABS_X, 32767)                      # the latest value counts
    joy.push(EV_KEY, TRIGGER, 1)
    s = dev.read(0.001)
    assert s.position == pytest.approx(0.04) and s.buttons == 0b10 and s.operator_present
    joy.push(EV_ABS, ecodes.ABS_X, -32767)
    joy.push(EV_KEY, ecodes.BTN_THUMB, 1)
    joy.push(EV_KEY, TRIGGER, 0)
    s = dev.read(0.002)
    assert s.position == pytest.approx(-0.04) and s.buttons == 0b01 and not s.operator_present


@pytest.mark.parametrize("force, level, direction", [(2.0, round(2 / 8 * LEVEL_MAX), 0xC000),
                                                     (-3.0, round(3 / 8 * LEVEL_MAX), 0x4000),
                                                     (50.0, round(4 / 8 * LEVEL_MAX), 0xC000),   # clamped to 4 N
                                                     (math.nan, 0, 0xC000)])
def test_force_sets_level_and_direction_of_the_constant_effect(force, level, direction):
    dev, joy = rig()
    dev.set_force(1.0, 0.0)
    dev.set_force(force, 0.001)
    assert joy.uploads[-1] == (3, level, direction, 200)
    assert dev.force == (0.0 if math.isnan(force) else max(-4.0, min(4.0, force)))


def test_unchanged_force_is_not_uploaded_again_and_the_effect_is_replayed_within_its_hold():
    dev, joy = rig()
    played = []
    for k in range(1001):                                     # 1 s at 1 kHz, hold 200 ms
        n = len(joy.writes)
        dev.set_force(1.0, 1e-3 * k)
        played += [k] * (joy.writes[n:] == [(EV_FF, 3, 1)])
    assert len(joy.uploads) == 2                              # the zero at start, then 1 N once
    gaps = [b - a for a, b in zip(played, played[1:] + [1000], strict=False)]
    assert played[0] == 0 and max(gaps) <= 101 and min(gaps[:-1]) >= 100    # replayed every hold / 2 [ms]


def test_unplugged_read_loses_the_device_stops_the_force_and_close_runs_once():
    dev, joy = rig()
    joy.push(EV_KEY, TRIGGER, 1)
    dev.read(0.0)
    dev.set_force(2.0, 0.0)
    joy.unplugged = True
    with pytest.raises(DeviceError, match="device lost: read failed"):
        dev.read(0.001)
    assert dev.lost and dev.force == 0.0 and not dev.state(0.002).operator_present
    with pytest.raises(DeviceError, match="was lost"):
        dev.read(0.002)
    dev.set_force(3.0, 0.002)                                 # no-op
    n = joy.closes
    dev.close()
    dev.close()
    assert joy.closes == n + 1


def test_close_zeroes_stops_and_erases_the_effect_then_releases_once():
    dev, joy = rig()
    dev.set_force(-2.0, 0.0)
    n = joy.closes
    with dev:
        pass
    dev.close()
    assert joy.uploads[-1][:2] == (3, 0) and joy.writes[-1] == (EV_FF, 3, 0) and joy.erased == [3]
    assert joy.closes == n + 1
    with pytest.raises(DeviceError, match="closed"):
        dev.read(0.1)


def test_no_device_no_constant_force_or_no_axis_is_one_clear_error():
    with pytest.raises(DeviceError, match="no force-feedback device for any event device: none found"):
        EvdevDevice(EvdevConfig(), FakeEvdev())
    rumble = FakeInput("/dev/input/event3", "gamepad", ff_codes=(ecodes.FF_RUMBLE,))
    with pytest.raises(DeviceError, match="no FF_CONSTANT effect"):
        EvdevDevice(EvdevConfig(match_name="game"), FakeEvdev(rumble))
    with pytest.raises(DeviceError, match="no axis ABS_RZ"):
        EvdevDevice(EvdevConfig(position_axis="ABS_RZ"), FakeEvdev(FakeInput("/dev/input/event7", "wheel")))
    with pytest.raises(ConfigError, match="'ABS_Q' is not an evdev code name"):
        EvdevDevice(EvdevConfig(position_axis="ABS_Q"), FakeEvdev(FakeInput("/dev/input/event7", "wheel")))
    joy = FakeInput("/dev/input/event7", "wheel")
    joy.refuse_upload = True
    with pytest.raises(DeviceError, match="effect was refused"):
        EvdevDevice(EvdevConfig(), FakeEvdev(joy))
    assert joy.closes == 2                                    # listed, then opened and released


@pytest.mark.parametrize("data, match", [({"force": {"limit": -1}}, "force.limit"),
                                         ({"force": {"direction": 70000}}, "force.direction"),
                                         ({"input": {"buttons": "BTN_A"}}, "input.buttons"),
                                         ({"input": {"axis": "x"}}, "unknown key.*input.axis"),
                                         ({"force": {"gain": 2}}, "force.gain")])
def test_device_file_errors_name_the_key(data, match):
    with pytest.raises(ConfigError, match=match):
        parse_evdev(data, "dev.yaml")


# ---- the master's console and faults with the evdev device in the loop ---------------------------------

def master(dev: EvdevDevice, watchdog_ms: float = 50.0):
    m = dict(motion_scale=0.5, force_scale=0.2, force_limit=4.0, ramp_time=0.0, force_rate_limit=1e6)
    cfg = Config(master=MasterConfig(watchdog_ms=watchdog_ms, mapping=MappingConfig(**m)))
    clock = FakeClock(100.0)
    links = MasterLinks(*(Topic(clock) for _ in range(4)))
    return MasterNode(cfg, dev, links, stop_linger=0.01), links, clock


def engaged_rig():
    dev, joy = rig(EvdevConfig(presence_button="BTN_TRIGGER", buttons=()))
    node, links, clock = master(dev)
    joy.push(EV_KEY, TRIGGER, 1)                              # deadman held
    tick(node, clock)
    slave_beat(links, clock)
    put_est(links, 1)
    tick(node, clock)
    assert node.state == SideState.ENGAGED
    return node, links, clock, joy


def test_master_engages_and_renders_minus_scale_times_the_estimate_through_the_effect():
    node, links, clock, joy = engaged_rig()
    joy.push(EV_ABS, ecodes.ABS_X, 3277)                       # +10 % of the travel
    put_est(links, 2, T_out=10.0)
    tick(node, clock)
    assert links.command.sent[-1].targets[0] == pytest.approx(0.004 + 0.5 * 0.0035, rel=1e-3)
    assert joy.uploads[-1][1:3] == (round(2.0 / 8.0 * LEVEL_MAX), 0x4000)    # -2 N: the opposite direction
    put_est(links, 3, T_out=100.0)                            # -20 N asked: the 4 N clamp holds
    tick(node, clock)
    assert joy.uploads[-1][1:3] == (round(4.0 / 8.0 * LEVEL_MAX), 0x4000)


def test_stale_estimate_and_released_deadman_render_zero():
    node, links, clock, joy = engaged_rig()
    put_est(links, 2, T_out=10.0)
    tick(node, clock)
    assert joy.uploads[-1][1] > 0
    for k in range(60):                                       # estimates stop: the watchdog trips at 50 ms
        if k % 10 == 0:
            slave_beat(links, clock)
        tick(node, clock)
    assert node.state == SideState.SAFE and joy.uploads[-1][1] == 0
    node, links, clock, joy = engaged_rig()
    put_est(links, 2, T_out=10.0)
    tick(node, clock)
    joy.push(EV_KEY, TRIGGER, 0)                              # the operator lets go
    put_est(links, 3, T_out=10.0)
    tick(node, clock)
    assert node.state != SideState.ENGAGED and joy.uploads[-1][1] == 0


def test_unplugged_mid_run_stops_the_master_step_with_zero_force():
    node, links, clock, joy = engaged_rig()
    put_est(links, 2, T_out=10.0)
    tick(node, clock)
    joy.unplugged = True
    with pytest.raises(DeviceError, match="device lost"):
        tick(node, clock)
    assert node.device.force == 0.0 and not node.device.state(clock.now()).operator_present


def test_the_shipped_device_file_loads_and_drives_the_fake():
    from pathlib import Path

    from master.evdev_device import load_evdev_file
    cfg = load_evdev_file(Path(__file__).resolve().parents[2] / "configs" / "devices" / "evdev_joystick.yaml")
    assert cfg.presence_button == "BTN_TRIGGER" and cfg.direction == 0xC000 and cfg.max_force == 8.0
    dev = EvdevDevice(cfg, FakeEvdev(FakeInput("/dev/input/event7", "stick")))
    dev.set_force(-8.0, 0.0)
    assert dev.dev.uploads[-1] == (3, round(4 / 8 * LEVEL_MAX), 0x4000, 200)


def test_the_effect_is_built_with_python_evdev_s_own_structures_when_installed():
    evdev = pytest.importorskip("evdev")                     # the extra; the fake stands in for it elsewhere
    from types import SimpleNamespace
    fake = FakeEvdev(FakeInput("/dev/input/event7", "stick"))
    ev = SimpleNamespace(list_devices=fake.list_devices, InputDevice=fake.InputDevice, ecodes=evdev.ecodes,
                         ff=evdev.ff)
    dev = EvdevDevice(EvdevConfig(), ev)
    dev.set_force(-2.0, 0.0)
    assert dev.dev.uploads[-1] == (3, round(2 / 8 * LEVEL_MAX), 0x4000, 200)
    assert dev.dev.writes[-1] == (evdev.ecodes.EV_FF, 3, 1)
