"""Vendor devices (master/vendor_devices.py): a missing package or vendor library is one line naming what to install
(also through `teleop master`), and the Force Dimension and Touch adapters drive the device through fake SDKs."""
from __future__ import annotations

import dataclasses
import math
import subprocess
import sys
from types import SimpleNamespace

import pytest

from master.devices import make_device
from master.vendor_devices import DhdAdapter, TouchAdapter, VendorConfig, VendorDevice, load_vendor_file, sdk_module
from teleop.config.schema import Config
from teleop.errors import ConfigError, DeviceError


def _missing(name):
    def importer(module):
        raise ModuleNotFoundError(f"No module named '{name}'", name=name)
    return importer


@pytest.mark.parametrize("kind, package, extra", [("forcedimension", "forcedimension_core", "forcedimension"),
                                                  ("touch", "pyOpenHaptics", "touch")])
def test_a_missing_package_names_the_extra(kind, package, extra):
    with pytest.raises(DeviceError) as e:
        sdk_module(kind, _missing(package))
    assert str(e.value) == (f"master.device.type {kind} needs the {package} package: "
                            f"pip install 'tsm-teleop[{extra}]'")


@pytest.mark.parametrize("kind, library", [("forcedimension", "libdhd"), ("touch", "libHD")])
def test_a_missing_vendor_library_names_the_library(kind, library):
    def importer(module):
        raise OSError(f"{library}.so: cannot open shared object file: No such file or directory")
    with pytest.raises(DeviceError, match=rf"{kind}: .*\({library}, from .*missing or cannot be loaded") as e:
        sdk_module(kind, importer)
    assert "\n" not in str(e.value)


@pytest.mark.parametrize("kind", ["forcedimension", "touch", "evdev"])
def test_teleop_master_without_the_extra_exits_non_zero_with_one_line(tmp_path, kind):
    mod = {"forcedimension": "forcedimension_core", "touch": "pyOpenHaptics", "evdev": "evdev"}[kind]
    cfg = tmp_path / "c.yaml"
    cfg.write_text(f"instrument: {{id: v{kind[:3]}}}\nmaster: {{device: {{type: {kind}}}}}\n", encoding="utf-8")
    # a sitecustomize that hides the package, so the test holds whether or not it is installed here
    hide = tmp_path / "hide"
    hide.mkdir()
    (hide / "sitecustomize.py").write_text(f"import sys\nsys.modules[{mod!r}] = None\n", encoding="utf-8")
    env = {"PYTHONPATH": str(hide), "PATH": "/usr/bin:/bin", "HOME": str(tmp_path)}
    r = subprocess.run([sys.executable, "-m", "live.cli", "master", "--config", str(cfg), "--max-duration", "1"],
                       capture_output=True, text=True, timeout=120, env=env, cwd=str(tmp_path))
    lines = [ln for ln in (r.stderr + r.stdout).splitlines() if ln.strip()]
    assert r.returncode != 0 and any("pip install 'tsm-teleop[" in ln for ln in lines), r.stderr
    assert len([ln for ln in lines if "tsm-teleop[" in ln]) == 1 and "Traceback" not in r.stderr


def test_make_device_refuses_a_joint_instrument_for_a_one_axis_device():
    from teleop.config.load import load_config
    cfg = load_config("configs/instrument-3dof.yaml")
    cfg = dataclasses.replace(cfg, master=dataclasses.replace(
        cfg.master, device=dataclasses.replace(cfg.master.device, type="touch")))
    with pytest.raises(DeviceError, match="drives one axis, the instrument needs"):
        make_device(cfg)
    assert Config().master.device.type == "simulated"


class FakeDhd:
    def __init__(self, opens=0):
        self.opens, self.pos, self.mask = opens, [0.01, -0.02, 0.03], 0b1
        self.forces, self.closed, self.fail = [], 0, False

    def open(self):
        return self.opens

    def enableForce(self, on):  # noqa: N802
        self.force_on = on
        return 0

    def errorGetLastStr(self):  # noqa: N802 - the SDK's name
        return "no device found"

    def getPosition(self, out):  # noqa: N802
        if self.fail:
            return -1
        out[:] = self.pos
        return 0

    def getButtonMask(self):  # noqa: N802
        return self.mask

    def setForce(self, f):  # noqa: N802
        self.forces.append(tuple(f))
        return 0

    def close(self):
        self.closed += 1


def test_force_dimension_through_its_sdk_position_force_and_loss():
    dhd = FakeDhd()
    dev = VendorDevice(VendorConfig("omega.3", axis=1, invert=True, limit=3.0), DhdAdapter(dhd))
    assert dhd.force_on is True
    s = dev.read(0.5)
    assert (s.position, s.buttons, s.operator_present) == (0.02, 1, True)
    dev.set_force(5.0, 0.5)                                   # clamped to 3 N, along -y (inverted axis y)
    assert dhd.forces[-1] == (0.0, -3.0, 0.0) and dev.force == 3.0
    dev.set_force(math.nan, 0.6)
    assert dhd.forces[-1] == (0.0, 0.0, 0.0)
    dhd.fail = True
    with pytest.raises(DeviceError, match="omega.3: device lost: read failed"):
        dev.read(0.7)
    assert dhd.forces[-1] == (0.0, 0.0, 0.0) and dev.lost
    dev.close()
    dev.close()
    assert dhd.closed == 1
    with pytest.raises(DeviceError, match="open failed: no device found"):
        DhdAdapter(FakeDhd(opens=-1))


def test_touch_through_its_servo_callback():
    hd = SimpleNamespace(pos=[12.0, 0.0, -5.0], buttons=2, applied=[])
    hd.get_transform = lambda: [[1.0, 0, 0, 0], [0, 1.0, 0, 0], [0, 0, 1.0, 0], hd.pos + [1.0]]
    hd.get_buttons = lambda: hd.buttons
    hd.set_force = lambda f: hd.applied.append(tuple(f))
    closed = []

    class Device:
        def __init__(self, device_name, callback):
            self.callback = callback

        def close(self):
            closed.append(True)

    ad = TouchAdapter(hd, SimpleNamespace(HapticDevice=Device), lambda fn: fn)
    dev = VendorDevice(VendorConfig("touch"), ad)
    ad.device.callback()                                      # one servo tick of the HD scheduler
    s = dev.read(0.0)
    assert s.position == pytest.approx(0.012) and s.buttons == 2
    dev.set_force(-1.5, 0.0)
    ad.device.callback()
    assert hd.applied[-1] == (-1.5, 0.0, 0.0)
    dev.close()
    ad.device.callback()
    assert hd.applied[-1] == (0.0, 0.0, 0.0) and closed == [True]


def test_vendor_file_errors_name_the_key(tmp_path):
    p = tmp_path / "v.yaml"
    p.write_text("input: {axis: w}\n")
    with pytest.raises(ConfigError, match="input.axis"):
        load_vendor_file("touch", p)
    p.write_text("input: {axis: z, invert: true}\nforce: {limit: 2.5}\n")
    assert load_vendor_file("touch", p) == VendorConfig("touch", 2, True, 2.5)
