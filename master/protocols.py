"""The scripted operator's protocols: per axis, a list of proximal-tension targets on one of its tendons.

A segment says "move until the proximal tension of tendon ``side`` of this axis crosses ``target``"
(:class:`Segment`); a protocol is a list of them, one per axis of the instrument, run together by
:class:`master.simulated.ScriptedOperator`. The kinds of axis have their own protocols:

* a single tendon (one axis, side 0): :data:`PROTOCOLS` by name, concatenated by
  :func:`build_protocol` - ``paper`` (the seed paper's experiment), ``minor`` (minor loops),
  ``short`` (tests); markers :data:`MARKER_PAPER` = 1, :data:`MARKER_MINOR` = 2;
* an antagonistic pair (one axis per joint): :func:`paper_protocol` - the paper's experiment on
  tendon a, then on tendon b, each ending at the joint's set tension + 0.5 N - ``paper`` or
  ``short``; markers :data:`MARKER_PAPER_A`, :data:`MARKER_PAPER_B`.

The command marker tags every axis's segment in 4 bits: bits 4 k .. 4 k + 3 hold axis k's tag
(:func:`joint_marker`); a single tendon's marker is therefore its segment's marker. The marker is a
uint32 on the wire, so it tags the first :data:`MARKER_AXES` (8) axes; the axes of a larger instrument
beyond them run their segments untagged.
:func:`operator_protocols` picks the kind from the config.
"""
from __future__ import annotations

from dataclasses import dataclass

from teleop.config.schema import Config, joint_set_tension
from teleop.errors import ConfigError

__all__ = ["Segment", "PROTOCOLS", "build_protocol", "paper_protocol", "joint_protocols",
           "joint_marker", "experiment_label", "MARKER_AXES", "MARKER_PAPER", "MARKER_MINOR", "MARKER_PAPER_A",
           "MARKER_PAPER_B"]

MARKER_PAPER = 1
MARKER_MINOR = 2
MARKER_PAPER_A = 1
MARKER_PAPER_B = 2
#: Axes a command marker tags: 4 bits each in the wire's uint32 (teleop.wire.codec)
MARKER_AXES = 8


@dataclass(frozen=True)
class Segment:
    """One leg of a protocol: move until the proximal tension of tendon ``side`` (0: the single tendon
    or tendon a of a pair, + device motion; 1: tendon b, - device motion) crosses ``target`` [N] (>= 0);
    tag ``marker`` (0..15)."""

    target: float
    marker: int = 0
    side: int = 0


def joint_marker(marker: int, joint: int) -> int:
    """Axis (joint) ``joint``'s 4-bit tag in a command marker."""
    return (int(marker) >> (4 * joint)) & 0xF


def experiment_label(marker: int, axes: list[str] | tuple[str, ...]) -> str:
    """The experiment a command marker tags, as the live view and the recordings name it: ``none``; for a
    single tendon ``paper`` or ``minor``; for a joint instrument (several ``axes``) each tagged joint's
    ``paper_a`` / ``paper_b``, e.g. ``bend_ud paper_a``. An unknown tag is named by its number."""
    if not marker:
        return "none"
    if len(axes) <= 1:
        return {MARKER_PAPER: "paper", MARKER_MINOR: "minor"}.get(int(marker) & 0xF, f"marker {marker}")
    names = {MARKER_PAPER_A: "paper_a", MARKER_PAPER_B: "paper_b"}
    return ", ".join(f"{a} {names.get(tag, f'marker {tag}')}" for k, a in enumerate(axes)
                     if (tag := joint_marker(marker, k)))


def _segments(targets: tuple[float, ...], marker: int) -> tuple[Segment, ...]:
    return tuple(Segment(float(t), marker) for t in targets)


# "~0" is 0.3 N: the release ends where the tension is clearly gone without relying on noise.
PROTOCOLS: dict[str, tuple[Segment, ...]] = {
    # the seed paper's experiment: one full pull, one partial release, re-pull, release
    "paper": _segments((20.0, 5.0, 20.0, 0.3), MARKER_PAPER),
    # partial releases and re-pulls with reversals inside the 2K band (T_in0 e^-2K ~ 0.28 T_in0 at
    # K = 0.63), then a re-pull past the first peak: the "tension at the last reversal" rule keeps
    # T_out held until 9 e^2K ~ 32 N, the tendon's memory slips again from 16 N (docs/concepts/model.md, the
    # tension-profile memory)
    "minor": _segments((16.0, 10.0, 14.0, 7.0, 13.0, 9.0, 20.0, 4.0, 0.3), MARKER_MINOR),
    # a short protocol for tests
    "short": _segments((6.0, 2.0, 0.3), MARKER_PAPER),
}


def build_protocol(names: str) -> tuple[Segment, ...]:
    """A single tendon's protocol: named protocols concatenated, e.g. ``"paper,minor"``.

    Raises
    ------
    ConfigError
        An unknown name (the known ones are listed) or an empty list.
    """
    out: list[Segment] = []
    for name in filter(None, (n.strip() for n in names.split(","))):
        if name not in PROTOCOLS:
            raise ConfigError(f"protocol: unknown protocol {name!r} (expected one of {', '.join(PROTOCOLS)})")
        out.extend(PROTOCOLS[name])
    if not out:
        raise ConfigError(f"protocol: {names!r} names no protocol (expected e.g. 'paper,minor')")
    return tuple(out)


def paper_protocol(rest_tension: float, targets=(20.0, 5.0, 20.0)) -> tuple[Segment, ...]:
    """A pair's protocol: the paper's experiment on tendon a then on tendon b, each ending at
    ``rest_tension + 0.5`` N [N]."""
    out: list[Segment] = []
    for side, tag in ((0, MARKER_PAPER_A), (1, MARKER_PAPER_B)):
        out += [Segment(float(t), tag, side) for t in targets]
        out.append(Segment(float(rest_tension) + 0.5, tag, side))
    return tuple(out)


def joint_protocols(cfg: Config, names: str) -> list[tuple[Segment, ...]]:
    """One protocol per joint of ``cfg.instrument.joints``: ``paper`` (also ``paper,minor``: the seed
    paper's experiment on tendon a, then b) or ``short`` (6 N, 2 N each way), each ending at the
    joint's set tension + 0.5 N.

    Raises
    ------
    ConfigError
        Another protocol name.
    """
    name = "paper" if names.strip() in ("paper,minor", "paper") else names.strip()
    targets = {"paper": (20.0, 5.0, 20.0), "short": (6.0, 2.0)}.get(name)
    if targets is None:
        raise ConfigError(f"protocol: {names!r} is not a joint-instrument protocol (expected 'paper' or 'short')")
    return [paper_protocol(joint_set_tension(cfg, j), targets) for j in cfg.instrument.joints]
