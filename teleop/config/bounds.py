"""Hard bounds of the safety-relevant settings and their waiver (``safety.override``).

:data:`teleop.config.ranges.RANGES` says which values a setting can take at all; :data:`BOUNDS` says how far a
setting may go before the system stops keeping the promises it makes about the operator and the
instrument: the force on the hand, the time a stale link drives the instrument, the tension the slave
puts into the tendon. A loaded config (:func:`teleop.config.load.load_config`) with a value past its bound is
refused with one line naming the key, the value, the bound and its reason, unless the key is listed under
``safety.override``; a side then announces each waiver at start-up (:func:`waiver_lines`) and records it
in its stats (:func:`waivers`), and the demo's summary carries them too.

Each reason comes from the physics of the default instrument and device (configs/default.yaml) or from
what the fault suite measures (docs/concepts/safety.md: every fault reaches the safe state within 100 ms).
"""
from __future__ import annotations

import difflib
import logging
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any, Literal

from teleop.errors import ConfigError

__all__ = ["Bound", "BOUNDS", "REARM_FRACTION", "bounded_keys", "check_bounds", "waivers", "waiver_lines",
           "announce_waivers"]

#: The slave's tension trip ends only once every measured |T_in| is below this fraction of ``slave.max_tension``
#: (slave/node_base.py): a load cell's noise about the limit does not switch SAFE and READY from cycle to cycle.
REARM_FRACTION = 0.9


@dataclass(frozen=True)
class Bound:
    """One hard bound: ``key`` (dotted, ``[]`` for every list entry) must satisfy ``value <op> limit``."""

    key: str
    op: Literal["<=", ">=", "=="]
    limit: float | bool | str
    unit: str
    reason: str

    def holds(self, value: Any) -> bool:
        """Whether ``value`` is within the bound."""
        if self.op == "==":
            return bool(value == self.limit)
        return bool(value <= self.limit) if self.op == "<=" else bool(value >= self.limit)

    def describe(self) -> str:
        """``'above the hard bound 100 ms'`` and the like: how a value past the bound passes it."""
        if self.op == "==":
            return f"the hard bound is {str(self.limit).lower()}"
        side = "above" if self.op == "<=" else "below"
        return f"{side} the hard bound {self.limit:g} {self.unit}".rstrip()


_WATCHDOG = ("a stale {what} would {act} for longer than the 100 ms within which the fault suite brings "
             "every fault to the safe state (docs/concepts/safety.md: worst measured 61 ms)")
_TENSION = ("the slave pulls the tendon to this tension by itself; {limit} N is 0.3 % strain of the default "
            "tendon (EA 15 kN) and about a third of the breaking load of a steel cable of that stiffness "
            "(~0.4 mm, ~150 N)")

