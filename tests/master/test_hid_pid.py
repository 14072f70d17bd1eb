"""HID PID force feedback, byte for byte, with a fake hidapi handle that records every report."""
import math

import pytest

from master.hid_pid import PidConfig, PidForce, parse_pid
from master.hid_reports import Section
from teleop.errors import ConfigError, DeviceError


class RecordingHandle:
    """The hidapi ``hid.device`` calls PidForce makes; every report kept as (kind, bytes)."""

    def __init__(self, block_load=(0x12, 3, 1, 0, 0)):
        self.sent = []
        self.block_load = list(block_load)
        self.fail_writes = 0            # the next n writes return -1

    def _send(self, kind, data):
        if self.fail_writes:
            self.fail_writes -= 1
            return -1
        self.sent.append((kind, bytes(data)))
        return len(data)

    def write(self, data):
        return self._send("output", data)

    def send_feature_report(self, data):
        return self._send("feature", data)

    def get_feature_report(self, report_id, size):
        self.sent.append(("get_feature", bytes([report_id, size])))
        return self.block_load[:size]


def h(s):
    return bytes.fromhex(s)


START = [
    ("output", h("0c 04")),                                     # Device Control: Device Reset
    ("output", h("0c 01")),                                     # Device Control: Enable Actuators
    ("output", h("0d ff")),                                     # Device Gain 255
    ("feature", h("11 01 00 00")),                              # Create New Effect: constant force
    ("get_feature", h("12 05")),                                # PID Block Load (id 0x12, 5 bytes)
    # Set Effect: index 3, type 1, duration 0xFFFF, repeat 0, period 0, gain 255, button 0, axes X, dir 0
    ("output", h("01 03 01 ff ff 00 00 00 00 ff 00 01 00 00 00 00")),
    ("output", h("05 03 00 00")),                               # Set Constant Force: index 3, 0
    ("output", h("0a 03 01 01")),                               # Effect Operation: index 3, Start, 1
]


def started(cfg=None, limit=4.0, **kw):
    handle = RecordingHandle(**kw)
    pid = PidForce(cfg or PidConfig(max_force=8.0), handle, limit)
    pid.start()
    return pid, handle


def test_start_sends_the_pid_sequence_byte_for_byte():
    pid, handle = started()
    assert handle.sent == START
    assert pid.block_index == 3


@pytest.mark.parametrize("force, payload", [
    (2.0, "c4 09"),          # 2/8*10000 = 2500 = 0x09c4, little endian
    (-2.0, "3c f6"),         # -2500
    (0.0008, "01 00"),       # 1 count
    (100.0, "88 13"),        # clamp at +4 N -> 5000
    (-100.0, "78 ec"),       # -5000
    (math.nan, "00 00"), (math.inf, "00 00"), (-math.inf, "00 00"),
])
def test_set_constant_force_magnitude_scaled_clamped_and_nan_safe(force, payload):
    pid, handle = started()
    pid.write(force)
    assert handle.sent[-1] == ("output", h("05 03") + h(payload))


def test_invert_flips_the_sign():
    pid, handle = started(PidConfig(max_force=8.0, invert=True))
    pid.write(2.0)
    assert handle.sent[-1] == ("output", h("05 03 3c f6"))


def test_stop_sends_stop_all_then_disable():
    pid, handle = started()
    handle.sent.clear()
    pid.stop()
    assert handle.sent == [("output", h("0c 03")), ("output", h("0c 02"))]
    with pytest.raises(DeviceError, match="not started"):
        pid.write(1.0)


def test_stop_still_disables_when_stop_all_fails():
    pid, handle = started()
    handle.sent.clear()
    handle.fail_writes = 1
    with pytest.raises(DeviceError, match="device control"):
        pid.stop()
    assert handle.sent == [("output", h("0c 02"))]


@pytest.mark.parametrize("reply, match", [
    ((0x12, 0, 2, 0, 0), "pool full"),
    ((0x12, 0, 3, 0, 0), "status 3"),
    ((0x12, 3), "malformed"),
    ((0x13, 3, 1, 0, 0), "malformed"),
])
def test_refused_or_malformed_block_load_is_a_device_error(reply, match):
    with pytest.raises(DeviceError, match=match):
        started(block_load=reply)


