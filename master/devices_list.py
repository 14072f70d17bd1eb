"""`teleop devices`: list the HID devices hidapi sees, and check that one can be opened.

The listing shows what a device file needs (``match.vendor_id``, ``match.product_id`` or
``match.path``). On Linux a hidraw node is usually root-only; :func:`probe_open` says which udev rule
gives the logged-in user access when opening fails for lack of permission.
"""
from __future__ import annotations

import argparse
import errno
import os
import sys
from typing import Any, Callable, TextIO

from master.hid import hid_module
from teleop.errors import DeviceError

__all__ = ["list_devices", "format_devices", "probe_open", "udev_rule", "add_arguments", "main_devices",
           "UDEV_RULES_FILE", "NONE_FOUND"]

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
    lines = ["  ".join(c.ljust(w) for c, w in zip(r, widths)) + "  " + r[-1] for r in rows]
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


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``teleop devices``."""
    parser.add_argument("--vid", type=lambda s: int(s, 16), default=0, metavar="HEX",
                        help="only this vendor id (hex, e.g. 1209)")
    parser.add_argument("--pid", type=lambda s: int(s, 16), default=0, metavar="HEX",
                        help="only this product id (hex)")
    parser.add_argument("--probe", metavar="PATH",
                        help="try to open the device at PATH (shows the udev rule on permission errors)")


def main_devices(args: argparse.Namespace, *, enumerate_fn: Callable[..., list[dict]] | None = None,
                 device_factory: Callable[[], Any] | None = None, out: TextIO | None = None) -> int:
    """Run ``teleop devices``: print the listing (or the probe result); 0 also when none are found.

    Raises
    ------
    DeviceError
        Enumeration failed, or ``--probe`` could not open the device (the CLI prints it, exit 2).
    """
    out = out or sys.stdout
    probe = getattr(args, "probe", None)
    if probe:
        print(probe_open(probe, device_factory=device_factory, enumerate_fn=enumerate_fn), file=out)
        return 0
    devices = list_devices(enumerate_fn, getattr(args, "vid", 0) or 0, getattr(args, "pid", 0) or 0)
    print(format_devices(devices), file=out)
    return 0
