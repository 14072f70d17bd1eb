"""`teleop devices`: what each device backend finds, and a check that a HID device can be opened.

Backends (``--backend``, default all): ``hid`` (the HID devices hidapi sees, with what a device file
needs: ``match.vendor_id``, ``match.product_id`` or ``match.path``), ``evdev`` (the event devices the
user may open, and whether each has the FF_CONSTANT effect :mod:`master.evdev_device` needs),
``forcedimension`` (the number of Force Dimension devices the DHD library sees) and ``touch`` (whether
the OpenHaptics HD library loads). A backend whose extra or vendor library is missing says in one line
what to install. On Linux a hidraw node is usually root-only; :func:`probe_open` says which udev rule
gives the logged-in user access when opening fails for lack of permission.
"""
from __future__ import annotations

import argparse
import errno
import os
import sys
from collections.abc import Callable
from typing import Any, TextIO

from master.hid import hid_module
from teleop.errors import DeviceError

__all__ = ["list_devices", "format_devices", "probe_open", "udev_rule", "add_arguments", "main_devices",
           "backend_lines", "BACKENDS", "UDEV_RULES_FILE", "NONE_FOUND"]

BACKENDS = ("hid", "evdev", "forcedimension", "touch")

UDEV_RULES_FILE = "/etc/udev/rules.d/70-haptic.rules"
NONE_FOUND = "no HID devices found"


def _int(v: Any, missing: int) -> int:
    """``v`` as an int, ``missing`` when hidapi gave None (0 is a real interface number)."""
    return missing if v is None else int(v)


def _text(v: Any) -> str:
    if isinstance(v, bytes):
        return v.decode("utf-8", "replace")
    return "" if v is None else str(v)


def list_devices(enumerate_fn: Callable[..., list[dict]] | None = None, vendor_id: int = 0,
                 product_id: int = 0) -> list[dict]:
    """The HID devices present, as plain dicts sorted by path.

    Parameters
    ----------
    enumerate_fn : callable, optional
        ``hid.enumerate``-like: ``(vendor_id, product_id) -> list of dicts``; default ``hid.enumerate``.
    vendor_id, product_id : int
        Filter (0: any).

    Returns
    -------
    list of dict
        Keys ``vendor_id``, ``product_id``, ``usage_page``, ``usage``, ``interface_number`` (int),
        ``manufacturer``, ``product``, ``serial``, ``path`` (str).

    Raises
    ------
    DeviceError
        Enumeration failed (OSError from hidapi).
    """
    fn = enumerate_fn or hid_module().enumerate
    try:
        raw = fn(vendor_id, product_id)
    except OSError as e:
        raise DeviceError(f"HID enumeration failed: {e}") from None
    out = [{
        "vendor_id": int(d.get("vendor_id") or 0), "product_id": int(d.get("product_id") or 0),
        "usage_page": int(d.get("usage_page") or 0), "usage": int(d.get("usage") or 0),
        "interface_number": _int(d.get("interface_number"), -1),
        "manufacturer": _text(d.get("manufacturer_string")), "product": _text(d.get("product_string")),
        "serial": _text(d.get("serial_number")), "path": _text(d.get("path")),
    } for d in raw]
    return sorted(out, key=lambda d: d["path"])


def format_devices(devices: list[dict]) -> str:
    """A table (one device per line, with a header), or the single line ``no HID devices found``."""
    if not devices:
        return NONE_FOUND
    rows = [("VID:PID", "usage", "manufacturer", "product", "path")]
    for d in devices:
        rows.append((f"{d['vendor_id']:04x}:{d['product_id']:04x}",
                     f"{d['usage_page']:04x}:{d['usage']:04x}",
                     d["manufacturer"] or "-", d["product"] or "-", d["path"]))
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]) - 1)]
    lines = ["  ".join(c.ljust(w) for c, w in zip(r, widths, strict=False)) + "  " + r[-1] for r in rows]
    return "\n".join(line.rstrip() for line in lines)


def udev_rule(vendor_id: int | None) -> str:
    """The udev rule line that gives the logged-in user access to the device's hidraw node."""
    vid = f'ATTRS{{idVendor}}=="{vendor_id:04x}", ' if vendor_id else ""
    return f'SUBSYSTEM=="hidraw", {vid}MODE="0660", TAG+="uaccess"'


def _permission_problem(path: str, exc: BaseException, access_fn: Callable[[str, int], bool]) -> bool:
    if isinstance(exc, PermissionError) or getattr(exc, "errno", None) in (errno.EACCES, errno.EPERM):
        return True
    # hidapi reports only "open failed": look at the node itself (hidraw backend paths are files)
    return path.startswith("/dev/") and access_fn(path, os.F_OK) and not access_fn(path, os.R_OK | os.W_OK)


