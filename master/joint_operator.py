"""A scripted operator on a multi-axis haptic device: one hand axis per joint of a joint instrument.

Each axis runs its own protocol of tension targets on one tendon of its joint at a time, the way
:mod:`master.simulated` does for one tendon: it watches the proximal tension of the tendon named by
the current segment (in the latest JointEstimate, what a surgeon sees on the tension read-out),
moves its intended hand position at ``speed`` toward the target - + pulls tendon a, - pulls tendon
b - dwells at each reversal, and takes the next segment once the target is crossed. The rendered
force pushes the hand back through a human arm holding the device, one mass-damper-spring per axis
about the intended position (:mod:`master.arm`, as :mod:`master.simulated`).

The paper protocol on a joint is the seed paper's experiment on tendon a (pull to 20 N, release to
5 N, pull to 20 N, release to the set tension + 0.5 N), then the same on tendon b. All axes run
together. The command marker tags every joint's segment in 4 bits: bits 4 j .. 4 j + 3 of
:attr:`MultiAxisOperator.marker` hold joint j's tag (:data:`MARKER_PAPER_A`, :data:`MARKER_PAPER_B`
or 0 between segments).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from master.arm import ArmParameters, HumanArm
from master.device import MultiAxisState
from master.simulated import ClutchHand, approach
from teleop.config import Config, joint_set_tension
from teleop.errors import ConfigError

__all__ = ["AxisSegment", "MultiAxisState", "paper_protocol", "joint_protocols", "MultiAxisOperator", "MARKER_PAPER_A",
           "MARKER_PAPER_B", "joint_marker"]

MARKER_PAPER_A = 1
MARKER_PAPER_B = 2


def joint_marker(marker: int, joint: int) -> int:
    """Joint ``joint``'s 4-bit tag in a command marker."""
    return (int(marker) >> (4 * joint)) & 0xF


@dataclass(frozen=True)
class AxisSegment:
    """Move until tendon ``side`` (0 = a, 1 = b) of the axis's joint crosses ``target`` [N]; tag ``marker``."""

    side: int
    target: float
    marker: int = 0


def paper_protocol(rest_tension: float, targets=(20.0, 5.0, 20.0)) -> tuple[AxisSegment, ...]:
    """The paper's experiment on tendon a then on tendon b, each ending at ``rest_tension + 0.5`` N."""
    out = []
    for side, tag in ((0, MARKER_PAPER_A), (1, MARKER_PAPER_B)):
        out += [AxisSegment(side, float(t), tag) for t in targets]
        out.append(AxisSegment(side, float(rest_tension) + 0.5, tag))
    return tuple(out)


