"""Vendor haptic devices through their SDKs: a Force Dimension device (``forcedimension-core``, over the
Force Dimension DHD library) and a 3D Systems Touch (``pyOpenHaptics``, over the OpenHaptics HD library).

Both are optional extras (``pip install 'tsm-teleop[forcedimension]'``, ``'tsm-teleop[touch]'``) over a
vendor library installed with the vendor's SDK. When the package or the library is missing, opening
the device raises :class:`DeviceError` with one line naming what to install; nothing else changes.

A vendor device is a Cartesian handle: one of its axes (``input.axis``: x, y or z of the vendor's frame,
``invert`` flips it) is the master's device axis; the handle position along it [m] is the device position
and the rendered force [N] is applied along it (the other two components zero), clamped to
``force.limit``, a NaN rendering zero. The device file (``master.device.file``, optional)::

    name: omega.3
    input: {axis: x, invert: false}
    force: {limit: 4.0}

Each SDK sits behind a small adapter (``open``, ``position`` [m], ``buttons``, ``set_force`` [N], ``close``)
taking the SDK module as a parameter, so tests drive the device through a fake SDK.
"""
from __future__ import annotations

import importlib
import math
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from master.device import DeviceState
from teleop.config.reader import read_yaml
from teleop.errors import ConfigError, DeviceError

__all__ = ["VendorConfig", "VendorDevice", "DhdAdapter", "TouchAdapter", "load_vendor_file", "sdk_module",
           "VENDORS"]

#: device type -> (module to import, pip extra, vendor library and where it comes from)
VENDORS = {
    "forcedimension": ("forcedimension_core.dhd", "forcedimension",
                       "the Force Dimension SDK library (libdhd, from the Force Dimension SDK)"),
    "touch": ("pyOpenHaptics.hd", "touch", "the OpenHaptics HD library (libHD, from the 3D Systems OpenHaptics "
                                           "Developer Edition and the Touch device drivers)"),
}
_AXES = {"x": 0, "y": 1, "z": 2}


def sdk_module(kind: str, importer=importlib.import_module) -> Any:
    """The SDK module of ``kind`` (``forcedimension`` or ``touch``).

    Raises
    ------
    DeviceError
        One line: the Python package to install when it is missing, else the vendor library.
    """
    name, extra, library = VENDORS[kind]
    try:
        return importer(name)
    except ModuleNotFoundError as e:
        if e.name is not None and name.startswith(e.name.split(".")[0]):
            raise DeviceError(f"master.device.type {kind} needs the {name.split('.')[0]} package: "
                              f"pip install 'tsm-teleop[{extra}]'") from None
        raise DeviceError(f"master.device.type {kind}: {library} is missing ({e})") from None
    except (ImportError, OSError) as e:
        raise DeviceError(f"master.device.type {kind}: {library} is missing or cannot be loaded ({e})") from None


@dataclass(frozen=True)
class VendorConfig:
    """The vendor device file: the handle axis used (0, 1, 2 = x, y, z), its sign, the force clamp [N]."""

    name: str
    axis: int = 0
    invert: bool = False
    limit: float = 4.0


def load_vendor_file(kind: str, path: str | Path | None) -> VendorConfig:
    """Read a vendor device file (None: the defaults).

    Raises
    ------
    ConfigError
        Unreadable, not YAML, an unknown axis, a limit not > 0 (named with the file and key).
    """
    if path is None:
        return VendorConfig(kind)
    # bounded: size, nesting, aliases (teleop/config/reader.py)
    data = read_yaml(Path(path), hex_integers=True)[0] or {}
    i, f = data.get("input") or {}, data.get("force") or {}
    axis = i.get("axis", "x")
    if axis not in _AXES:
        raise ConfigError(f"{path}: input.axis: expected x, y or z, got {axis!r}")
    limit = f.get("limit", 4.0)
    if isinstance(limit, bool) or not isinstance(limit, (int, float)) or not (math.isfinite(limit) and limit > 0):
        raise ConfigError(f"{path}: force.limit: expected a number > 0 [N], got {limit!r}")
    return VendorConfig(str(data.get("name", kind)), _AXES[axis], bool(i.get("invert", False)), float(limit))


class DhdAdapter:
    """Force Dimension over ``forcedimension_core.dhd`` (calls as in its documentation: ``open`` -> id or -1,
    ``enableForce``, ``getPosition(out=)`` [m], ``getButtonMask``, ``setForce`` [N], ``errorGetLastStr``,
    ``close``)."""

    def __init__(self, dhd: Any):
        self.dhd = dhd
        if dhd.open() < 0:
            raise DeviceError(f"Force Dimension device: open failed: {dhd.errorGetLastStr()} (see `teleop devices`)")
        if dhd.enableForce(True) < 0:
            msg = dhd.errorGetLastStr()
            dhd.close()
            raise DeviceError(f"Force Dimension device: force mode refused: {msg}")
        self._pos = [0.0, 0.0, 0.0]

    def position(self) -> tuple[float, float, float]:
        if self.dhd.getPosition(out=self._pos) < 0:
            raise OSError(self.dhd.errorGetLastStr())
        return (self._pos[0], self._pos[1], self._pos[2])

    def buttons(self) -> int:
        return int(self.dhd.getButtonMask())

    def set_force(self, f: tuple[float, float, float]) -> None:
        if self.dhd.setForce(list(f)) < 0:
            raise OSError(self.dhd.errorGetLastStr())

    def close(self) -> None:
        self.dhd.close()


