"""The hidapi driver with a fake handle (opened by ids or path, the latest valid report, the force stopped on loss
and close), its device files, and `teleop devices`."""
import errno
import io
import math
import os
import struct
from argparse import ArgumentParser
from collections import deque
from pathlib import Path

import pytest

from master.device import DeviceState, HapticDevice
from master.devices_list import NONE_FOUND, add_arguments, format_devices, list_devices, main_devices, probe_open
from master.hid import HidDevice, load_device_file, parse_device
from teleop.errors import ConfigError, DeviceError
from tests.master.test_hid_reports import h

DEVICES = Path(__file__).resolve().parents[2] / "configs" / "devices"


# ---- the driver -------------------------------------------------------------------------------------

class FakeHandle:
    """hidapi ``hid.device`` stand-in: scripted input reports, every report sent recorded."""

    def __init__(self, block_load=(0x12, 1, 1, 0, 0)):
        self.inbox = deque()
        self.sent = []
        self.block_load = list(block_load)
        self.opened = None
        self.nonblocking = None
        self.closes = 0
        self.unplugged = False
        self.read_exc = None

    def open(self, vendor_id=0, product_id=0, serial_number=None):
        if self.unplugged:
            raise OSError("open failed")
        self.opened = ("ids", vendor_id, product_id, serial_number)

    def open_path(self, path):
        self.opened = ("path", path)

    def set_nonblocking(self, v):
        self.nonblocking = v
        return 0

    def read(self, max_length, timeout_ms=0):
        if self.read_exc is not None:
            raise self.read_exc
        if self.unplugged:
            raise OSError("read error")
        return list(self.inbox.popleft()[:max_length]) if self.inbox else []

    def _send(self, kind, data):
        if self.unplugged:
            return -1
        self.sent.append((kind, bytes(data)))
        return len(data)

    def write(self, data):
        return self._send("output", data)

    def send_feature_report(self, data):
        return self._send("feature", data)

    def get_feature_report(self, report_id, max_length):
        return self.block_load[:max_length]

    def close(self):
        self.closes += 1


def pid_device(**kw):
    handle = FakeHandle(**kw)
    dev = HidDevice(load_device_file(DEVICES / "generic_pid_joystick.yaml"), lambda: handle)
    return dev, handle


def vendor_device():
    handle = FakeHandle()
    dev = HidDevice(load_device_file(DEVICES / "vendor_report_example.yaml"), lambda: handle)
    return dev, handle


def joy(x_counts, buttons):
    return bytes([1]) + struct.pack("<h", x_counts) + bytes([buttons])


def test_pid_device_opens_by_ids_nonblocking_and_starts_the_effect():
    dev, handle = pid_device()
    assert isinstance(dev, HapticDevice)
    assert handle.opened == ("ids", 0x1209, 0x0001, None) and handle.nonblocking == 1
    assert handle.sent[-1] == ("output", h("0a 01 01 01"))        # Effect Operation: Start


def test_read_drains_to_the_latest_valid_report_and_counts_bad_ones():
    dev, handle = pid_device()
    handle.inbox.extend([joy(100, 0x01), h("01 00"), joy(-200, 0x03), h("07 00 00 00"), joy(3000, 0x09)])
    s = dev.read(0.0)
    assert s == DeviceState(0.0, pytest.approx(3000 * 1.0653e-6), 0b1001, True)
    assert not handle.inbox
    assert dev.input.accepted == 3 and dev.input.rejected == {"short": 1, "wrong_id": 1, "non_finite": 0}
    s = dev.read(0.05)                                              # nothing new: last state, new time
    assert s.t == 0.05 and s.buttons == 0b1001 and s.operator_present


def test_no_report_yet_means_operator_not_present():
    dev, _ = pid_device()
    assert dev.read(0.0) == DeviceState(0.0, 0.0, 0, False)


def test_set_force_saturates_and_zeroes_nan():
    dev, handle = vendor_device()
    dev.set_force(10.0, 0.0)
    assert handle.sent[-1] == ("output", h("03 46 b8 0b 00 00 00 00"))   # +3000 mN, limit 3 N
    assert dev.force == 3.0
    dev.set_force(math.nan, 0.001)
    assert handle.sent[-1] == ("output", h("03 46 00 00 00 00 00 00")) and dev.force == 0.0


