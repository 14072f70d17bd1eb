"""HID report maps: where each value sits in a report, and its conversion to and from SI units.

A report map is read from YAML (a ``configs/devices/*.yaml`` file). Byte offsets count from the
first byte of the buffer hidapi hands over or takes: for input, that is the report id when the
device numbers its reports (``report_id`` set) and the first data byte otherwise; for output and
feature reports it is always the report id (``0`` for a device that does not number its reports),
as ``hid.device.write`` and ``send_feature_report`` expect.

Conversions (a *field*: ``byte_offset``, ``type``, ``endian``, ``scale``, ``offset``)::

    input   value [SI] = raw * scale + offset                  e.g. counts -> m
    output  raw        = round(value [SI] * scale + offset)    e.g. N -> counts

Types: ``u8 i8 u16 i16 u32 i32 f32``, ``endian: little | big`` (default little).

Decoding never raises on device data: a short report, a wrong report id or a non-finite float is
rejected, counted in :attr:`InputMap.rejected` by reason, and ``None`` is returned.
"""
from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field
from typing import Any

from teleop.errors import ConfigError, DeviceError

__all__ = ["TYPES", "Field", "InputMap", "InputSample", "OutputMap", "Section", "parse_int",
           "parse_field", "parse_input", "parse_output", "send_report"]

# struct code, size [bytes], raw minimum, raw maximum
TYPES: dict[str, tuple[str, int, float, float]] = {
    "u8": ("B", 1, 0, 0xFF), "i8": ("b", 1, -0x80, 0x7F),
    "u16": ("H", 2, 0, 0xFFFF), "i16": ("h", 2, -0x8000, 0x7FFF),
    "u32": ("I", 4, 0, 0xFFFF_FFFF), "i32": ("i", 4, -0x8000_0000, 0x7FFF_FFFF),
    "f32": ("f", 4, -3.4028234663852886e38, 3.4028234663852886e38),
}
_ENDIAN = {"little": "<", "big": ">"}


class Section:
    """Strict reader of one YAML mapping: every key must be taken, leftovers are errors.

    ``where`` is ``"<file>: <dotted.path>"``; every :class:`ConfigError` names it.
    """

    def __init__(self, data: Any, source: str, path: str):
        self.source, self.path = source, path
        if data is None:
            data = {}
        if not isinstance(data, dict):
            raise self.error(f"expected a mapping, got {type(data).__name__}")
        self.data = dict(data)
        self._taken: set[str] = set()

    def key(self, name: str) -> str:
        return f"{self.path}.{name}" if self.path else name

    def error(self, msg: str, name: str | None = None) -> ConfigError:
        where = self.key(name) if name is not None else (self.path or "top level")
        return ConfigError(f"{self.source}: {where}: {msg}")

    def has(self, name: str) -> bool:
        return name in self.data

    def raw(self, name: str, default: Any = ...) -> Any:
        self._taken.add(name)
        if name not in self.data:
            if default is ...:
                raise self.error("missing key", name)
            return default
        return self.data[name]

    def sub(self, name: str, default: Any = ...) -> Section:
        return Section(self.raw(name, default), self.source, self.key(name))

    def int(self, name: str, default: Any = ..., lo: int | None = None, hi: int | None = None) -> Any:
        v = self.raw(name, default)
        if v is None:
            return None
        return parse_int(v, self, name, lo, hi)

    def num(self, name: str, default: Any = ..., positive: bool = False) -> float:
        v = self.raw(name, default)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise self.error(f"expected a finite number, got {v!r}", name)
        if positive and v <= 0:
            raise self.error(f"expected a number > 0, got {v!r}", name)
        return float(v)

    def choice(self, name: str, choices: tuple[str, ...], default: Any = ...) -> str:
        v = self.raw(name, default)
        if v not in choices:
            raise self.error(f"expected one of {', '.join(choices)}, got {v!r}", name)
        return v

    def done(self) -> None:
        """Raise on the first key nobody took (unknown key)."""
        for k in self.data:
            if k not in self._taken:
                known = ", ".join(sorted(self._taken))
                raise self.error(f"unknown key (expected one of: {known})", str(k))


