"""USB HID PID force feedback: the device force rendered as one streamed constant-force effect.

Protocol (USB Device Class Definition for Physical Interface Devices, PID 1.0, 1999)::

    start   Device Control: Device Reset (optional), Enable Actuators
            Device Gain (optional)
            Create New Effect (feature) -> PID Block Load (feature): effect block index
            Set Effect: index, type = constant force, duration = infinite, gain, axes, direction
            Set Constant Force: index, magnitude 0
            Effect Operation: index, Start
    write   Set Constant Force: index, magnitude = round(F / max_force * magnitude_max)
    stop    Device Control: Stop All Effects, then Disable Actuators

Report ids and byte layouts come from the device's report descriptor and differ per device, so
every id, length, byte offset and type is configurable (``force.pid.reports`` in a device file).
The defaults are the layout of the example force-feedback joystick descriptor that the common open
firmwares build on (Set Effect 0x01, Set Constant Force 0x05, Effect Operation 0x0A, Device Control
0x0C, Device Gain 0x0D, Create New Effect 0x11 and PID Block Load 0x12 as feature reports; 8-bit
block index, 16-bit signed magnitude +-10000). The enumerated values are the 1-based indices of the
PID 1.0 usage arrays: Effect Type ET Constant Force = 1; Device Control DC Enable Actuators = 1,
DC Disable Actuators = 2, DC Stop All Effects = 3, DC Device Reset = 4; Effect Operation Op Effect
Start = 1, Op Effect Stop = 3; Block Load Status Success = 1, Full = 2, Error = 3. An infinite
duration is the 16-bit null value 0xFFFF (as Linux hid-pidff sends, PID_INFINITE). Check them against
your descriptor (``hidrd-convert`` or ``usbhid-dump`` show it).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from master.hid_reports import Field, Section, parse_field, send_report
from teleop.errors import DeviceError

__all__ = ["PidReport", "PidConfig", "PidForce", "DEFAULT_REPORTS", "parse_pid"]

# name -> (kind, report id, length [bytes], {field: (byte offset, type)}, required fields)
DEFAULT_REPORTS: dict[str, tuple[str, int, int, dict[str, tuple[int, str]], tuple[str, ...]]] = {
    "device_control": ("output", 0x0C, 2, {"control": (1, "u8")}, ("control",)),
    "device_gain": ("output", 0x0D, 2, {"gain": (1, "u8")}, ("gain",)),
    "create_new_effect": ("feature", 0x11, 4, {"effect_type": (1, "u8"), "byte_count": (2, "u16")},
                          ("effect_type",)),
    "block_load": ("feature", 0x12, 5, {"block_index": (1, "u8"), "load_status": (2, "u8")},
                   ("block_index", "load_status")),
    "set_effect": ("output", 0x01, 16, {
        "block_index": (1, "u8"), "effect_type": (2, "u8"), "duration": (3, "u16"),
        "trigger_repeat": (5, "u16"), "sample_period": (7, "u16"), "gain": (9, "u8"),
        "trigger_button": (10, "u8"), "axes_enable": (11, "u8"), "direction": (12, "u8"),
        "start_delay": (14, "u16")}, ("block_index", "effect_type", "duration")),
    "set_constant_force": ("output", 0x05, 4, {"block_index": (1, "u8"), "magnitude": (2, "i16")},
                           ("block_index", "magnitude")),
    "effect_operation": ("output", 0x0A, 4, {"block_index": (1, "u8"), "operation": (2, "u8"),
                                             "loop_count": (3, "u8")}, ("block_index", "operation")),
}

# enumerated values (1-based indices into the PID 1.0 usage arrays), overridable under `values`
DEFAULT_VALUES: dict[str, int] = {
    "effect_type_constant": 1, "control_enable": 1, "control_disable": 2, "control_stop_all": 3,
    "control_reset": 4, "op_start": 1, "op_stop": 3, "load_success": 1, "duration_infinite": 0xFFFF,
    "loop_count": 1, "trigger_button": 0, "direction": 0, "axes_enable": 0x01, "gain": 255,
}


@dataclass(frozen=True)
class PidReport:
    """One PID report: ``kind`` (output | feature), id, length [bytes] and its fields."""

    kind: str
    report_id: int
    length: int
    fields: dict[str, Field]

    def build(self, **values: int) -> bytes:
        """The report bytes: id in byte 0, each named value at its field, zeros elsewhere.

        Values of fields this device's layout leaves out (configured as null) are dropped; a value
        outside the field's type range is clipped to it.
        """
        buf = bytearray(self.length)
        buf[0] = self.report_id
        for name, v in values.items():
            f = self.fields.get(name)
            if f is not None:
                lo, hi = f.raw_range
                f.pack_into(buf, int(min(max(v, lo), hi)))
        return bytes(buf)


@dataclass(frozen=True)
class PidConfig:
    """Settings of the PID force channel (``force.pid`` in a device file).

    Attributes
    ----------
    max_force : float
        Force [N] the device renders at ``|magnitude| = magnitude_max``; > 0.
    magnitude_max : int
        Logical maximum of the Set Constant Force magnitude (PID 1.0 examples: 10000).
    create_effect : bool
        Ask the device for a block index (Create New Effect + Block Load); False: use
        ``effect_block_index``.
    reset_on_start : bool
        Send Device Reset before Enable Actuators (clears effects left by a crashed run).
    device_gain : int or None
        Device Gain report value (0..255); None: do not send it.
    invert : bool
        Flip the sign (device axis opposite to the force axis).
    """

    max_force: float
    magnitude_max: int = 10000
    effect_block_index: int = 1
    create_effect: bool = True
    reset_on_start: bool = True
    device_gain: int | None = 255
    invert: bool = False
    values: dict[str, int] = field(default_factory=lambda: dict(DEFAULT_VALUES))
    reports: dict[str, PidReport] = field(default_factory=dict)

    def __post_init__(self):
        if not self.reports:
            object.__setattr__(self, "reports", {name: _default_report(name) for name in DEFAULT_REPORTS})


def _default_report(name: str) -> PidReport:
    kind, rid, length, fields, _ = DEFAULT_REPORTS[name]
    return PidReport(kind, rid, length, {k: Field(off, t) for k, (off, t) in fields.items()})


def _bool(sec: Section, name: str, default: bool) -> bool:
    v = sec.raw(name, default)
    if not isinstance(v, bool):
        raise sec.error(f"expected true or false, got {v!r}", name)
    return v


def _parse_report(sec: Section, name: str) -> PidReport:
    kind, rid, length, fields, required = DEFAULT_REPORTS[name]
    base = _default_report(name)
    out_fields = dict(base.fields)
    fs = sec.sub("fields", {})
    for fname in list(fs.data):
        if fname not in fields:
            raise fs.error(f"unknown field (expected one of: {', '.join(fields)})", str(fname))
        if fs.data[fname] is None:
            if fname in required:
                raise fs.error("this field is required", str(fname))
            fs.raw(fname)
            del out_fields[fname]
            continue
        f = parse_field(fs.sub(fname), si=False)
        if f.byte_offset < 1:
            raise fs.error("byte 0 holds the report id", f"{fname}.byte_offset")
        out_fields[fname] = f
    fs.done()
    needed = max(f.end for f in out_fields.values())
    rep = PidReport(kind=sec.choice("kind", ("output", "feature"), kind),
                    report_id=sec.int("report_id", rid, 1, 255),
                    length=sec.int("length", max(length, needed), 1, 4096), fields=out_fields)
    if rep.length < needed:
        raise sec.error(f"{rep.length} is shorter than the fields (need {needed} bytes)", "length")
    sec.done()
    return rep


def parse_pid(sec: Section) -> PidConfig:
    """A :class:`PidConfig` from the ``force.pid`` section of a device file (strict)."""
    vals = dict(DEFAULT_VALUES)
    vs = sec.sub("values", {})
    for k in list(vs.data):
        if k not in DEFAULT_VALUES:
            raise vs.error(f"unknown value (expected one of: {', '.join(DEFAULT_VALUES)})", str(k))
        vals[k] = vs.int(k, lo=0, hi=0xFFFF_FFFF)
    vs.done()
    reports = {}
    rs = sec.sub("reports", {})
    for k in list(rs.data):
        if k not in DEFAULT_REPORTS:
            raise rs.error(f"unknown report (expected one of: {', '.join(DEFAULT_REPORTS)})", str(k))
    for name in DEFAULT_REPORTS:
        reports[name] = _parse_report(rs.sub(name, {}), name)
    rs.done()
    cfg = PidConfig(
        max_force=sec.num("max_force", positive=True),
        magnitude_max=sec.int("magnitude_max", 10000, 1, 0x7FFF_FFFF),
        effect_block_index=sec.int("effect_block_index", 1, 1, 255),
        create_effect=_bool(sec, "create_effect", True),
        reset_on_start=_bool(sec, "reset_on_start", True),
        device_gain=sec.int("device_gain", 255, 0, 0xFFFF),
        invert=_bool(sec, "invert", False),
        values=vals, reports=reports)
    mag = reports["set_constant_force"].fields["magnitude"]
    if cfg.magnitude_max > mag.raw_range[1]:
        raise sec.error(f"{cfg.magnitude_max} does not fit the magnitude field ({mag.type})", "magnitude_max")
    sec.done()
    return cfg


class PidForce:
    """The PID force channel of an open hidapi handle (see the module docstring for the sequence).

    Parameters
    ----------
    cfg : PidConfig
    handle : hidapi ``hid.device``-like
        Needs ``write``, ``send_feature_report`` and, with ``create_effect``, ``get_feature_report``.
    limit : float
        Force clamp [N], > 0; the effective clamp is ``min(limit, cfg.max_force)``.

    Raises
    ------
    DeviceError
        From :meth:`start`, :meth:`write`, :meth:`stop`: a report was not sent (hidapi -1 / OSError /
        ValueError) or the device refused the effect (Block Load status not Success).
    """

    def __init__(self, cfg: PidConfig, handle: Any, limit: float):
        self.cfg, self.handle = cfg, handle
        self.limit = min(float(limit), cfg.max_force)
        self.block_index: int | None = None
        self.magnitude = 0           # last magnitude sent [logical units]

    def _send(self, name: str, **values: int) -> None:
        rep = self.cfg.reports[name]
        send_report(self.handle, rep.kind, rep.build(**values), f"PID {name.replace('_', ' ')}")

    def control(self, what: str) -> None:
        """Device Control report: ``what`` in enable, disable, stop_all, reset."""
        self._send("device_control", control=self.cfg.values[f"control_{what}"])

    def magnitude_for(self, force: float) -> int:
        """Constant-force magnitude for ``force`` [N]: NaN/inf -> 0; clamped to +-limit, then scaled."""
        if not math.isfinite(force):
            return 0
        f = min(max(float(force), -self.limit), self.limit)
        if self.cfg.invert:
            f = -f
        # magnitude = round(F / max_force * magnitude_max)
        m = int(round(f / self.cfg.max_force * self.cfg.magnitude_max))
        return max(-self.cfg.magnitude_max, min(self.cfg.magnitude_max, m))

    def _create_effect(self) -> int:
        v = self.cfg.values
        self._send("create_new_effect", effect_type=v["effect_type_constant"], byte_count=0)
        rep = self.cfg.reports["block_load"]
        try:
            data = bytes(self.handle.get_feature_report(rep.report_id, rep.length))
        except (OSError, ValueError) as e:
            raise DeviceError(f"PID block load report (id {rep.report_id}) not read: {e}") from None
        need = max(f.end for f in rep.fields.values())
        if len(data) < need or data[0] != rep.report_id:
            raise DeviceError(f"PID block load report malformed: got {data.hex(' ') or 'nothing'} "
                              f"(expected id {rep.report_id}, >= {need} bytes)")
        status = int(rep.fields["load_status"].unpack(data))
        index = int(rep.fields["block_index"].unpack(data))
        if status != v["load_success"] or index < 1:
            raise DeviceError(f"PID device refused the constant-force effect: block load status {status} "
                              f"(1 success, 2 pool full, 3 error), block index {index}")
        return index

    def start(self) -> None:
        """Enable the actuators and start a constant-force effect of magnitude 0."""
        v = self.cfg.values
        if self.cfg.reset_on_start:
            self.control("reset")
        self.control("enable")
        if self.cfg.device_gain is not None:
            self._send("device_gain", gain=self.cfg.device_gain)
        idx = self._create_effect() if self.cfg.create_effect else self.cfg.effect_block_index
        self._send("set_effect", block_index=idx, effect_type=v["effect_type_constant"],
                   duration=v["duration_infinite"], trigger_repeat=0, sample_period=0, gain=v["gain"],
                   trigger_button=v["trigger_button"], axes_enable=v["axes_enable"],
                   direction=v["direction"], start_delay=0)
        self._send("set_constant_force", block_index=idx, magnitude=0)
        self._send("effect_operation", block_index=idx, operation=v["op_start"], loop_count=v["loop_count"])
        self.block_index = idx
        self.magnitude = 0

    def write(self, force: float) -> None:
        """Stream ``force`` [N] as the effect's magnitude (Set Constant Force)."""
        if self.block_index is None:
            raise DeviceError("PID constant-force effect not started (call start() first)")
        m = self.magnitude_for(force)
        self._send("set_constant_force", block_index=self.block_index, magnitude=m)
        self.magnitude = m

    def stop(self) -> None:
        """Stop All Effects, then Disable Actuators; both are attempted, the first error is raised."""
        err: DeviceError | None = None
        for what in ("stop_all", "disable"):
            try:
                self.control(what)
            except DeviceError as e:
                err = err or e
        self.block_index = None
        if err is not None:
            raise err