def assert_stopped(handle, since):
    """Zero force, then Stop All Effects, then Disable Actuators, each exactly once."""
    assert handle.sent[since:] == [("output", h("05 01 00 00")), ("output", h("0c 03")), ("output", h("0c 02"))]


@pytest.mark.parametrize("fault", ["oserror", "valueerror", "minus_one"])
def test_unplugged_mid_run_raises_stops_force_and_operator_not_present(fault):
    dev, handle = pid_device()
    handle.inbox.append(joy(100, 0x01))
    assert dev.read(0.0).operator_present
    dev.set_force(2.0, 0.0)
    n = len(handle.sent)
    if fault == "minus_one":
        real_send = handle._send
        handle._send = lambda kind, data: -1 if data[0] == 0x05 and data[2:] != b"\0\0" else real_send(kind, data)
        with pytest.raises(DeviceError, match="lost: .*not sent"):
            dev.set_force(1.0, 0.001)
    else:
        handle.read_exc = OSError("read error") if fault == "oserror" else ValueError("not open")
        with pytest.raises(DeviceError, match="lost: read failed"):
            dev.read(0.001)
    assert dev.lost and dev.force == 0.0
    assert dev.state(0.002).operator_present is False
    assert_stopped(handle, n)
    with pytest.raises(DeviceError, match="was lost"):
        dev.read(0.002)
    dev.set_force(1.0, 0.002)                                       # no-op: nothing sent, no raise
    assert dev.force == 0.0
    dev.close()
    assert_stopped(handle, n)                                       # nothing more sent on close
    assert handle.closes == 1


def test_silence_longer_than_lost_after_is_a_lost_device():
    dev, handle = pid_device()                                      # lost_after_ms: 100
    handle.inbox.append(joy(0, 0x01))
    dev.read(10.0)
    assert dev.read(10.1).operator_present                          # exactly the limit: still fine
    n = len(handle.sent)
    with pytest.raises(DeviceError, match=r"no valid input report for 0\.101 s"):
        dev.read(10.101)
    assert_stopped(handle, n)
    assert not dev.state(10.2).operator_present


def test_only_malformed_reports_also_count_as_silence():
    dev, handle = pid_device()
    dev.read(0.0)
    handle.inbox.extend([h("02 00 00 00")] * 5)
    with pytest.raises(DeviceError, match="no valid input report"):
        dev.read(0.2)
    assert dev.input.rejected["wrong_id"] == 5


def test_close_twice_sends_zero_then_stop_all_then_disable_once():
    dev, handle = pid_device()
    dev.set_force(3.0, 0.0)
    n = len(handle.sent)
    dev.close()
    dev.close()
    assert_stopped(handle, n)
    assert handle.closes == 1 and dev.closed
    dev.set_force(1.0, 0.1)                                         # no-op after close
    assert len(handle.sent) == n + 3
    with pytest.raises(DeviceError, match="closed"):
        dev.read(0.1)


def test_with_block_closes_on_exception_exactly_once():
    dev, handle = pid_device()
    with pytest.raises(RuntimeError, match="boom"):
        with dev:
            dev.set_force(-3.0, 0.0)
            n = len(handle.sent)
            raise RuntimeError("boom")
    dev.close()
    assert_stopped(handle, n)
    assert handle.closes == 1


def test_open_failure_names_the_device_and_the_probe_command():
    handle = FakeHandle()
    handle.unplugged = True
    with pytest.raises(DeviceError, match=r"generic PID joystick \(1209:0001\): open failed; .*--probe"):
        HidDevice(load_device_file(DEVICES / "generic_pid_joystick.yaml"), lambda: handle)


def test_refused_effect_at_start_disables_and_closes_before_raising():
    with pytest.raises(DeviceError, match="pool full"):
        pid_device(block_load=(0x12, 0, 2, 0, 0))
    handle = FakeHandle(block_load=(0x12, 0, 2, 0, 0))
    with pytest.raises(DeviceError):
        HidDevice(load_device_file(DEVICES / "generic_pid_joystick.yaml"), lambda: handle)
    assert handle.sent[-2:] == [("output", h("0c 03")), ("output", h("0c 02"))] and handle.closes == 1