def parse_int(v: Any, sec: Section, name: str, lo: int | None = None, hi: int | None = None) -> int:
    """An integer given as an int or a string (``"0x1A2B"``, ``"0b101"``, ``"42"``), in ``[lo, hi]``."""
    if isinstance(v, str):
        try:
            v = int(v.strip(), 0)
        except ValueError:
            raise sec.error(f"expected an integer (e.g. 42 or \"0x2a\"), got {v!r}", name) from None
    if isinstance(v, bool) or not isinstance(v, int):
        raise sec.error(f"expected an integer, got {v!r}", name)
    if (lo is not None and v < lo) or (hi is not None and v > hi):
        raise sec.error(f"{v} is out of range [{lo}, {hi}]", name)
    return v


@dataclass(frozen=True)
class Field:
    """One value in a report: position, binary type, and linear conversion (see module docstring)."""

    byte_offset: int
    type: str = "u8"
    endian: str = "little"
    scale: float = 1.0
    offset: float = 0.0

    @property
    def size(self) -> int:
        return TYPES[self.type][1]

    @property
    def end(self) -> int:
        return self.byte_offset + self.size

    @property
    def raw_range(self) -> tuple[float, float]:
        return TYPES[self.type][2], TYPES[self.type][3]

    def _fmt(self) -> str:
        return _ENDIAN[self.endian] + TYPES[self.type][0]

    def unpack(self, data: bytes) -> int | float:
        """The raw value at :attr:`byte_offset` (``data`` must be long enough)."""
        return struct.unpack_from(self._fmt(), data, self.byte_offset)[0]

    def pack_into(self, buf: bytearray, raw: int | float) -> None:
        """Write ``raw`` (already within :attr:`raw_range`) at :attr:`byte_offset`."""
        struct.pack_into(self._fmt(), buf, self.byte_offset, raw)

    def to_si(self, raw: float) -> float:
        # value [SI] = raw * scale + offset
        return raw * self.scale + self.offset

    def to_raw(self, value: float, lo: float | None = None, hi: float | None = None) -> int | float:
        """``round(value * scale + offset)`` clipped to ``[lo, hi]`` and to the type's range."""
        # raw = value * scale + offset
        raw = value * self.scale + self.offset
        tlo, thi = self.raw_range
        lo = tlo if lo is None else max(lo, tlo)
        hi = thi if hi is None else min(hi, thi)
        raw = min(max(raw, lo), hi)
        return float(raw) if self.type == "f32" else int(round(raw))


def parse_field(sec: Section, *, si: bool = True, more: bool = False) -> Field:
    """A :class:`Field` from a YAML mapping; ``si=False`` forbids ``scale``/``offset`` (raw fields).

    Unknown keys are errors unless ``more`` (the caller reads further keys, then calls ``done``).
    """
    f = Field(
        byte_offset=sec.int("byte_offset", lo=0, hi=4095),
        type=sec.choice("type", tuple(TYPES), "u8"),
        endian=sec.choice("endian", tuple(_ENDIAN), "little"),
        scale=sec.num("scale", 1.0) if si else 1.0,
        offset=sec.num("offset", 0.0) if si else 0.0,
    )
    if f.scale == 0.0:
        raise sec.error("scale must not be 0", "scale")
    if not more:
        sec.done()
    return f


@dataclass(frozen=True)
class InputSample:
    """One decoded input report: axes [SI], button bit mask, presence (None: no presence switch)."""

    axes: dict[str, float]
    buttons: int
    present: bool | None