def joint_protocols(cfg: Config, names: str) -> list[tuple[AxisSegment, ...]]:
    """One axis protocol per joint of ``cfg.instrument.joints``: ``paper`` (also ``paper,minor``: the
    seed paper's experiment on tendon a, then b) or ``short`` (6 N, 2 N each way), each ending at the
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


class _Axis:
    def __init__(self, segments, speed, arm: ArmParameters, dwell, start_delay, timeout):
        self.segments, self.speed, self.k_arm, self.dwell = tuple(segments), speed, arm.stiffness, dwell
        self.arm = HumanArm(arm)
        self.start_delay, self.timeout = start_delay, timeout
        self.intended = self.force = self.velocity = 0.0
        self.index, self.direction, self.marker, self.timeouts = -1, 0, 0, 0
        self.finished = False
        self._wait: float | None = None
        self._t_seg = 0.0

    def advance(self, t: float, dt: float, T_in: tuple[float, float]) -> None:
        self.velocity = 0.0                      # intended hand speed [m/s], set below while moving
        if self.finished:
            return
        if self.index < 0 or self._wait is not None:
            if self._wait is None:
                self._wait = t + self.start_delay
            if t < self._wait:
                return
            self._wait = None
            if self.index + 1 >= len(self.segments):
                self.finished, self.direction, self.marker = True, 0, 0
                return
            self.index += 1
            seg = self.segments[self.index]
            self.marker, self._t_seg = seg.marker, t
            self.direction = 1 if seg.target > T_in[seg.side] else -1
            return
        seg = self.segments[self.index]
        T = T_in[seg.side]
        reached = T >= seg.target if self.direction > 0 else T <= seg.target
        if reached or t - self._t_seg > self.timeout:
            self.timeouts += 0 if reached else 1
            self.direction, self._wait, self.start_delay = 0, t + self.dwell, self.dwell
            return
        # + device motion pulls tendon a, - pulls b
        self.velocity = (1.0 if seg.side == 0 else -1.0) * self.direction * self.speed * approach(abs(seg.target - T))
        self.intended += self.velocity * dt


class MultiAxisOperator:
    """Scripted hands on a multi-axis device, one protocol per axis (module docstring).

    Parameters
    ----------
    protocols : sequence of sequence of AxisSegment
        One per axis (1..4).
    speed, arm_stiffness, dwell, start_delay, segment_timeout
        As :class:`master.simulated.ScriptedOperator` [m/s, N/m, s, s, s].
    arm : ArmParameters, optional
        Arm and device of every axis (:mod:`master.arm`); default ``ArmParameters(stiffness=arm_stiffness)``.
    clutch_bit, clutch_time
        As :class:`master.simulated.ScriptedOperator`: when the console asks to align, the operator
        holds the clutch button (bit ``clutch_bit``) for ``clutch_time`` [s] and lets go, which
        re-anchors every axis where the hands are.

    Raises
    ------
    ConfigError
        No axes, an empty protocol, a segment with a side other than 0/1 or a negative target, or a
        setting out of range.
    """

    def __init__(self, protocols, speed: float = 0.025, arm_stiffness: float = 300.0, dwell: float = 0.2,
                 start_delay: float = 0.5, segment_timeout: float = 15.0, clutch_bit: int = 1,
                 clutch_time: float = 0.05, arm: ArmParameters | None = None):
        protocols = [tuple(p) for p in protocols]
        if not protocols or any(not p for p in protocols):
            raise ConfigError("protocol: a multi-axis operator needs one non-empty protocol per axis")
        for p in protocols:
            for s in p:
                if s.side not in (0, 1) or not (math.isfinite(s.target) and s.target >= 0):
                    raise ConfigError(f"protocol: segment {s!r}: side must be 0 (a) or 1 (b), target >= 0 N")
        for name, v in (("speed", speed), ("arm_stiffness", arm_stiffness), ("segment_timeout", segment_timeout)):
            if not (math.isfinite(v) and v > 0):
                raise ConfigError(f"multi-axis operator: {name} must be a finite number > 0, got {v!r}")
        for name, v in (("dwell", dwell), ("start_delay", start_delay)):
            if not (math.isfinite(v) and v >= 0):
                raise ConfigError(f"multi-axis operator: {name} must be a finite number >= 0, got {v!r}")
        arm = arm or ArmParameters(stiffness=float(arm_stiffness))
        self.axes = [_Axis(p, float(speed), arm, float(dwell), float(start_delay),
                           float(segment_timeout)) for p in protocols]
        self._T: list[tuple[float, float]] | None = None
        self._engaged = False
        self._t_prev: float | None = None
        self.clutch = ClutchHand(clutch_bit, clutch_time)

    @property
    def n_axes(self) -> int:
        return len(self.axes)

    @property
    def finished(self) -> bool:
        return all(a.finished for a in self.axes)

    @property
    def timeouts(self) -> int:
        return sum(a.timeouts for a in self.axes)

    @property
    def marker(self) -> int:
        """Every axis's segment tag, 4 bits per joint (module docstring)."""
        return sum((a.marker & 0xF) << (4 * j) for j, a in enumerate(self.axes))

    def watch(self, T_in: list[tuple[float, float]] | None, engaged: bool) -> None:
        """Latest proximal tensions per joint, (T_in,a, T_in,b) [N] (None: none yet), and whether engaged."""
        ok = T_in is not None and len(T_in) == len(self.axes) and all(math.isfinite(v) for p in T_in for v in p)
        self._T = list(T_in) if ok else None
        self._engaged = bool(engaged)

    def on_console(self, status) -> None:
        """The console's status (:class:`master.console.ConsoleStatus`): ALIGN makes the operator clutch."""
        self.clutch.on_console(status)

    @property
    def clutches(self) -> int:
        """Clutch presses so far."""
        return self.clutch.count

    def read(self, t: float) -> MultiAxisState:
        """Advance every axis's script to ``t`` [s]; hand positions [m] and the clutch button."""
        dt = 0.0 if self._t_prev is None else max(0.0, t - self._t_prev)
        self._t_prev = t
        for a in self.axes:
            a.velocity = 0.0
        if self._engaged and self._T is not None:
            for a, T in zip(self.axes, self._T):
                a.advance(t, dt, T)
        buttons = self.clutch.buttons(t)
        # per axis: (m_a + m_d) dv/dt = k_a (p_i - p) + b_a (v_i - v) + F - b_d v - F_c sgn(v)
        pos = tuple(a.arm.step(dt, a.intended, a.velocity, a.force) for a in self.axes)
        return MultiAxisState(t=t, positions=pos, buttons=buttons)

    def set_forces(self, forces, t: float) -> None:
        """Render one force per axis [N] (non-finite: 0)."""
        for a, f in zip(self.axes, forces):
            a.force = float(f) if math.isfinite(f) else 0.0

    def close(self) -> None:
        for a in self.axes:
            a.force = 0.0
