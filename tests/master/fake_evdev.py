"""A fake of python-evdev's driver layer (list_devices, InputDevice, ecodes, ff) for the evdev device's tests:
scripted input events, every force-feedback call recorded. Codes are those of linux/input-event-codes.h."""
from __future__ import annotations

from collections import deque
from types import SimpleNamespace

_CODES = {"EV_SYN": 0, "EV_KEY": 1, "EV_ABS": 3, "EV_FF": 0x15, "ABS_X": 0, "ABS_Y": 1, "ABS_RZ": 5,
          "BTN_TRIGGER": 0x120, "BTN_THUMB": 0x121, "BTN_THUMB2": 0x122, "FF_CONSTANT": 0x52, "FF_GAIN": 0x60,
          "FF_AUTOCENTER": 0x61, "FF_RUMBLE": 0x50}
ecodes = SimpleNamespace(ecodes=dict(_CODES), **_CODES)


class _Struct(SimpleNamespace):
    pass


ff = SimpleNamespace(
    Envelope=lambda a, b, c, d: _Struct(attack_length=a, attack_level=b, fade_length=c, fade_level=d),
    Trigger=lambda button, interval: _Struct(button=button, interval=interval),
    Replay=lambda length, delay: _Struct(length=length, delay=delay),
    Constant=lambda level, env: _Struct(level=level, ff_envelope=env),
    EffectType=lambda ff_constant_effect: _Struct(ff_constant_effect=ff_constant_effect),
    Effect=lambda type, id, direction, trig, rep, u: _Struct(type=type, id=id, direction=direction, ff_trigger=trig,
                                                             ff_replay=rep, u=u),
)


class FakeInput:
    """One event device: capabilities, an axis range, an event queue; records uploads, writes, erases, closes."""

    def __init__(self, path: str, name: str, ff_codes=(0x52,), axis_range=(-32767, 32767), axes=(0,)):
        self.path, self.name = path, name
        self.ff_codes, self.axes = list(ff_codes), list(axes)
        self.range = axis_range
        self.events: deque = deque()
        self.uploads: list = []          # (id, level, direction, replay length) per upload
        self.writes: list = []           # (type, code, value)
        self.erased: list = []
        self.closes = 0
        self.unplugged = False
        self.refuse_upload = False

    def capabilities(self, absinfo: bool = True):
        info = SimpleNamespace(value=0, min=self.range[0], max=self.range[1])
        return {ecodes.EV_ABS: [(a, info) for a in self.axes], ecodes.EV_KEY: [0x120, 0x121],
                ecodes.EV_FF: self.ff_codes}

    def absinfo(self, code):
        return SimpleNamespace(value=0, min=self.range[0], max=self.range[1], fuzz=0, flat=0, resolution=0)

    def push(self, type_: int, code: int, value: int) -> None:
        self.events.append(SimpleNamespace(type=type_, code=code, value=value))

    def read_one(self):
        if self.unplugged:
            raise OSError(19, "No such device")
        return self.events.popleft() if self.events else None

    def upload_effect(self, effect) -> int:
        if self.unplugged or self.refuse_upload:
            raise OSError(28, "No space left on device")
        eid = 3 if effect.id == -1 else effect.id
        self.uploads.append((eid, effect.u.ff_constant_effect.level, effect.direction, effect.ff_replay.length))
        return eid

    def write(self, type_: int, code: int, value: int) -> None:
        if self.unplugged:
            raise OSError(19, "No such device")
        self.writes.append((type_, code, value))

    def erase_effect(self, eid: int) -> None:
        if self.unplugged:
            raise OSError(19, "No such device")
        self.erased.append(eid)

    def close(self) -> None:
        self.closes += 1


class FakeEvdev:
    """The module: ``list_devices``, ``InputDevice`` (the same FakeInput per path), ``ecodes``, ``ff``."""

    ecodes = ecodes
    ff = ff

    def __init__(self, *devices: FakeInput):
        self.devices = {d.path: d for d in devices}

    def list_devices(self):
        return list(self.devices)

    def InputDevice(self, path):  # noqa: N802 - python-evdev's name
        if path not in self.devices:
            raise OSError(2, "No such file")
        return self.devices[path]