@dataclass
class InputMap:
    """Decoder of the device's input report (position axes, buttons, presence switch).

    ``buttons`` is a field plus ``masks``: bit ``i`` of :attr:`InputSample.buttons` is set when
    ``raw & masks[i]`` is non-zero. ``presence`` is a field plus ``mask`` and ``active_low``.
    """

    report_id: int | None
    axes: dict[str, Field]
    position_axis: str
    # several device axes (one per instrument axis); () = (position_axis,)
    position_axes: tuple[str, ...] = ()
    buttons: Field | None = None
    button_masks: tuple[int, ...] = ()
    presence: Field | None = None
    presence_mask: int = 1
    presence_active_low: bool = False
    read_size: int = 64
    rejected: dict[str, int] = field(default_factory=lambda: {"short": 0, "wrong_id": 0, "non_finite": 0})
    accepted: int = 0

    @property
    def length(self) -> int:
        """Minimum report length [bytes] that holds every field."""
        ends = [f.end for f in self.axes.values()]
        ends += [f.end for f in (self.buttons, self.presence) if f is not None]
        return max(ends + [1 if self.report_id is not None else 0])

    def decode(self, data: bytes | bytearray | list[int]) -> InputSample | None:
        """Decode one report; ``None`` (and a count in :attr:`rejected`) when it is malformed."""
        data = bytes(data)
        if self.report_id is not None and (not data or data[0] != self.report_id):
            self.rejected["short" if not data else "wrong_id"] += 1
            return None
        if len(data) < self.length:
            self.rejected["short"] += 1
            return None
        axes = {}
        for name, f in self.axes.items():
            v = f.to_si(f.unpack(data))
            if not math.isfinite(v):
                self.rejected["non_finite"] += 1
                return None
            axes[name] = v
        buttons = 0
        if self.buttons is not None:
            raw = int(self.buttons.unpack(data))
            for i, m in enumerate(self.button_masks):
                if raw & m:
                    buttons |= 1 << i
        present = None
        if self.presence is not None:
            on = bool(int(self.presence.unpack(data)) & self.presence_mask)
            present = on != self.presence_active_low
        self.accepted += 1
        return InputSample(axes, buttons, present)


def parse_input(sec: Section) -> InputMap:
    """An :class:`InputMap` from the ``input`` section of a device file.

    Keys of the section that belong to the caller must be read (``sec.raw``) before this call:
    it ends with :meth:`Section.done`, which rejects every key not read.
    """
    axes_sec = sec.sub("axes")
    if not axes_sec.data:
        raise axes_sec.error("expected at least one axis")
    axes = {}
    for name in list(axes_sec.data):
        axes[str(name)] = parse_field(axes_sec.sub(name))
    axes_sec.done()
    listed = sec.raw("position_axes", None)
    if listed is not None and (not isinstance(listed, list) or not listed or len(set(map(str, listed))) != len(listed)
                               or any(str(a) not in axes for a in listed)):
        raise sec.error(f"expected a list of distinct axes out of ({', '.join(axes)}), got {listed!r}", "position_axes")
    position_axis = sec.raw("position_axis", str(listed[0]) if listed else next(iter(axes)))
    if position_axis not in axes:
        raise sec.error(f"{position_axis!r} is not one of the axes ({', '.join(axes)})", "position_axis")
    m = InputMap(report_id=sec.int("report_id", None, 0, 255), axes=axes, position_axis=position_axis,
                 position_axes=tuple(str(a) for a in listed) if listed else (position_axis,),
                 read_size=sec.int("read_size", 64, 1, 4096))
    if sec.has("buttons"):
        b = sec.sub("buttons")
        m.buttons = parse_field(b, si=False, more=True)
        masks = b.raw("masks")
        if not isinstance(masks, list) or not masks:
            raise b.error("expected a non-empty list of bit masks", "masks")
        m.button_masks = tuple(parse_int(x, b, f"masks[{i}]", 1, 0xFFFF_FFFF) for i, x in enumerate(masks))
        b.done()
    else:
        sec.raw("buttons", None)
    if sec.has("presence"):
        p = sec.sub("presence")
        m.presence = parse_field(p, si=False, more=True)
        m.presence_mask = p.int("mask", 1, 1, 0xFFFF_FFFF)
        active_low = p.raw("active_low", False)
        if not isinstance(active_low, bool):
            raise p.error(f"expected true or false, got {active_low!r}", "active_low")
        m.presence_active_low = active_low
        p.done()
    else:
        sec.raw("presence", None)
    if m.length > m.read_size:
        raise sec.error(f"fields reach byte {m.length} but read_size is {m.read_size}", "read_size")
    sec.done()
    return m