def test_open_by_path():
    cfg = load_device_file(DEVICES / "vendor_report_example.yaml")
    data = {"match": {"path": "/dev/hidraw9"}, "input": {"axes": {"x": {"byte_offset": 0}}},
            "force": {"limit": 1.0, "backend": "report", "report": {"field": {"byte_offset": 1}}}}
    handle = FakeHandle()
    with HidDevice(parse_device(data, "p.yaml"), lambda: handle) as dev:
        assert handle.opened == ("path", b"/dev/hidraw9") and dev.cfg.name == "/dev/hidraw9"
    assert cfg.input.report_id == 2


# ---- device files -----------------------------------------------------------------------------------

def good():
    return {"match": {"vendor_id": "0x1209", "product_id": 1},
            "input": {"report_id": 1, "axes": {"x": {"byte_offset": 1, "type": "i16"}}},
            "force": {"limit": 2.0, "backend": "report", "report": {"field": {"byte_offset": 1, "type": "i16"}}}}


def with_(path, value):
    d = good()
    *parents, last = path.split(".")
    node = d
    for p in parents:
        node = node[p]
    node[last] = value
    return d


@pytest.mark.parametrize("data, match", [
    (with_("colour", "red"), r"dev\.yaml: colour: unknown key"),
    (with_("input.axes.x.bits", 3), r"dev\.yaml: input\.axes\.x\.bits: unknown key"),
    (with_("input.axes.x.type", "u24"), r"input\.axes\.x\.type: expected one of u8, i8"),
    (with_("input.axes.x.endian", "middle"), r"input\.axes\.x\.endian: expected one of little, big"),
    (with_("input.axes.x.scale", 0), r"input\.axes\.x\.scale: scale must not be 0"),
    (with_("input.axes.x.byte_offset", -1), r"input\.axes\.x\.byte_offset: -1 is out of range"),
    (with_("input.axes", {}), r"input\.axes: expected at least one axis"),
    (with_("input.position_axis", "y"), r"input\.position_axis: 'y' is not one of the axes"),
    (with_("input.read_size", 2), r"input\.read_size: fields reach byte 3"),
    (with_("input.lost_after_ms", 0), r"input\.lost_after_ms: expected a number > 0"),
    (with_("input.buttons", {"byte_offset": 1}), r"input\.buttons\.masks: missing key"),
    (with_("match", {"vendor_id": "0x1209"}), r"dev\.yaml: match: give path, or both"),
    (with_("match.vendor_id", "0x12345"), r"match\.vendor_id: 74565 is out of range"),
    (with_("force.backend", "ffb"), r"force\.backend: expected one of pid, report"),
    (with_("force.limit", -1), r"force\.limit: expected a number > 0"),
    (with_("force.report.raw_max", 40000), r"force\.report\.raw_max: 40000 is outside the i16 range"),
    (with_("force.report.field.byte_offset", 0), r"force\.report\.field\.byte_offset: byte 0 holds"),
    (with_("force.report.length", 2), r"force\.report\.length: 2 is shorter"),
    (with_("force.pid", {"max_force": 3}), r"force\.pid: unknown key"),
    ([1, 2], r"dev\.yaml: top level: expected a mapping"),
])
def test_device_file_errors_name_file_and_key(data, match):
    with pytest.raises(ConfigError, match=match):
        parse_device(data, "dev.yaml")


