"""A scripted operator: a simulated surgeon's hand on a simulated haptic device, one hand axis per
instrument axis.

Each axis follows its own *protocol* (:mod:`master.protocols`), a list of proximal-tension targets
on one tendon of the axis at a time ("pull until T_in reaches 20 N, then release until 5 N, ..."):
a single tendon has one axis, a joint instrument one per antagonistic pair (+ device motion pulls
tendon a, - pulls tendon b). The axis watches the T_in of the tendon named by its segment in the
latest Estimate (what a surgeon sees on the endoscope and the tension read-out), moves its intended
hand position at a set speed toward the target, stops when the read-out carried on at its rate for the
hand's lag crosses the target, dwells briefly, and goes on to the next segment, or pulls on in the same
one when the read-out never came within ``APPROACH_BAND`` of the target (a rate that collapsed at the
end of a capstan dead zone, where the tension moves fast and the tip does not); all axes run
together and the operator is finished when every axis is. The hand is not a position source: it is a
human arm as haptics models it, a mass-damper-spring about the intended position holding a device
with its own mass and friction, one per axis (:mod:`master.arm`; Hogan 1985, Tsuji et al. 1995)::

    (m_a + m_d) dv/dt = k_a (p_intended - p) + b_a (v_intended - v) + F_rendered - b_d v - F_c sgn(v)

so the master's force feedback acts on the motion it commands, as with a real hand. ``static_arm``
keeps the first model, a massless spring ``p = p_intended + F / k_arm``, for comparisons only: with
it the passivity controller's force steps become position steps and the loop chatters
(docs/concepts/haptic-loop.md).

When the console asks to align (after a fault the hand has moved, or the slave relaxed) the
operator clutches: it holds the clutch button (``clutch_bit``) for ``clutch_time`` and lets go, which
re-anchors the map of every axis (:mod:`master.console`); it presses the deadman all the time.

Each segment carries a marker, which the master sends in ``Command.marker`` (4 bits per axis,
:func:`master.protocols.joint_marker`) so the recordings can be cut per experiment.
"""
from __future__ import annotations

import logging
import math
from typing import Any

from master.arm import ArmParameters, HumanArm
from master.clutch_hand import ClutchHand
from master.device import DeviceState, MultiAxisState
from master.protocols import MARKER_AXES, Segment
from teleop.errors import ConfigError

__all__ = ["AxisScript", "ScriptedOperator"]

log = logging.getLogger("teleop.master")

#: Tension error [N] below which the operator slows its intention, and the slowest fraction of speed.
APPROACH_BAND, APPROACH_MIN = 1.0, 0.15
#: Smoothing time of the read-out rate the operator anticipates with [s].
RATE_TIME = 0.01


def approach(error: float) -> float:
    """Fraction of the set speed at ``error`` [N] from the target: 1 beyond APPROACH_BAND, down to
    APPROACH_MIN at the target (an operator slows down as the read-out nears the target)."""
    return min(1.0, max(APPROACH_MIN, error / APPROACH_BAND))


