"""`teleop devices` per backend (master/devices_list.py): evdev devices with or without FF_CONSTANT, the vendor SDKs
through a fake import, one line for what is missing, sections when all backends are listed."""
from __future__ import annotations

import io
from argparse import ArgumentParser
from types import SimpleNamespace

from master.devices_list import BACKENDS, add_arguments, backend_lines, main_devices
from tests.master.fake_evdev import FakeEvdev, FakeInput


def _args(*argv: str):
    p = ArgumentParser()
    add_arguments(p)
    return p.parse_args(list(argv))


def _no_package(module: str):
    raise ModuleNotFoundError(f"No module named {module.split('.')[0]!r}", name=module.split(".")[0])


def test_evdev_lists_each_device_and_whether_it_can_render_a_constant_force():
    ev = FakeEvdev(FakeInput("/dev/input/event7", "FF joystick"),
                   FakeInput("/dev/input/event2", "keyboard", ff_codes=()))
    lines = backend_lines("evdev", evdev=ev)
    assert [ln.split()[0] for ln in lines] == ["/dev/input/event2", "/dev/input/event7"]
    assert lines[0].endswith("no FF_CONSTANT (not usable)") and lines[1].endswith("FF_CONSTANT")
    assert backend_lines("evdev", evdev=FakeEvdev())[0].startswith("no event devices readable")


def test_vendor_backends_count_devices_or_say_what_to_install():
    dhd = SimpleNamespace(getDeviceCount=lambda: 2)
    assert backend_lines("forcedimension", importer=lambda m: dhd) == ["2 Force Dimension device(s) found"]
    dhd0 = SimpleNamespace(getDeviceCount=lambda: 0)
    assert backend_lines("forcedimension", importer=lambda m: dhd0)[0].startswith("no Force Dimension device found")
    assert backend_lines("touch", importer=lambda m: object())[0].startswith("OpenHaptics HD library loaded")
    line, = backend_lines("touch", importer=_no_package)
    assert line.endswith("pip install 'tsm-teleop[touch]'")


def test_all_backends_print_one_section_each_and_exit_0():
    out = io.StringIO()
    ev = FakeEvdev(FakeInput("/dev/input/event7", "wheel"), FakeInput("/dev/input/event9", "stick"))
    assert main_devices(_args(), enumerate_fn=lambda vid, pid: [], evdev=ev, importer=_no_package, out=out) == 0
    text = out.getvalue().splitlines()
    assert [ln.split(":")[0] for ln in text if not ln.startswith("  ")] == list(BACKENDS)
    assert text[0] == "hid: no HID devices found" and text[1] == "evdev:" and text[2].startswith("  /dev/input/event7")
    assert text[4] == "forcedimension: master.device.type forcedimension needs the forcedimension_core package: " \
                      "pip install 'tsm-teleop[forcedimension]'"
    out = io.StringIO()
    main_devices(_args("--backend", "evdev"), evdev=FakeEvdev(), out=out)
    assert out.getvalue().count("\n") == 1 and out.getvalue().startswith("no event devices readable")