#: The hard bounds (docs/reference/safety-bounds.md renders this table).
BOUNDS: tuple[Bound, ...] = (
    Bound("master.mapping.force_limit", "<=", 10.0, "N",
          "10 N pushes a relaxed arm (100 N/m, the soft end of the arm stiffness) 0.1 m, which at motion scale "
          "0.2 moves the tendon 20 mm, the whole joint travel; desktop haptic devices render 3-12 N"),
    Bound("master.mapping.force_rate_limit", "<=", 1000.0, "N/s",
          "at 1000 N/s the force reaches the 10 N bound in 10 ms, well inside the ~100 ms a hand needs to "
          "react; a faster slew lets a force step reach the hand unshaped"),
    Bound("master.mapping.motion_scale", "<=", 1.0, "-",
          "above 1 the instrument moves more than the hand, amplifying the operator's tremor (8-12 Hz, "
          "0.1-0.5 mm) instead of scaling it down"),
    Bound("master.mapping.passivity", "==", True, "",
          "without the passivity controller a delayed link generates energy at the hand (-0.39 J at 20 ms "
          "each way, a growing oscillation, docs/concepts/safety.md)"),
    Bound("master.mapping.passivity_reserve", ">=", 0.004, "J",
          "while the reserve's gain fades the port can give back up to 4 N x 0.1 m/s x 10 ms = 4 mJ; a "
          "smaller reserve leaves it to the hard controller, which switches the force between full and "
          "damped from one sample to the next, a limit cycle on a light hand (docs/concepts/haptic-loop.md)"),
    Bound("master.watchdog_ms", "<=", 100.0, "ms",
          _WATCHDOG.format(what="estimate", act="keep rendering its force on the operator's hand")),
    Bound("slave.watchdog_ms", "<=", 100.0, "ms",
          _WATCHDOG.format(what="command", act="drive the instrument")),
    Bound("slave.heartbeat_hz", ">=", 30.0, "Hz",
          "a heartbeat is stale after 3 periods; below 30 Hz that is more than the 100 ms within which the "
          "fault suite brings every fault to the safe state"),
    Bound("master.max_tension", "<=", 1000.0, "N",
          "an estimate above 1000 N is not a surgical tendon's tension (a 1 mm steel cable breaks near "
          "1 kN); accepting it lets a corrupt estimate through to the force on the hand"),
    Bound("slave.max_tension", "<=", 100.0, "N",
          "the slave relaxes a tendon whose measured tension passes this limit; 100 N is two thirds of the "
          "breaking load of a steel cable of the default tendon's stiffness (~0.4 mm, ~150 N) and 0.7 % strain "
          "of the default tendon (EA 15 kN): a higher limit lets the slave hold a tendon near its break"),
    Bound("slave.max_step", "<=", 0.005, "m",
          "one command may move a tendon by this much at once; 5 mm is a quarter of the default joint's 20 mm "
          "travel, which the motor covers in 0.1 s at its 50 mm/s: a forged or corrupt command beyond it is a jump, "
          "not a motion of the hand (25 mm/s at most, 0.1 mm per 1 ms command at motion scale 0.2)"),
    Bound("slave.max_speed", "<=", 0.1, "m/s",
          "the followed target moves no faster than this; 0.1 m/s is twice the default motor's speed limit and 20 "
          "times the fastest hand motion at motion scale 0.2 (25 mm/s x 0.2): a faster target is not an operator's"),
    Bound("transport.auth.installation", "==", True, "",
          "without the installation's credentials any process that reaches the session (another user's on the "
          "same host, a peer on the network) links to the sides and can command the instrument and forge its "
          "estimates (docs/concepts/security.md)"),
    Bound("recording.rerun_serve.bind", "==", "127.0.0.1", "",
          "a served Rerun stream carries the whole live view (tensions, commands, the console's state, the "
          "run id) to anyone who reaches the port, without authentication or encryption; on loopback only "
          "this machine's users see it (docs/how-to/rerun-view.md)"),
    Bound("recording.rerun_serve.memory_limit", "<=", 1.0e9, "B",
          "a side's Rerun server keeps this much of the stream in the memory of the machine that runs the "
          "1 kHz loop; past 1 GB a long session pushes that machine toward swapping, and a loop that waits "
          "on a page fault misses its deadlines"),
    Bound("calibration.target_tension", "<=", 50.0, "N", _TENSION.format(limit=50)),
    Bound("sheath.pretension", "<=", 50.0, "N", _TENSION.format(limit=50)),
    Bound("instrument.joints[].pretension", "<=", 50.0, "N", _TENSION.format(limit=50)),
    Bound("pair_control.min_tension", "<=", 50.0, "N", _TENSION.format(limit=50)),
)


def bounded_keys() -> list[str]:
    """The dotted keys of :data:`BOUNDS`, in table order (the names ``safety.override`` accepts)."""
    return [b.key for b in BOUNDS]


def _values(obj: Any, key: str, prefix: str = "") -> Iterator[tuple[str, Any]]:
    """(indexed dotted path, value) of ``key`` in ``obj``; a ``[]`` segment runs over the list."""
    head, _, rest = key.partition(".")
    if head.endswith("[]"):
        for i, item in enumerate(getattr(obj, head[:-2])):
            path = f"{prefix}{head[:-2]}[{i}]"
            yield from _values(item, rest, path + ".") if rest else [(path, item)]
        return
    value = getattr(obj, head)
    if rest:
        yield from _values(value, rest, f"{prefix}{head}.")
    else:
        yield f"{prefix}{head}", value


def _show(value: Any) -> str:
    if isinstance(value, str):
        return value
    return str(value).lower() if isinstance(value, bool) else f"{value:g}"