@dataclass(frozen=True)
class OutputMap:
    """Encoder of a vendor force report (``kind`` output or feature).

    ``limit`` [N] clamps the force; ``raw_min``/``raw_max`` clamp the encoded value (default: the
    type's range). ``fixed`` bytes (e.g. a command code) are written into every report.
    """

    kind: str
    report_id: int
    force: Field
    limit: float
    length: int
    raw_min: float | None = None
    raw_max: float | None = None
    fixed: tuple[tuple[Field, int], ...] = ()

    def encode(self, force: float) -> bytes:
        """The report for ``force`` [N]: NaN/inf -> 0, clamped to ``[-limit, limit]``, then to raw."""
        f = 0.0 if not math.isfinite(force) else min(max(float(force), -self.limit), self.limit)
        buf = bytearray(self.length)
        buf[0] = self.report_id
        for fld, value in self.fixed:
            fld.pack_into(buf, value)
        self.force.pack_into(buf, self.force.to_raw(f, self.raw_min, self.raw_max))
        return bytes(buf)


def parse_output(sec: Section, limit: float) -> OutputMap:
    """An :class:`OutputMap` from the ``force.report`` section; ``limit`` [N] from ``force.limit``."""
    kind = sec.choice("kind", ("output", "feature"), "output")
    rid = sec.int("report_id", 0, 0, 255)
    force = parse_field(sec.sub("field"))
    if force.byte_offset < 1:
        raise sec.error("byte 0 holds the report id", "field.byte_offset")
    lo, hi = force.raw_range
    raw_min = sec.int("raw_min", None) if force.type != "f32" else sec.num("raw_min", lo)
    raw_max = sec.int("raw_max", None) if force.type != "f32" else sec.num("raw_max", hi)
    for name, v in (("raw_min", raw_min), ("raw_max", raw_max)):
        if v is not None and not lo <= v <= hi:
            raise sec.error(f"{v} is outside the {force.type} range [{lo}, {hi}]", name)
    if raw_min is not None and raw_max is not None and raw_min > raw_max:
        raise sec.error(f"raw_min {raw_min} > raw_max {raw_max}", "raw_min")
    fixed = []
    fixed_list = sec.raw("fixed", [])
    if not isinstance(fixed_list, list):
        raise sec.error("expected a list of {byte_offset, type, value}", "fixed")
    for i, item in enumerate(fixed_list):
        fs = Section(item, sec.source, sec.key(f"fixed[{i}]"))
        fld = parse_field(fs, si=False, more=True)
        if fld.byte_offset < 1:
            raise fs.error("byte 0 holds the report id", "byte_offset")
        flo, fhi = fld.raw_range
        fixed.append((fld, fs.int("value", lo=int(flo), hi=int(fhi))))
        fs.done()
    needed = max([force.end] + [f.end for f, _ in fixed])
    length = sec.int("length", needed, 1, 4096)
    if length < needed:
        raise sec.error(f"{length} is shorter than the fields (need {needed} bytes)", "length")
    sec.done()
    return OutputMap(kind, rid, force, limit, length, raw_min, raw_max, tuple(fixed))


def send_report(handle: Any, kind: str, data: bytes, what: str) -> None:
    """Send an output (``write``) or feature (``send_feature_report``) report through a hidapi handle.

    Raises
    ------
    DeviceError
        hidapi returned -1 or raised (OSError: I/O error, ValueError: handle not open); ``what``
        names the report in the message.
    """
    try:
        n = handle.write(data) if kind == "output" else handle.send_feature_report(data)
    except (OSError, ValueError) as e:
        raise DeviceError(f"HID {what} report (id {data[0]}) not sent: {e}") from None
    if isinstance(n, int) and n < 0:
        raise DeviceError(f"HID {what} report (id {data[0]}) not sent: hidapi returned {n} (unplugged?)")