def probe_open(path: str, *, device_factory: Callable[[], Any] | None = None,
               enumerate_fn: Callable[..., list[dict]] | None = None,
               access_fn: Callable[[str, int], bool] = os.access) -> str:
    """Open the device at ``path`` and close it again; return a one-line description.

    Raises
    ------
    DeviceError
        The device cannot be opened. When the cause is a permission (the hidraw node exists but is
        not readable and writable, or hidapi raised EACCES/EPERM) the message names the udev rule to
        add to :data:`UDEV_RULES_FILE`, with the device's vendor id when the listing knows it.

    Notes
    -----
    hidapi's Python binding raises a bare ``OSError('open failed')``; the permission check therefore
    looks at the node with ``access_fn`` (``os.access``; injectable for tests).
    """
    h = (device_factory or hid_module().device)()
    try:
        h.open_path(path.encode())
    except (OSError, ValueError) as e:
        if _permission_problem(path, e, access_fn):
            vid = None
            try:
                vid = next((d["vendor_id"] for d in list_devices(enumerate_fn) if d["path"] == path), None)
            except DeviceError:
                pass
            raise DeviceError(
                f"permission denied opening {path}: add the line '{udev_rule(vid)}' to {UDEV_RULES_FILE}, "
                f"then run 'sudo udevadm control --reload && sudo udevadm trigger' and replug") from None
        raise DeviceError(f"cannot open {path}: {e or 'open failed'} (is it plugged in? see `teleop devices`)") \
            from None
    try:
        names = []
        for getter in ("get_manufacturer_string", "get_product_string"):
            try:
                names.append(_text(getattr(h, getter)()))
            except (OSError, ValueError, AttributeError):
                pass
        label = " ".join(n for n in names if n) or "(no strings)"
        return f"opened {path}: {label}"
    finally:
        try:
            h.close()
        except (OSError, ValueError):
            pass


def _evdev_lines(ev: Any) -> list[str]:
    from master.evdev_device import evdev_module, ff_devices
    try:
        found = ff_devices(ev if ev is not None else evdev_module())
    except DeviceError as e:
        return [str(e)]
    if not found:
        return ["no event devices readable (force feedback needs read and write access to /dev/input/event*: "
                "the input group or a udev rule)"]
    width = max(len(n) for _, n, _ in found)
    return [f"{p}  {n.ljust(width)}  {'FF_CONSTANT' if ok else 'no FF_CONSTANT (not usable)'}" for p, n, ok in found]


def _vendor_lines(kind: str, importer: Callable[[str], Any] | None) -> list[str]:
    from master.vendor_devices import sdk_module
    try:
        sdk = sdk_module(kind) if importer is None else sdk_module(kind, importer)
    except DeviceError as e:
        return [str(e)]
    if kind == "touch":       # OpenHaptics finds a device only by opening it
        return ["OpenHaptics HD library loaded; the Touch opens as its 'Default Device' (Touch Setup names it)"]
    n = int(sdk.getDeviceCount())
    return [f"{n} Force Dimension device(s) found" if n > 0 else "no Force Dimension device found "
            "(plugged in and powered? the DHD library counts none)"]


def backend_lines(name: str, *, enumerate_fn: Callable[..., list[dict]] | None = None, vendor_id: int = 0,
                  product_id: int = 0, evdev: Any = None, importer: Callable[[str], Any] | None = None) -> list[str]:
    """What backend ``name`` (one of :data:`BACKENDS`) finds: a table, or one line saying why none.

    ``enumerate_fn``, ``evdev`` and ``importer`` stand in for hidapi's enumerate, python-evdev and the
    vendor SDK import in tests. Never raises :class:`DeviceError`: its message becomes the line.
    """
    if name == "hid":
        try:
            return format_devices(list_devices(enumerate_fn, vendor_id, product_id)).splitlines()
        except DeviceError as e:
            return [str(e)]
    if name == "evdev":
        return _evdev_lines(evdev)
    return _vendor_lines(name, importer)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``teleop devices``."""
    parser.add_argument("--vid", type=lambda s: int(s, 16), default=0, metavar="HEX",
                        help="only this vendor id (hex, e.g. 1209)")
    parser.add_argument("--pid", type=lambda s: int(s, 16), default=0, metavar="HEX",
                        help="only this product id (hex)")
    parser.add_argument("--backend", choices=BACKENDS + ("all",), default="all",
                        help="list one backend only (default all: hid, evdev, forcedimension, touch)")
    parser.add_argument("--probe", metavar="PATH",
                        help="try to open the device at PATH (shows the udev rule on permission errors)")


def main_devices(args: argparse.Namespace, *, enumerate_fn: Callable[..., list[dict]] | None = None,
                 device_factory: Callable[[], Any] | None = None, out: TextIO | None = None, evdev: Any = None,
                 importer: Callable[[str], Any] | None = None) -> int:
    """Run ``teleop devices``: print what each backend finds (or the probe result); 0 also when none are found.

    One backend (``--backend``) prints its listing bare; all of them print ``<backend>: <line>``, or
    ``<backend>:`` and its table indented.

    Raises
    ------
    DeviceError
        ``--probe`` could not open the device (the CLI prints it, exit 2).
    """
    out = out or sys.stdout
    probe = getattr(args, "probe", None)
    if probe:
        print(probe_open(probe, device_factory=device_factory, enumerate_fn=enumerate_fn), file=out)
        return 0
    chosen = getattr(args, "backend", "all") or "all"
    for name in BACKENDS if chosen == "all" else (chosen,):
        lines = backend_lines(name, enumerate_fn=enumerate_fn, vendor_id=getattr(args, "vid", 0) or 0,
                              product_id=getattr(args, "pid", 0) or 0, evdev=evdev, importer=importer)
        if chosen != "all":
            print("\n".join(lines), file=out)
        elif len(lines) == 1:
            print(f"{name}: {lines[0]}", file=out)
        else:
            print(f"{name}:\n" + "\n".join("  " + ln for ln in lines), file=out)
    return 0
