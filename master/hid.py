"""A haptic device over hidapi: position and buttons from an input report, force out as a report.

The report layout comes from a device file (``configs/devices/*.yaml``)::

    name: my joystick                     # for messages
    match: {vendor_id: "0x1209", product_id: "0x0001"}   # or {path: /dev/hidraw3}; serial optional
    input:                                # master.hid_reports.parse_input, plus:
      lost_after_ms: 100                  # no valid report for this long: device lost [ms]
      position_axes: [x, y, z]            # several axes (one per joint of an instrument); else position_axis
    force:
      limit: 4.0                          # clamp of the rendered force [N]
      backend: pid                        # pid (master.hid_pid) | report (vendor output report)
      pid: {...}  or  report: {...}       # report: a list of maps, one per position axis, for several axes

With several position axes the device reads as a multi-axis state (``positions``, one per axis) and
renders one force per axis (:meth:`HidDevice.set_forces`); the PID backend drives one axis only.

Safety: the force written is always finite and within ``force.limit``; a read error, a write error
or silence longer than ``lost_after_ms`` marks the device lost (``operator_present`` False, zero
force and stop attempted, :class:`DeviceError` raised). :meth:`HidDevice.close` writes zero force,
then stops the force channel (PID: Stop All Effects, Disable Actuators), then closes the handle;
it runs once, whatever happened before. Callers hold the device in a ``with`` block so that every
exit path (return, exception, Ctrl-C) goes through it::

    with HidDevice.from_file("configs/devices/generic_pid_joystick.yaml") as dev:
        while running:
            state = dev.read(clock.now())
            dev.set_force(force, clock.now())
"""
from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from master.device import DeviceState, MultiAxisState
from master.hid_pid import PidConfig, PidForce, parse_pid
from master.hid_reports import InputMap, InputSample, OutputMap, Section, parse_input, parse_output, send_report
from teleop.config.reader import read_yaml
from teleop.errors import DeviceError

__all__ = ["Match", "HidDeviceConfig", "HidDevice", "load_device_file", "parse_device", "hid_module"]

MAX_DRAIN = 256          # reports read per cycle at most (a device sends ~1 per ms)


def hid_module() -> Any:
    """The hidapi module (``import hid``), imported on first use.

    Raises
    ------
    DeviceError
        hidapi (or its shared library) is not installed.
    """
    try:
        import hid
    except ImportError as e:  # pragma: no cover - hidapi is a dependency
        raise DeviceError(f"hidapi is not usable (pip install hidapi): {e}") from None
    return hid


@dataclass(frozen=True)
class Match:
    """Which device to open: ``path``, or ``vendor_id`` + ``product_id`` (+ ``serial``)."""

    vendor_id: int = 0
    product_id: int = 0
    serial: str | None = None
    path: str | None = None

    def describe(self) -> str:
        return self.path if self.path else f"{self.vendor_id:04x}:{self.product_id:04x}"


@dataclass(frozen=True)
class HidDeviceConfig:
    """A parsed device file (see the module docstring)."""

    name: str
    match: Match
    input: InputMap
    force_limit: float                     # [N]
    force: OutputMap | PidConfig | tuple[OutputMap, ...]   # a tuple: one report map per position axis
    lost_after: float = 0.1                # [s]


def parse_device(data: Any, source: str = "<dict>") -> HidDeviceConfig:
    """A :class:`HidDeviceConfig` from the mapping of a device file.

    Raises
    ------
    ConfigError
        Unknown or missing key, wrong type or range; the message names ``source`` and the dotted key.
    """
    top = Section(data, source, "")
    m = top.sub("match")
    path = m.raw("path", None)
    if path is not None and (not isinstance(path, str) or not path):
        raise m.error(f"expected a device path string, got {path!r}", "path")
    serial = m.raw("serial", None)
    if serial is not None and not isinstance(serial, str):
        raise m.error(f"expected a string, got {serial!r}", "serial")
    match = Match(m.int("vendor_id", 0, 0, 0xFFFF), m.int("product_id", 0, 0, 0xFFFF), serial, path)
    if path is None and (match.vendor_id == 0 or match.product_id == 0):
        raise m.error("give path, or both vendor_id and product_id")
    m.done()
    ins = top.sub("input")
    lost_after = ins.num("lost_after_ms", 100.0, positive=True) / 1000.0
    inp = parse_input(ins)
    fs = top.sub("force")
    limit = fs.num("limit", positive=True)
    backend = fs.choice("backend", ("pid", "report"))
    force: OutputMap | PidConfig | tuple[OutputMap, ...]
    n_axes = len(inp.position_axes)
    if backend == "pid":
        if n_axes > 1:
            raise fs.error(f"the PID backend drives one axis; {n_axes} position axes need backend: report with one "
                           f"report map per axis", "backend")
        force = parse_pid(fs.sub("pid"))
    elif isinstance(fs.raw("report", None), list):
        items = fs.raw("report")
        if len(items) != n_axes:
            raise fs.error(f"expected one report map per position axis ({n_axes}), got {len(items)}", "report")
        force = tuple(parse_output(Section(it, source, fs.key(f"report[{i}]")), limit) for i, it in enumerate(items))
    else:
        if n_axes > 1:
            raise fs.error(f"{n_axes} position axes need a list of report maps, one per axis", "report")
        force = parse_output(fs.sub("report"), limit)
    fs.done()
    name = top.raw("name", match.describe())
    if not isinstance(name, str):
        raise top.error(f"expected a string, got {name!r}", "name")
    top.done()
    return HidDeviceConfig(name, match, inp, limit, force, lost_after)