class TouchAdapter:
    """A 3D Systems Touch over ``pyOpenHaptics``: its servo-loop callback (the HD scheduler, 1 kHz) copies the
    position (the translation of ``hd.get_transform()``, mm -> m) and ``hd.get_buttons()`` out and applies the
    latest force (``hd.set_force``); the master's loop only exchanges them."""

    def __init__(self, hd: Any, device_module: Any = None, callback_decorator: Any = None):
        self.hd = hd
        dev_mod = device_module or importlib.import_module("pyOpenHaptics.hd_device")
        deco = callback_decorator or importlib.import_module("pyOpenHaptics.hd_callback").hd_callback
        self._lock = threading.Lock()
        self._pos, self._buttons, self._force = (0.0, 0.0, 0.0), 0, [0.0, 0.0, 0.0]

        @deco
        def servo():
            p = hd.get_transform()[3]            # row 3 of the 4x4 transform: the translation [mm]
            b = hd.get_buttons()
            with self._lock:
                self._pos, self._buttons, f = (1e-3 * p[0], 1e-3 * p[1], 1e-3 * p[2]), int(b), list(self._force)
            hd.set_force(f)

        self._servo = servo
        try:
            self.device = dev_mod.HapticDevice(device_name="Default Device", callback=servo)
        except Exception as e:  # noqa: BLE001 - the HD library raises its own error types
            raise DeviceError(f"3D Systems Touch: open failed: {e} (see `teleop devices`)") from None

    def position(self) -> tuple[float, float, float]:
        with self._lock:
            return self._pos

    def buttons(self) -> int:
        with self._lock:
            return self._buttons

    def set_force(self, f: tuple[float, float, float]) -> None:
        with self._lock:
            self._force = list(f)

    def close(self) -> None:
        self.set_force((0.0, 0.0, 0.0))
        self.device.close()


class VendorDevice:
    """A Cartesian vendor handle as a one-axis haptic device (module docstring).

    Parameters
    ----------
    cfg : VendorConfig
    adapter : DhdAdapter or TouchAdapter (or a fake with the same five methods)
    """

    def __init__(self, cfg: VendorConfig, adapter: Any):
        self.cfg, self.adapter = cfg, adapter
        self.sign = -1.0 if cfg.invert else 1.0
        self.force, self.lost, self.closed = 0.0, False, False
        self._last = DeviceState(0.0, 0.0, 0, False)

    def read(self, t: float) -> DeviceState:
        """The handle position along the axis [m] and the buttons at ``t`` [s].

        Raises
        ------
        DeviceError
            Closed or lost, or the SDK failed (the device is then lost: zero force attempted).
        """
        if self.closed or self.lost:
            raise DeviceError(f"{self.cfg.name}: the device was {'closed' if self.closed else 'lost'}")
        try:
            p, b = self.adapter.position(), self.adapter.buttons()
        except OSError as e:
            self._lose(f"read failed ({e})")
        self._last = DeviceState(t, self.sign * float(p[self.cfg.axis]), b, True)
        return self._last

    def set_force(self, force: float, t: float) -> None:
        """Render ``force`` [N] along the axis (clamped to ``force.limit``, NaN -> 0); no-op when lost or closed."""
        if self.closed or self.lost:
            return
        f = 0.0 if not math.isfinite(force) else max(-self.cfg.limit, min(self.cfg.limit, float(force)))
        vec = [0.0, 0.0, 0.0]
        vec[self.cfg.axis] = self.sign * f
        try:
            self.adapter.set_force((vec[0], vec[1], vec[2]))
        except OSError as e:
            self._lose(f"force not sent ({e})")
        self.force = f

    def close(self) -> None:
        """Zero force, then release the device; once."""
        if self.closed:
            return
        self.closed = True
        for step in ((lambda: self.adapter.set_force((0.0, 0.0, 0.0))), self.adapter.close):
            try:
                step()
            except OSError:
                pass
        self.force = 0.0

    def __enter__(self) -> VendorDevice:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _lose(self, reason: str) -> None:
        try:
            self.adapter.set_force((0.0, 0.0, 0.0))
        except OSError:
            pass
        self.lost, self.force = True, 0.0
        raise DeviceError(f"{self.cfg.name}: device lost: {reason}")