def test_fixed_block_index_without_create_effect_and_no_gain_no_reset():
    pid, handle = started(PidConfig(max_force=8.0, create_effect=False, effect_block_index=2,
                                    device_gain=None, reset_on_start=False))
    assert [k for k, _ in handle.sent] == ["output"] * 4          # enable, set effect, force 0, start
    assert handle.sent[0] == ("output", h("0c 01"))
    assert handle.sent[1][1][:2] == h("01 02")
    assert handle.sent[-1] == ("output", h("0a 02 01 01"))


def cfg_from(data, source="dev.yaml"):
    return parse_pid(Section(data, source, "force.pid"))


def test_layout_from_yaml_changes_ids_offsets_types_and_endianness():
    cfg = cfg_from({
        "max_force": 5.0, "magnitude_max": 255,
        "values": {"duration_infinite": 0, "op_start": 2},
        "reports": {
            "set_constant_force": {"report_id": 0x15, "length": 6, "fields": {
                "block_index": {"byte_offset": 2, "type": "u8"},
                "magnitude": {"byte_offset": 3, "type": "i16", "endian": "big"}}},
            "set_effect": {"fields": {"trigger_repeat": None, "sample_period": None, "start_delay": None}},
            "effect_operation": {"report_id": 0x1A, "fields": {"loop_count": None}},
        }})
    pid, handle = started(cfg, limit=10.0)
    pid.write(-5.0)                                             # -255, big endian at byte 3
    assert handle.sent[-1] == ("output", h("15 00 03 ff 01 00"))
    assert handle.sent[-2] == ("output", h("1a 03 02 00"))      # Start Solo, loop count left out
    assert handle.sent[-4][1][3:5] == h("00 00")                # duration 0


@pytest.mark.parametrize("data, match", [
    ({}, r"dev\.yaml: force\.pid\.max_force: missing key"),
    ({"max_force": 0}, r"force\.pid\.max_force: expected a number > 0"),
    ({"max_force": 4, "gain": 3}, r"dev\.yaml: force\.pid\.gain: unknown key"),
    ({"max_force": 4, "reports": {"set_force": {}}}, r"force\.pid\.reports\.set_force: unknown report"),
    ({"max_force": 4, "reports": {"set_effect": {"idx": 1}}}, r"force\.pid\.reports\.set_effect\.idx: unknown key"),
    ({"max_force": 4, "reports": {"set_constant_force": {"fields": {"magnitude": None}}}},
     r"fields\.magnitude: this field is required"),
    ({"max_force": 4, "reports": {"set_constant_force": {"fields": {"magnitude": {"byte_offset": 0}}}}},
     r"byte 0 holds the report id"),
    ({"max_force": 4, "reports": {"set_constant_force": {"length": 3}}}, r"shorter than the fields"),
    ({"max_force": 4, "reports": {"device_control": {"kind": "input"}}}, r"expected one of output, feature"),
    ({"max_force": 4, "values": {"op_pause": 5}}, r"force\.pid\.values\.op_pause: unknown value"),
    ({"max_force": 4, "magnitude_max": 40000}, r"does not fit the magnitude field \(i16\)"),
    ({"max_force": 4, "create_effect": "yes"}, r"create_effect: expected true or false"),
    ({"max_force": 4, "reports": {"device_control": {"report_id": "0xZZ"}}}, r"report_id: expected an integer"),
])
def test_pid_config_errors_name_file_and_key(data, match):
    with pytest.raises(ConfigError, match=match):
        cfg_from(data)


def test_hex_strings_and_defaults_from_yaml():
    cfg = cfg_from({"max_force": 4, "reports": {"device_control": {"report_id": "0x2C"}}})
    assert cfg.reports["device_control"].report_id == 0x2C
    assert cfg.reports["set_effect"].report_id == 0x01 and cfg.reports["set_effect"].length == 16
    assert cfg == cfg_from({"max_force": 4, "reports": {"device_control": {"report_id": 44}}})