class AxisScript:
    """One axis of the scripted operator: its protocol and the arm holding its device axis.

    Parameters
    ----------
    segments : sequence of Segment, the axis's protocol (not empty).
    speed : float, intended hand speed [m/s].
    arm : ArmParameters, the arm and device axis.
    static_arm : bool, the massless spring instead (comparisons only).
    dwell, start_delay, segment_timeout : float [s], as :class:`ScriptedOperator`.

    Attributes
    ----------
    intended, velocity : the intended hand position [m] and speed [m/s].
    force : the rendered force [N].
    index : current segment, -1 before the start. direction : +1 raising the watched tension, -1
    lowering it, 0 still. marker : the current (or last) segment's. finished, timeouts.
    events : list of dict, one per stop: ``segment`` (1-based), ``side`` (0 = a, 1 = b), ``target`` [N],
    ``t_start``, ``t_end`` [s] (the device's clock), ``T_in`` (the reading [N]) and ``T_seen`` (the reading
    carried on at its rate for the hand's lag [N]) at the stop, ``reached`` (False: ``segment_timeout``),
    ``resumed`` (the reading never came within APPROACH_BAND of the target through the segment and its
    dwell, and the segment went on); each is also logged.
    name : str, the axis's name in those log lines.
    """

    def __init__(self, segments, speed: float, arm: ArmParameters, static_arm: bool, dwell: float,
                 start_delay: float, segment_timeout: float):
        self.segments = tuple(segments)
        self.max_side = max(s.side for s in self.segments)     # the watched tendons an estimate must have
        self.speed, self.dwell, self.start_delay, self.segment_timeout = speed, dwell, start_delay, segment_timeout
        self.k_arm = arm.stiffness
        self.arm = HumanArm(arm)
        self.static_arm = static_arm
        # the hand lags its intention by ~(b_a + b_d) / k_a seconds: the operator anticipates that much
        self._lead = 0.0 if static_arm else (arm.damping + arm.device_damping) / arm.stiffness   # [s]
        self.intended = self.velocity = self.force = 0.0
        self.index, self.direction, self.marker, self.timeouts = -1, 0, 0, 0
        self.finished = False
        self._T_last: float | None = None
        self._t_read = 0.0                       # when the watched reading last changed [s]
        self._rate = 0.0                         # smoothed dT_in/dt of the watched tendon [N/s]
        self._wait_until: float | None = None    # start delay / dwell end [s]
        self._t_segment = 0.0
        self._sense = 0                          # the current segment's direction: +1 raising its tension, -1 lowering
        self._reached = False                    # the segment stopped as reached, until its dwell ends
        self._peak = 0.0                         # [N] the reading nearest the segment's target so far
        self.events: list[dict[str, Any]] = []
        self.name = "axis"

    def position(self, dt: float) -> float:
        """The hand's position after ``dt`` [s] under the rendered force [m]."""
        if self.static_arm:
            # p_hand = p_intended + F / k_arm   (massless spring)
            return self.intended + self.force / self.k_arm
        # (m_a + m_d) dv/dt = k_a (p_i - p) + b_a (v_i - v) + F - b_d v - F_c sgn(v)
        return self.arm.step(dt, self.intended, self.velocity, self.force)

    def advance(self, t: float, dt: float, T_in: tuple[float, ...]) -> None:
        """Advance the script to ``t`` [s] seeing the axis's proximal tensions ``T_in`` [N] (one per tendon)."""
        self.velocity = 0.0                      # intended hand speed [m/s], set below while moving
        if self.finished:
            return
        side = self.segments[max(self.index, 0)].side
        self._read_rate(t, T_in[side])
        T = T_in[side]
        if self.index >= 0 and self._sense * (T - self._peak) > 0.0:
            self._peak = T
        if self.index < 0 or self._wait_until is not None:     # waiting to start, or dwelling after a segment
            if self._wait_until is None:
                self._wait_until = t + self.start_delay
            if t < self._wait_until:
                return
            self._wait_until = None
            if self._short_of_target(T):
                return
            if self.index + 1 >= len(self.segments):
                self.finished, self.direction = True, 0
                return
            self._start(self.index + 1, t, T_in)
            return
        seg = self.segments[self.index]
        # the operator anticipates: it stops the intention when the read-out, carried on at its present
        # rate for the hand's lag, reaches the target (a person stops early when the read-out moves fast)
        T_seen = T + self._rate * self._lead
        reached = T_seen >= seg.target if self.direction > 0 else T_seen <= seg.target
        if reached or t - self._t_segment > self.segment_timeout:
            self.timeouts += 0 if reached else 1
            self._ended(seg, t, T, T_seen, reached)
            self._reached = reached
            self.direction = 0
            self._wait_until = t + self.dwell
            return
        # slow down near the target (a hand with mass lags its intention: stopping at full speed would
        # carry the tendon on by ~b v / k of hand travel, several newtons where the tendon sticks);
        # + device motion pulls tendon a (side 0), - pulls tendon b
        sign = 1.0 if seg.side == 0 else -1.0
        self.velocity = sign * self.direction * self.speed * approach(abs(seg.target - T_seen))
        self.intended += self.velocity * dt

    def _short_of_target(self, T: float) -> bool:
        """After a segment's dwell: whether the read-out never came within APPROACH_BAND of the target the
        operator stopped for, through the segment and its dwell (the anticipation misjudged a rate that
        collapsed, e.g. a capstan dead zone ending); if so the operator pulls on in the same segment, its
        timeout still counting. A reading that reached the band and then relaxed (friction that grows with
        speed letting go at rest) is not pulled on again. ``T``: the reading now [N], for the log."""
        if not self._reached:           # before the first segment, after a timeout and once a segment starts
            return False
        target = self.segments[self.index].target
        if self._sense * (target - self._peak) <= APPROACH_BAND:
            return False
        self.direction, self._reached = self._sense, False
        self._T_last, self._rate = None, 0.0
        self.events[-1]["resumed"] = True
        log.info("operator %s: segment %d/%d: T_in came to %.2f N and settled at %.2f N, short of %g N: pulling on",
                 self.name, self.index + 1, len(self.segments), self._peak, T, target)
        return True

    def _ended(self, seg: Segment, t: float, T: float, T_seen: float, reached: bool) -> None:
        """Record and log the end of the current segment at ``t`` [s] with the reading ``T`` and ``T_seen`` [N]."""
        ev = {"segment": self.index + 1, "side": seg.side, "target": seg.target, "t_start": self._t_segment,
              "t_end": t, "T_in": T, "T_seen": T_seen, "reached": bool(reached), "resumed": False}
        self.events.append(ev)
        log.info("operator %s: segment %d/%d (tendon %s to %g N) %s at clock %.3f s after %.3f s: T_in %.2f N, "
                 "seen %.2f N", self.name, ev["segment"], len(self.segments), "ab"[seg.side], seg.target,
                 "reached" if reached else "timed out", t, t - self._t_segment, T, T_seen)

    def _read_rate(self, t: float, T: float) -> None:
        """Update the read-out rate [N/s], smoothed over RATE_TIME, from the watched tension ``T`` [N] at ``t`` [s].

        The rate is the change between two successive different readings over the time between them:
        estimates that arrive late and then together (a stalled link or slave) read as the motion they
        carry, not as a jump in one cycle. An unchanged reading leaves the rate as it is."""
        if self._T_last is None:
            self._T_last, self._t_read = T, t
            return
        span = t - self._t_read
        if T == self._T_last or span <= 0.0:
            return
        self._rate += span / (RATE_TIME + span) * ((T - self._T_last) / span - self._rate)
        self._T_last, self._t_read = T, t

    def _start(self, index: int, t: float, T_in: tuple[float, ...]) -> None:
        seg = self.segments[index]
        self._T_last, self._rate = None, 0.0          # a segment starts after a pause: the rate is read anew
        self.index, self.marker, self._t_segment = index, seg.marker, t
        self._reached = False
        self.direction = self._sense = 1 if seg.target > T_in[seg.side] else -1
        self._peak = T_in[seg.side]