def load_device_file(path: str | Path) -> HidDeviceConfig:
    """Read and check a device file.

    Raises
    ------
    ConfigError
        Missing or unreadable file, YAML syntax error, or any error of :func:`parse_device`.
    """
    path = Path(path)
    data = read_yaml(path, hex_integers=True)[0]     # bounded: size, nesting, aliases (teleop/config/reader.py)
    return parse_device(data, str(path))


class _ReportForce:
    """Force as vendor output/feature reports (:class:`OutputMap`, one per axis): zero on start, nothing
    to stop. ``write`` takes one force [N] or one per axis."""

    def __init__(self, omaps: OutputMap | tuple[OutputMap, ...], handle: Any):
        self.omaps = omaps if isinstance(omaps, tuple) else (omaps,)
        self.handle = handle
        self.limit = self.omaps[0].limit

    def start(self) -> None:
        self.write([0.0] * len(self.omaps))

    def write(self, force) -> None:
        forces = [force] if not isinstance(force, (list, tuple)) else list(force)
        for om, f in zip(self.omaps, forces + [0.0] * (len(self.omaps) - len(forces)), strict=False):
            send_report(self.handle, om.kind, om.encode(f), "force")

    def stop(self) -> None:
        pass


class HidDevice:
    """:class:`master.device.HapticDevice` over hidapi (see the module docstring).

    Parameters
    ----------
    cfg : HidDeviceConfig
    handle_factory : callable, optional
        Returns an unopened handle with the ``hid.device`` interface; default ``hid.device``.
        Tests pass a fake.

    Raises
    ------
    DeviceError
        The device cannot be opened (message names it and the ``teleop devices --probe`` check) or
        the force channel cannot be started (the handle is closed again before raising).
    """

    def __init__(self, cfg: HidDeviceConfig, handle_factory: Callable[[], Any] | None = None):
        self.cfg = cfg
        self.input = dataclasses.replace(cfg.input, rejected=dict.fromkeys(cfg.input.rejected, 0), accepted=0)
        self.lost = False
        self.lost_reason = ""
        self.force = 0.0                       # last force sent [N], after the clamp (axis 0)
        self.n_axes = len(cfg.input.position_axes) or 1
        self.forces = [0.0] * self.n_axes      # last force sent per axis [N]
        self._closed = False
        self._stopped = False
        self._last: InputSample | None = None
        self._t_ref: float | None = None       # time of the last valid report (or of the first read)
        factory = handle_factory or hid_module().device
        self._handle = factory()
        where = cfg.match.describe()
        try:
            if cfg.match.path:
                self._handle.open_path(cfg.match.path.encode())
            else:
                self._handle.open(cfg.match.vendor_id, cfg.match.product_id, cfg.match.serial)
        except (OSError, ValueError) as e:
            self._closed = True
            raise DeviceError(f"cannot open HID device {cfg.name} ({where}): {e}; "
                              f"check it with `teleop devices --probe PATH`") from None
        try:
            self._handle.set_nonblocking(1)
            self._out = (PidForce(cfg.force, self._handle, cfg.force_limit) if isinstance(cfg.force, PidConfig)
                         else _ReportForce(cfg.force, self._handle))
            self._out.start()
        except BaseException:
            self.close()
            raise

    @classmethod
    def from_file(cls, path: str | Path, handle_factory: Callable[[], Any] | None = None) -> HidDevice:
        """Open the device described by a device file (:func:`load_device_file`)."""
        return cls(load_device_file(path), handle_factory)

    # ---- HapticDevice -------------------------------------------------------------------------

    def read(self, t: float) -> DeviceState | MultiAxisState:
        """Drain the pending input reports and return the state of the latest valid one at ``t`` [s].

        Malformed reports are counted in ``self.input.rejected`` and skipped. Before the first valid
        report the state is ``position 0.0, operator_present False``.

        Raises
        ------
        DeviceError
            Read error or device unplugged (hidapi OSError/ValueError), no valid report for longer
            than ``lost_after``, or the device was already lost or closed.
        """
        self._check_usable()
        if self._t_ref is None:
            self._t_ref = t
        latest = None
        try:
            for _ in range(MAX_DRAIN):
                data = self._handle.read(self.input.read_size, 0)
                if not data:
                    break
                latest = self.input.decode(data) or latest
        except (OSError, ValueError) as e:
            self._lose(f"read failed ({e or type(e).__name__})")
        if latest is not None:
            self._last, self._t_ref = latest, t
        elif t - self._t_ref > self.cfg.lost_after:
            self._lose(f"no valid input report for {t - self._t_ref:.3f} s "
                       f"(limit {self.cfg.lost_after:.3f} s; unplugged?)")
        return self.state(t)

    def set_force(self, force: float, t: float) -> None:
        """Write ``force`` [N], saturated to ``force.limit`` (NaN/inf -> 0).

        A no-op once the device is lost or closed: its force output was stopped then, and a zeroing
        call in a caller's ``finally`` must not mask the error that got it there (:meth:`read` keeps
        raising for a lost device).

        Raises
        ------
        DeviceError
            The report was not sent; the device is then lost.
        """
        self.set_forces([force], t)

    def set_forces(self, forces, t: float) -> None:
        """Write one force per position axis [N] (missing ones 0), each saturated to ``force.limit``;
        otherwise as :meth:`set_force`."""
        if self._closed or self.lost:
            return
        fs = [float(f) for f in forces][:self.n_axes]
        fs += [0.0] * (self.n_axes - len(fs))
        try:
            self._write(fs)
        except DeviceError as e:
            self._lose(str(e))
        self.forces = [_clamp(f, self._out.limit) for f in fs]
        self.force = self.forces[0]

    def close(self) -> None:
        """Zero force, stop the force channel, close the handle; once (later calls do nothing)."""
        if self._closed:
            return
        self._closed = True
        try:
            self._stop_output()
        finally:
            try:
                self._handle.close()
            except (OSError, ValueError):
                pass

    def __enter__(self) -> HidDevice:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ---- helpers --------------------------------------------------------------------------------

    def state(self, t: float) -> DeviceState | MultiAxisState:
        """The last known state at ``t`` [s] (operator not present when lost or never read); a
        :class:`MultiAxisState` when the device has several position axes."""
        s = self._last
        multi = self.n_axes > 1
        if s is None:
            return MultiAxisState(t, (0.0,) * self.n_axes, 0, False) if multi else DeviceState(t, 0.0, 0, False)
        present = (True if s.present is None else s.present) and not self.lost and not self._closed
        if multi:
            return MultiAxisState(t, tuple(s.axes[a] for a in self.input.position_axes), s.buttons, present)
        return DeviceState(t, s.axes[self.input.position_axis], s.buttons, present)

    def _write(self, forces: list[float]) -> None:
        """Send one force per axis [N]: the PID backend drives a single axis (:func:`parse_device`), the
        report backend takes the list (one report map per axis)."""
        if isinstance(self._out, PidForce):
            self._out.write(forces[0])
        else:
            self._out.write(forces)

    @property
    def closed(self) -> bool:
        return self._closed

    def _check_usable(self) -> None:
        if self._closed:
            raise DeviceError(f"HID device {self.cfg.name} is closed")
        if self.lost:
            raise DeviceError(f"HID device {self.cfg.name} was lost: {self.lost_reason}")

    def _stop_output(self) -> None:
        """Best effort, once: zero force, then stop (every step attempted; errors swallowed)."""
        if self._stopped or not hasattr(self, "_out"):
            return
        self._stopped = True
        self.force = 0.0
        self.forces = [0.0] * self.n_axes
        for step in (lambda: self._write([0.0] * self.n_axes), self._out.stop):
            try:
                step()
            except (DeviceError, OSError, ValueError):
                pass

    def _lose(self, reason: str) -> None:
        self.lost, self.lost_reason = True, reason
        self._stop_output()
        raise DeviceError(f"HID device {self.cfg.name} lost: {reason}")


def _clamp(force: float, limit: float) -> float:
    """``force`` [N] clipped to ``[-limit, limit]``; 0 when NaN or inf."""
    f = float(force)
    return max(-limit, min(limit, f)) if math.isfinite(f) else 0.0
