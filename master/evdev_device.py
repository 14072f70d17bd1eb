"""A force-feedback joystick or wheel through Linux kernel force feedback (evdev), with python-evdev.

This is how a USB HID PID device (and most force-feedback wheels) is driven on Linux: the kernel's
``hid-pidff`` (or the vendor's) driver turns force-feedback effects uploaded to the event device
(``/dev/input/eventN``) into the device's reports. The device here uploads one ``FF_CONSTANT`` effect
and updates its level and direction on every change of the rendered force:

* force -> effect: ``level = round(|F| / force.max_force * 0x7fff)`` (clipped), direction
  ``force.direction`` for a positive force and the opposite one (``+ 0x8000``) for a negative force
  (the kernel's convention, Documentation/input/ff.rst: 0x4000 "left", 0xC000 "right"; which of them
  pushes the handle toward + on its axis depends on the driver, so ``force.direction`` is a setting);
* the effect's replay length is ``force.hold_ms`` and it is played again every ``hold_ms / 2``: a
  master that stops updating it (a hung process) loses its force after at most ``hold_ms``, in the
  kernel, with no help from user space;
* position: ``EV_ABS`` events of ``input.position_axis`` mapped linearly from the axis range to
  ``+-input.travel`` [m] (``invert`` flips it); buttons: ``EV_KEY`` events of ``input.buttons`` (bit i =
  i-th listed button held); ``input.presence_button`` held is the deadman (none: always present);
* safety: the force is clamped to ``force.limit`` and a NaN renders zero; a read or write error marks
  the device lost (operator absent, zero force and stop attempted, :class:`DeviceError`); :meth:`close`
  writes zero, stops and erases the effect and releases the device, once.

The device file (``master.device.file``, optional: without one, the first event device that has
``FF_CONSTANT`` and the defaults below)::

    name: my wheel
    match: {path: /dev/input/by-id/usb-...-event-joystick}    # or {name: "substring"}; none: first FF device
    input: {position_axis: ABS_X, travel: 0.035, invert: false, buttons: [BTN_TRIGGER], presence_button: null}
    force: {limit: 4.0, max_force: 8.0, direction: 0xC000, hold_ms: 200, gain: 1.0, autocenter: 0.0}

The driver layer (``evdev``: ``list_devices``, ``InputDevice``, ``ecodes``, ``ff``) is injected, so
tests run the master through a fake of it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from master.device import DeviceState
from teleop.config.reader import read_yaml
from teleop.errors import ConfigError, DeviceError

__all__ = ["EvdevConfig", "EvdevDevice", "parse_evdev", "load_evdev_file", "evdev_module", "ff_devices", "LEVEL_MAX"]

LEVEL_MAX = 0x7FFF
MAX_EVENTS = 512        # events drained per read at most


def evdev_module() -> Any:
    """python-evdev (``import evdev``).

    Raises
    ------
    DeviceError
        Not installed: one line naming the extra to install.
    """
    try:
        import evdev
    except ImportError:
        raise DeviceError("master.device.type evdev needs python-evdev: pip install 'tsm-teleop[evdev]' "
                          "(Linux only)") from None
    return evdev


@dataclass(frozen=True)
class EvdevConfig:
    """The evdev device file (module docstring); units SI, direction in Linux FF units (0..0xFFFF)."""

    name: str = "evdev force-feedback device"
    path: str | None = None
    match_name: str | None = None
    position_axis: str = "ABS_X"
    travel: float = 0.035
    invert: bool = False
    buttons: tuple[str, ...] = ("BTN_TRIGGER", "BTN_THUMB")
    presence_button: str | None = None
    limit: float = 4.0
    max_force: float = 8.0
    direction: int = 0xC000
    hold_ms: int = 200
    gain: float = 1.0
    autocenter: float = 0.0


def _positive(src: str, key: str, v: Any) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v > 0):
        raise ConfigError(f"{src}: {key}: expected a number > 0, got {v!r}")
    return float(v)


def _unit(src: str, key: str, v: Any) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0.0 <= v <= 1.0:
        raise ConfigError(f"{src}: {key}: expected a number in [0, 1], got {v!r}")
    return float(v)


def parse_evdev(data: Any, source: str = "<dict>") -> EvdevConfig:
    """An :class:`EvdevConfig` from the device file's mapping (missing keys keep their defaults).

    Raises
    ------
    ConfigError
        A key of the wrong type or out of range, or an unknown key (named with the file).
    """
    data = data or {}
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: expected a mapping with match, input, force")
    unknown = set(data) - {"name", "match", "input", "force", "type"}
    m, i, f = (data.get(k) or {} for k in ("match", "input", "force"))
    for sec, allowed, d in (("match", {"path", "name"}, m),
                            ("input", {"position_axis", "travel", "invert", "buttons", "presence_button"}, i),
                            ("force", {"limit", "max_force", "direction", "hold_ms", "gain", "autocenter"}, f)):
        if not isinstance(d, dict):
            raise ConfigError(f"{source}: {sec}: expected a mapping")
        unknown |= {f"{sec}.{k}" for k in set(d) - allowed}
    if unknown:
        raise ConfigError(f"{source}: unknown key(s) {', '.join(sorted(unknown))}")
    d0 = EvdevConfig()
    direction = f.get("direction", d0.direction)
    if isinstance(direction, bool) or not isinstance(direction, int) or not 0 <= direction <= 0xFFFF:
        raise ConfigError(f"{source}: force.direction: expected an integer 0..0xFFFF, got {direction!r}")
    buttons = i.get("buttons", d0.buttons)
    if not isinstance(buttons, (list, tuple)) or not all(isinstance(b, str) for b in buttons):
        raise ConfigError(f"{source}: input.buttons: expected a list of key names (BTN_...), got {buttons!r}")
    return EvdevConfig(
        name=str(data.get("name", d0.name)), path=m.get("path"), match_name=m.get("name"),
        position_axis=str(i.get("position_axis", d0.position_axis)),
        travel=_positive(source, "input.travel", i.get("travel", d0.travel)), invert=bool(i.get("invert", False)),
        buttons=tuple(buttons), presence_button=i.get("presence_button"),
        limit=_positive(source, "force.limit", f.get("limit", d0.limit)),
        max_force=_positive(source, "force.max_force", f.get("max_force", d0.max_force)), direction=direction,
        hold_ms=int(_positive(source, "force.hold_ms", f.get("hold_ms", d0.hold_ms))),
        gain=_unit(source, "force.gain", f.get("gain", d0.gain)),
        autocenter=_unit(source, "force.autocenter", f.get("autocenter", d0.autocenter)))


def load_evdev_file(path: str | Path | None) -> EvdevConfig:
    """Read an evdev device file (None: the defaults).

    Raises
    ------
    ConfigError
        Unreadable, not YAML, or a wrong key (:func:`parse_evdev`).
    """
    if path is None:
        return EvdevConfig()
    data = read_yaml(Path(path), hex_integers=True)[0]     # bounded: size, nesting, aliases (teleop/config/reader.py)
    return parse_evdev(data, str(path))


def ff_devices(ev: Any) -> list[tuple[str, str, bool]]:
    """``(path, name, has FF_CONSTANT)`` of every event device the user may open, sorted by path."""
    out = []
    for path in sorted(ev.list_devices()):
        try:
            d = ev.InputDevice(path)
        except OSError:
            continue
        try:
            ff = d.capabilities().get(ev.ecodes.EV_FF, [])
            out.append((path, str(d.name), ev.ecodes.FF_CONSTANT in ff))
        finally:
            d.close()
    return out


class EvdevDevice:
    """One-axis haptic device over Linux force feedback (module docstring).

    Parameters
    ----------
    cfg : EvdevConfig
    ev : module, optional
        python-evdev or a fake of it (default: :func:`evdev_module`).

    Raises
    ------
    DeviceError
        No matching device, no FF_CONSTANT, the position axis missing, or the effect refused (named).
    """

    def __init__(self, cfg: EvdevConfig, ev: Any = None):
        self.cfg, self.ev = cfg, ev if ev is not None else evdev_module()
        codes = self.ev.ecodes.ecodes
        for key, name in [("input.position_axis", cfg.position_axis)] + [("input.buttons", b) for b in cfg.buttons] \
                + ([("input.presence_button", cfg.presence_button)] if cfg.presence_button else []):
            if name not in codes:
                raise ConfigError(f"{cfg.name}: {key}: {name!r} is not an evdev code name (ABS_X, BTN_TRIGGER, ...)")
        self.axis = codes[cfg.position_axis]
        self.buttons = {codes[b]: i for i, b in enumerate(cfg.buttons)}
        self.presence = codes[cfg.presence_button] if cfg.presence_button else None
        self.dev = self._open()
        self.label = f"{cfg.name} ({self.dev.path})"
        info = self.dev.absinfo(self.axis)
        self.center, self.half = 0.5 * (info.max + info.min), 0.5 * (info.max - info.min) or 1.0
        self.raw, self.held, self.force, self.lost, self.closed = info.value, 0, 0.0, False, False
        self.present_raw = False              # the deadman button: released until an event says held
        self.effect_id: int | None = None
        self._level = (0, cfg.direction)
        self._played = -math.inf
        self._start()

    def _open(self) -> Any:
        ev, cfg = self.ev, self.cfg
        found = [(p, n, ok) for p, n, ok in ff_devices(ev) if (cfg.path is None or p == cfg.path)
                 and (cfg.match_name is None or cfg.match_name in n)]
        usable = [x for x in found if x[2]]
        if not usable:
            what = cfg.path or (f"name containing {cfg.match_name!r}" if cfg.match_name else "any event device")
            why = "it has no FF_CONSTANT effect" if found else "none found (plugged in? readable? see `teleop devices`)"
            raise DeviceError(f"{cfg.name}: no force-feedback device for {what}: {why}")
        dev = ev.InputDevice(usable[0][0])
        if self.axis not in [c for c, _ in dev.capabilities(absinfo=True).get(ev.ecodes.EV_ABS, [])]:
            dev.close()
            raise DeviceError(f"{cfg.name} ({usable[0][0]}): no axis {cfg.position_axis} (input.position_axis)")
        return dev

    def _effect(self, level: int, direction: int) -> Any:
        ff, c = self.ev.ff, self.ev.ecodes
        env = ff.Envelope(0, 0, 0, 0)
        return ff.Effect(c.FF_CONSTANT, -1 if self.effect_id is None else self.effect_id, direction,
                         ff.Trigger(0, 0), ff.Replay(self.cfg.hold_ms, 0),
                         ff.EffectType(ff_constant_effect=ff.Constant(level, env)))

    def _start(self) -> None:
        c = self.ev.ecodes
        try:
            self.dev.write(c.EV_FF, c.FF_AUTOCENTER, int(round(self.cfg.autocenter * 0xFFFF)))
            self.dev.write(c.EV_FF, c.FF_GAIN, int(round(self.cfg.gain * 0xFFFF)))
            self.effect_id = self.dev.upload_effect(self._effect(0, self.cfg.direction))
        except OSError as e:
            self.dev.close()
            self.closed = True
            raise DeviceError(f"{self.label}: the FF_CONSTANT effect was refused: {e}") from None

    # ---- the HapticDevice protocol -------------------------------------------------------------------
    def read(self, t: float) -> DeviceState:
        """Drain the pending events; the latest position [m], buttons and deadman at ``t`` [s].

        Raises
        ------
        DeviceError
            Closed or lost, or the read failed (the device is then lost: zero force, effect stopped).
        """
        if self.closed or self.lost:
            raise DeviceError(f"{self.label}: the device was {'closed' if self.closed else 'lost'}")
        c = self.ev.ecodes
        try:
            for _ in range(MAX_EVENTS):
                e = self.dev.read_one()
                if e is None:
                    break
                if e.type == c.EV_ABS and e.code == self.axis:
                    self.raw = e.value
                elif e.type == c.EV_KEY:
                    if e.code in self.buttons:
                        bit = 1 << self.buttons[e.code]
                        self.held = self.held | bit if e.value else self.held & ~bit
                    if e.code == self.presence:
                        self.present_raw = bool(e.value)
        except OSError as err:
            self._lose(f"read failed ({err})")
        return self.state(t)

    def state(self, t: float) -> DeviceState:
        """The last reading at ``t`` [s] without reading (operator absent once lost or closed)."""
        u = (self.raw - self.center) / self.half
        present = not (self.lost or self.closed) and (self.presence is None or self.present_raw)
        return DeviceState(t, (-1.0 if self.cfg.invert else 1.0) * self.cfg.travel * u, self.held, present)

    def set_force(self, force: float, t: float) -> None:
        """Render ``force`` [N] (clamped to ``force.limit``, NaN -> 0) from ``t`` [s]; no-op when lost or closed.

        Raises
        ------
        DeviceError
            The update was refused (the device is then lost).
        """
        if self.closed or self.lost:
            return
        f = 0.0 if not math.isfinite(force) else max(-self.cfg.limit, min(self.cfg.limit, float(force)))
        try:
            self._render(f, t)
        except OSError as err:
            self._lose(f"force not sent ({err})")

    def _render(self, f: float, t: float) -> None:
        level = min(LEVEL_MAX, int(round(abs(f) / self.cfg.max_force * LEVEL_MAX)))
        direction = self.cfg.direction if f >= 0 else (self.cfg.direction + 0x8000) & 0xFFFF
        if (level, direction) != self._level:
            self.dev.upload_effect(self._effect(level, direction))     # same id: the playing effect changes
            self._level = (level, direction)
        if t - self._played >= 0.5e-3 * self.cfg.hold_ms:
            self.dev.write(self.ev.ecodes.EV_FF, self.effect_id, 1)     # (re)play: hold_ms more
            self._played = t
        self.force = f

    def close(self) -> None:
        """Zero force, stop and erase the effect, release the device; once, whatever happened before."""
        if self.closed:
            return
        if not self.lost:
            self._stop()
        self.closed = True
        try:
            self.dev.close()
        except OSError:
            pass

    def __enter__(self) -> EvdevDevice:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _stop(self) -> None:
        """Zero level, stop playing, erase the effect; each step tried even when one before it fails."""
        steps = [lambda: self.dev.upload_effect(self._effect(0, self.cfg.direction)),
                 lambda: self.dev.write(self.ev.ecodes.EV_FF, self.effect_id, 0),
                 lambda: self.dev.erase_effect(self.effect_id)]
        for step in steps:
            try:
                step()
            except OSError:
                pass
        self.force, self._level = 0.0, (0, self.cfg.direction)

    def _lose(self, reason: str) -> None:
        self._stop()
        self.lost = True
        raise DeviceError(f"{self.label}: device lost: {reason}")