def test_device_file_read_errors(tmp_path):
    with pytest.raises(ConfigError, match="nope.yaml: config file not found"):
        load_device_file(tmp_path / "nope.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("match: {vendor_id: 1\ninput: [\n")
    with pytest.raises(ConfigError, match=r"bad\.yaml:\d+:\d+: YAML syntax error"):
        load_device_file(bad)


@pytest.mark.parametrize("name", ["generic_pid_joystick.yaml", "vendor_report_example.yaml"])
def test_shipped_device_files_load(name):
    cfg = load_device_file(DEVICES / name)
    assert cfg.force_limit > 0 and cfg.input.length <= cfg.input.read_size


# ---- teleop devices ---------------------------------------------------------------------------------

ENTRY = {"path": b"/dev/hidraw3", "vendor_id": 0x1209, "product_id": 0x0001, "serial_number": "S1",
         "release_number": 0x100, "manufacturer_string": "Acme", "product_string": "FFB Stick",
         "usage_page": 0x01, "usage": 0x04, "interface_number": 0}


def test_listing_none_found_is_one_line_and_exit_0():
    assert format_devices(list_devices(lambda vid, pid: [])) == NONE_FOUND == "no HID devices found"
    out = io.StringIO()
    args = ArgumentParser()
    add_arguments(args)
    assert main_devices(args.parse_args(["--backend", "hid"]), enumerate_fn=lambda vid, pid: [], out=out) == 0
    assert out.getvalue() == "no HID devices found\n"


def test_listing_found_is_a_table_with_ids_usage_strings_and_path():
    other = dict(ENTRY, path=b"/dev/hidraw1", vendor_id=0x046D, product_id=0xC215, manufacturer_string="",
                 product_string="Extreme 3D", usage_page=0xFF00, usage=0x01)
    text = format_devices(list_devices(lambda vid, pid: [ENTRY, other]))
    lines = text.splitlines()
    assert len(lines) == 3 and lines[0].split() == ["VID:PID", "usage", "manufacturer", "product", "path"]
    assert lines[1].split() == ["046d:c215", "ff00:0001", "-", "Extreme", "3D", "/dev/hidraw1"]
    assert lines[2].split() == ["1209:0001", "0001:0004", "Acme", "FFB", "Stick", "/dev/hidraw3"]


def test_listing_passes_the_filter_and_wraps_enumeration_errors():
    seen = []
    list_devices(lambda vid, pid: seen.append((vid, pid)) or [], 0x1209, 0x0001)
    assert seen == [(0x1209, 0x0001)]

    def broken(vid, pid):
        raise OSError("hid_init failed")
    with pytest.raises(DeviceError, match="HID enumeration failed: hid_init failed"):
        list_devices(broken)


class DeniedHandle(FakeHandle):
    def __init__(self, exc):
        super().__init__()
        self.exc = exc

    def open_path(self, path):
        raise self.exc


@pytest.mark.parametrize("exc, access", [
    (OSError("open failed"), lambda p, mode: mode == os.F_OK),     # hidapi's bare message; node not rw
    (PermissionError(errno.EACCES, "Permission denied"), lambda p, mode: True),
])
def test_probe_permission_denied_names_the_udev_rule(exc, access):
    with pytest.raises(DeviceError) as e:
        probe_open("/dev/hidraw3", device_factory=lambda: DeniedHandle(exc),
                   enumerate_fn=lambda vid, pid: [ENTRY], access_fn=access)
    msg = str(e.value)
    assert "\n" not in msg and "permission denied opening /dev/hidraw3" in msg
    assert 'SUBSYSTEM=="hidraw", ATTRS{idVendor}=="1209", MODE="0660", TAG+="uaccess"' in msg
    assert "/etc/udev/rules.d/70-haptic.rules" in msg


def test_probe_other_failure_and_success():
    with pytest.raises(DeviceError, match="cannot open /dev/hidraw8: open failed") as e:
        probe_open("/dev/hidraw8", device_factory=lambda: DeniedHandle(OSError("open failed")),
                   access_fn=lambda p, mode: False)                  # the node does not exist
    assert "udev" not in str(e.value)
    handle = FakeHandle()
    handle.get_manufacturer_string = lambda: "Acme"
    handle.get_product_string = lambda: "FFB Stick"
    out = io.StringIO()
    args = ArgumentParser()
    add_arguments(args)
    assert main_devices(args.parse_args(["--probe", "/dev/hidraw3"]), device_factory=lambda: handle, out=out) == 0
    assert out.getvalue() == "opened /dev/hidraw3: Acme FFB Stick\n" and handle.closes == 1