def _check_override(cfg: Any, error: Callable[[str, str], ConfigError]) -> None:
    keys = bounded_keys()
    for i, name in enumerate(cfg.safety.override):
        if name not in keys:
            near = difflib.get_close_matches(name, keys, 1, 0.6)
            hint = f"did you mean '{near[0]}'?" if near else f"bounded keys: {', '.join(keys)}"
            raise error(f"safety.override[{i}]", f"safety.override[{i}]: '{name}' has no hard bound to "
                                                 f"waive ({hint})")


def _check_rest_below_limit(cfg: Any, error: Callable[[str, str], ConfigError]) -> None:
    """Refuse a ``slave.max_tension`` whose re-arm level is not above the tensions the slave relaxes to (a
    tension whose own bound is waived is left to the waiver)."""
    rest = [("sheath.pretension", "sheath.pretension", cfg.sheath.pretension)]
    for i, j in enumerate(cfg.instrument.joints):
        rest.append((f"instrument.joints[{i}].pretension", "instrument.joints[].pretension", j.pretension)
                    if j.pretension > 0 else ("pair_control.min_tension", "pair_control.min_tension",
                                              cfg.pair_control.min_tension))
    waived = set(cfg.safety.override)
    level = REARM_FRACTION * cfg.slave.max_tension
    for path, key, value in rest:
        if key not in waived and not value < level:
            raise error("slave.max_tension", f"slave.max_tension = {_show(cfg.slave.max_tension)}: a tension trip "
                                              f"ends below {REARM_FRACTION:g} of it ({level:g} N), not above {path} = "
                                              f"{_show(value)} N, the tension the slave relaxes to: it would stay SAFE")


def check_bounds(cfg: Any, error: Callable[[str, str], ConfigError]) -> None:
    """Refuse a value past its hard bound unless ``safety.override`` lists its key.

    Parameters
    ----------
    cfg : teleop.config.schema.Config
    error : callable
        ``error(dotted path, message)`` -> the ConfigError to raise (the loader adds file and line).

    Raises
    ------
    ConfigError
        ``slave.max_tension`` not above the tensions the slave relaxes to (:data:`REARM_FRACTION` of it
        at most), ``safety.override`` names a key without a bound, or a value is past its bound: one line
        ``<key> = <value>: above the hard bound <limit> <unit>: <reason> (...)``.
    """
    _check_override(cfg, error)
    waived = set(cfg.safety.override)
    for b in BOUNDS:
        if b.key in waived:
            continue
        for path, value in _values(cfg, b.key):
            if not b.holds(value):
                raise error(path, f"{path} = {_show(value)}: {b.describe()}: {b.reason} (to run past it "
                                  f"anyway, list '{b.key}' under safety.override)")
    _check_rest_below_limit(cfg, error)


def waivers(cfg: Any) -> list[dict]:
    """Each ``safety.override`` entry with its values and whether they pass the bound (for the stats).

    Returns
    -------
    list of dict
        ``{"key", "bound", "unit", "values": {path: value}, "past_bound": bool, "reason"}`` per entry.
    """
    out = []
    table = {b.key: b for b in BOUNDS}
    for name in cfg.safety.override:
        b = table.get(name)
        if b is None:
            continue
        values = dict(_values(cfg, b.key))
        out.append({"key": b.key, "bound": f"{b.op} {_show(b.limit)}", "unit": b.unit, "values": values,
                    "past_bound": any(not b.holds(v) for v in values.values()), "reason": b.reason})
    return out


def waiver_lines(cfg: Any) -> list[str]:
    """One line per waiver, as a side prints it at start-up."""
    lines = []
    for w in waivers(cfg):
        vals = ", ".join(f"{p} = {_show(v)}" for p, v in w["values"].items()) or "no entries"
        state = "PAST its hard bound" if w["past_bound"] else "within its hard bound"
        value, bound = f"{vals} {w['unit']}".rstrip(), f"{w['bound']} {w['unit']}".rstrip()
        lines.append(f"SAFETY WAIVER (safety.override): {value}, {state} {bound}: {w['reason']}".replace("  ", " "))
    return lines


def announce_waivers(cfg: Any, logger: logging.Logger) -> list[dict]:
    """Log every waiver as a warning (a side's start-up); returns :func:`waivers` for the stats."""
    for line in waiver_lines(cfg):
        logger.warning("%s", line)
    return waivers(cfg)
