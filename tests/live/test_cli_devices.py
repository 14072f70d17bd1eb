"""`teleop devices` and `teleop master` with a HID device, without a device attached.

The HID paths are driven through a fake hidapi handle at byte level: the master must leave the
device with zero force, all effects stopped and the actuators disabled on every exit path.
"""
from __future__ import annotations

import subprocess
import sys
from collections import deque
from pathlib import Path
from types import SimpleNamespace

import pytest

import master.hid
from live.cli import main
from teleop.session.transport import free_tcp_port, loopback_endpoint

DEVICE_FILE = Path(__file__).resolve().parents[2] / "configs" / "devices" / "generic_pid_joystick.yaml"
ZERO, STOP_ALL, DISABLE = bytes.fromhex("05 01 00 00"), bytes.fromhex("0c 03"), bytes.fromhex("0c 02")


class Handle:
    """hidapi ``hid.device`` stand-in: no input reports unless queued; reports sent are recorded."""

    def __init__(self, present=True):
        self.present, self.inbox, self.sent, self.closes = present, deque(), [], 0

    def open(self, vendor_id=0, product_id=0, serial_number=None):
        if not self.present:
            raise OSError("open failed")

    def open_path(self, path):
        self.open()

    def set_nonblocking(self, v):
        return 0

    def read(self, max_length, timeout_ms=0):
        return list(self.inbox.popleft()) if self.inbox else []

    def write(self, data):
        self.sent.append(bytes(data))
        return len(data)

    def send_feature_report(self, data):
        return self.write(data)

    def get_feature_report(self, report_id, max_length):
        return [0x12, 1, 1, 0, 0]            # PID Block Load: effect block 1 created

    def close(self):
        self.closes += 1


def hid_config(tmp_path: Path) -> Path:
    path = tmp_path / "hid.yaml"
    path.write_text(f"instrument: {{id: hidtest}}\nmaster:\n  device:\n    type: hid\n    file: {DEVICE_FILE}\n")
    return path


def one_line(capsys) -> str:
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def test_devices_without_any_device_says_so_in_one_line_exit_0():
    proc = subprocess.run([sys.executable, "-m", "live.cli", "devices", "--backend", "hid"], capture_output=True,
                          text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    out = [ln for ln in proc.stdout.splitlines() if ln.strip()]
    assert out == ["no HID devices found"] and proc.stderr == ""


def test_devices_lists_every_backend_with_what_it_found_or_why_none():
    proc = subprocess.run([sys.executable, "-m", "live.cli", "devices"], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0 and proc.stderr == "", proc.stderr
    heads = [ln.split(":")[0] for ln in proc.stdout.splitlines() if not ln.startswith(" ")]
    assert heads == ["hid", "evdev", "forcedimension", "touch"]


def test_devices_is_listed_in_the_help():
    proc = subprocess.run([sys.executable, "-m", "live.cli", "-h"], capture_output=True, text=True, timeout=60)
    assert "devices" in proc.stdout


def test_master_with_an_absent_hid_device_fails_in_one_line_naming_it(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(master.hid, "hid_module", lambda: SimpleNamespace(device=lambda: Handle(present=False)))
    assert main(["master", "--config", str(hid_config(tmp_path)), "--run-dir", str(tmp_path / "run")]) == 2
    line = one_line(capsys)
    assert line.startswith("teleop: error: cannot open HID device generic PID joystick (1209:0001)")


def test_master_hid_without_a_config_file_key_is_a_config_error(tmp_path, capsys):
    cfg = tmp_path / "nofile.yaml"
    cfg.write_text("master:\n  device:\n    type: hid\n")
    assert main(["master", "--config", str(cfg)]) == 2
    assert "master.device.file" in one_line(capsys)


@pytest.mark.parametrize("exit_path", ["device_lost", "max_duration"])
def test_master_leaves_the_hid_device_stopped_on_every_exit_path(exit_path, tmp_path, monkeypatch, capsys):
    handle = Handle()
    if exit_path == "max_duration":            # reports keep coming: the run ends by --max-duration
        handle.inbox.extend([bytes.fromhex("01 00 00 01")] * 100000)
    monkeypatch.setattr(master.hid, "hid_module", lambda: SimpleNamespace(device=lambda: handle))
    ep = loopback_endpoint(free_tcp_port())
    rc = main(["master", "--config", str(hid_config(tmp_path)), "--listen", ep, "--max-duration", "0.3",
               "--run-dir", str(tmp_path / "run")])
    if exit_path == "device_lost":             # no input report for 100 ms: lost, one line, exit 2
        assert rc == 2 and "HID device generic PID joystick lost: no valid input report" in one_line(capsys)
    else:
        assert rc == 0
    assert handle.sent[-3:] == [ZERO, STOP_ALL, DISABLE] and handle.closes == 1
    assert handle.sent.count(STOP_ALL) == 1 and handle.sent.count(DISABLE) == 1
    assert (tmp_path / "run" / "master_stats.json").is_file()