def _per_axis(protocols) -> list[tuple[Segment, ...]]:
    """One protocol (a sequence of Segment: one axis) or one per axis, as a list of tuples."""
    protocols = tuple(protocols)
    if protocols and all(isinstance(s, Segment) for s in protocols):
        return [protocols]
    return [tuple(p) for p in protocols]


class ScriptedOperator:
    """A :class:`~master.device.HapticDevice` and :class:`~master.device.OperatorView` driven by a
    script, one hand axis per instrument axis (module docstring).

    Parameters
    ----------
    protocols : sequence of Segment (one axis), or one such sequence per axis (1..16)
        Each axis's protocol, executed in order (:mod:`master.protocols`).
    speed : float
        Intended hand speed along the device axis [m/s], > 0.
    arm_stiffness : float
        Arm stiffness k_a [N/m], > 0, used when ``arm`` is None.
    arm : ArmParameters, optional
        The arm and device of every axis (:mod:`master.arm`); default ``ArmParameters(stiffness=arm_stiffness)``.
    static_arm : bool
        The massless spring ``p = p_intended + F / k_a`` instead (comparisons only; module docstring).
    dwell : float
        Pause at each reversal [s], >= 0.
    start_delay : float
        Wait after control is engaged before the first segment [s], >= 0 (lets the force ramp in).
    segment_timeout : float
        Give up a segment that has not reached its target after this long [s], > 0 (counted in
        ``timeouts``; the script goes on with the next one).
    clutch_bit, clutch_time
        When the console asks to align, the operator holds the clutch button (bit ``clutch_bit``; < 0:
        never) for ``clutch_time`` [s] and lets go, which re-anchors every axis where the hands are.

    Attributes
    ----------
    axes : list of AxisScript
    finished : bool
        Every axis has executed its whole protocol.
    marker : int
        Every axis's segment tag, 4 bits per axis (a single tendon: its segment's marker).
    timeouts : int
        Segments abandoned after ``segment_timeout``.

    Raises
    ------
    ConfigError
        No axes or an empty protocol, a segment with a side other than 0/1 or a negative target, or a
        setting out of range (named).
    """

    def __init__(self, protocols, speed: float = 0.025, arm_stiffness: float = 300.0, dwell: float = 0.2,
                 start_delay: float = 0.5, segment_timeout: float = 15.0, clutch_bit: int = 1,
                 clutch_time: float = 0.05, arm: ArmParameters | None = None, static_arm: bool = False):
        per_axis = _per_axis(protocols)
        if not per_axis or any(not p for p in per_axis):
            raise ConfigError("protocol: a scripted operator needs at least one segment on every axis")
        for p in per_axis:
            for seg in p:
                if seg.side not in (0, 1) or not (math.isfinite(seg.target) and seg.target >= 0):
                    raise ConfigError(f"protocol: segment {seg!r}: side must be 0 or 1, target a finite number >= 0 N")
        for name, v, zero_ok in (("speed", speed, False), ("arm_stiffness", arm_stiffness, False),
                                 ("dwell", dwell, True), ("start_delay", start_delay, True),
                                 ("segment_timeout", segment_timeout, False)):
            if not (math.isfinite(v) and (v >= 0 if zero_ok else v > 0)):
                raise ConfigError(f"scripted operator: {name} must be a finite number "
                                  f"{'>= 0' if zero_ok else '> 0'}, got {v!r}")
        self.arm_params = arm or ArmParameters(stiffness=float(arm_stiffness))
        self.static_arm = bool(static_arm)
        self.axes = [AxisScript(p, float(speed), self.arm_params, self.static_arm, float(dwell), float(start_delay),
                                float(segment_timeout)) for p in per_axis]
        for k, a in enumerate(self.axes):
            a.name = str(k)
        self.segments = per_axis[0]
        self.k_arm = self.arm_params.stiffness
        self._T: list[tuple[float, ...]] | None = None
        self._engaged = False
        self._t_prev: float | None = None
        self.clutch = ClutchHand(clutch_bit, clutch_time)

    # -- the instrument's axes ---------------------------------------------------------------------
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
    def segment_events(self) -> list[list[dict[str, Any]]]:
        """Per axis, the ended segments (:attr:`AxisScript.events`)."""
        return [list(a.events) for a in self.axes]

    @property
    def marker(self) -> int:
        """The segment tag of every axis up to :data:`master.protocols.MARKER_AXES`, 4 bits per axis
        (:func:`master.protocols.joint_marker`)."""
        return sum((a.marker & 0xF) << (4 * k) for k, a in enumerate(self.axes[:MARKER_AXES]))

    # the first axis's script (a single tendon's), for logs, tests and benchmarks
    @property
    def index(self) -> int:
        return self.axes[0].index

    @property
    def direction(self) -> int:
        return self.axes[0].direction

    @property
    def intended(self) -> float:
        return self.axes[0].intended

    @property
    def force(self) -> float:
        return self.axes[0].force

    # -- OperatorView ------------------------------------------------------------------------------
    def on_console(self, status) -> None:
        """The console's status (:class:`master.console.ConsoleStatus`): ALIGN makes the operator clutch."""
        self.clutch.on_console(status)

    @property
    def clutches(self) -> int:
        """Clutch presses so far."""
        return self.clutch.count

    def watch(self, T_in: Any, engaged: bool) -> None:
        """Latest proximal tensions [N] and whether control is engaged: per axis a tuple (the single
        tendon's, or tendon a's and b's), or one float for a one-axis operator; None (or anything
        non-finite or of another shape): none yet."""
        if isinstance(T_in, (int, float)):
            T_in = [(T_in,)]
        seen = None if T_in is None else [tuple(v) if isinstance(v, (tuple, list)) else (v,) for v in T_in]
        ok = (seen is not None and len(seen) == len(self.axes)
              and all(len(v) > a.max_side and all(math.isfinite(x) for x in v)
                      for v, a in zip(seen, self.axes, strict=False)))
        self._T = [tuple(float(x) for x in v) for v in seen] if ok and seen is not None else None
        self._engaged = bool(engaged)

    # -- HapticDevice ------------------------------------------------------------------------------
    def read(self, t: float) -> Any:
        """Advance every axis's script to ``t`` [s]; the hand position [m] (a DeviceState for one axis,
        a MultiAxisState for several) and the clutch button."""
        dt = 0.0 if self._t_prev is None else max(0.0, t - self._t_prev)
        self._t_prev = t
        for a in self.axes:
            a.velocity = 0.0
        if self._engaged and self._T is not None:
            for a, T in zip(self.axes, self._T, strict=False):
                a.advance(t, dt, T)
        buttons = self.clutch.buttons(t)
        pos = tuple(a.position(dt) for a in self.axes)
        if len(pos) == 1:
            return DeviceState(t=t, position=pos[0], buttons=buttons)
        return MultiAxisState(t=t, positions=pos, buttons=buttons)

    def set_force(self, force: float, t: float) -> None:
        """Render ``force`` [N] on the first axis (non-finite: 0)."""
        self.set_forces([force], t)

    def set_forces(self, forces, t: float) -> None:
        """Render one force per axis [N] (non-finite: 0)."""
        for a, f in zip(self.axes, forces, strict=False):
            a.force = float(f) if math.isfinite(f) else 0.0

    def close(self) -> None:
        for a in self.axes:
            a.force = 0.0

    @property
    def progress(self) -> str:
        """Human-readable position in the script, for logs."""
        def one(a: AxisScript) -> str:
            if a.finished:
                return "done"
            if a.index < 0:
                return "waiting"
            return f"segment {a.index + 1}/{len(a.segments)} -> {a.segments[a.index].target:g} N"
        return "; ".join(one(a) for a in self.axes)
