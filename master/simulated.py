"""A scripted operator: a simulated surgeon's hand on a simulated haptic device.

The operator follows a *protocol*, a list of proximal-tension targets ("pull until T_in reaches
20 N, then release until 5 N, ..."). It watches the T_in echoed in the latest Estimate (what a
surgeon sees on the endoscope and the tension read-out), moves its intended hand position at a set
speed toward the next target, dwells briefly at each reversal, and goes on to the next segment when
the target is crossed. The hand is not a position source: it is a human arm as haptics models it, a
mass-damper-spring about the intended position holding a device with its own mass and friction
(:mod:`master.arm`; Hogan 1985, Tsuji et al. 1995)::

    (m_a + m_d) dv/dt = k_a (p_intended - p) + b_a (v_intended - v) + F_rendered - b_d v - F_c sgn(v)

so the master's force feedback acts on the motion it commands, as with a real hand. ``static_arm``
keeps the first model, a massless spring ``p = p_intended + F / k_arm``, for comparisons only: with
it the passivity controller's force steps become position steps and the loop chatters
(docs/stability.md).

When the console asks to align (after a fault the hand has moved, or the slave relaxed) the
operator clutches: it holds the clutch button (``clutch_bit``) for ``clutch_time`` and lets go, which
re-anchors the map (:mod:`master.console`); it presses the deadman all the time.

Each segment carries a marker (1 = paper experiment, 2 = minor-loop experiment), which the master
sends in ``Command.marker`` so the recordings can be cut per experiment.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from master.arm import ArmParameters, HumanArm
from master.device import DeviceState
from teleop.errors import ConfigError

__all__ = ["Segment", "PROTOCOLS", "build_protocol", "ClutchHand", "ScriptedOperator"]

MARKER_PAPER = 1
MARKER_MINOR = 2


@dataclass(frozen=True)
class Segment:
    """One leg of a protocol: move until the proximal tension crosses ``target`` [N] (>= 0)."""

    target: float
    marker: int = 0


def _segments(targets: tuple[float, ...], marker: int) -> tuple[Segment, ...]:
    return tuple(Segment(float(t), marker) for t in targets)


# "~0" is 0.3 N: the release ends where the tension is clearly gone without relying on noise.
PROTOCOLS: dict[str, tuple[Segment, ...]] = {
    # the seed paper's experiment: one full pull, one partial release, re-pull, release
    "paper": _segments((20.0, 5.0, 20.0, 0.3), MARKER_PAPER),
    # partial releases and re-pulls with reversals inside the 2K band (T_in0 e^-2K ~ 0.28 T_in0 at
    # K = 0.63), then a re-pull past the first peak: the "tension at the last reversal" rule keeps
    # T_out held until 9 e^2K ~ 32 N, the tendon's memory slips again from 16 N (literature.md s. 0)
    "minor": _segments((16.0, 10.0, 14.0, 7.0, 13.0, 9.0, 20.0, 4.0, 0.3), MARKER_MINOR),
    # a short protocol for tests
    "short": _segments((6.0, 2.0, 0.3), MARKER_PAPER),
}


def build_protocol(names: str) -> tuple[Segment, ...]:
    """Concatenate named protocols, e.g. ``"paper,minor"``.

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


#: Tension error [N] below which the operator slows its intention, and the slowest fraction of speed.
APPROACH_BAND, APPROACH_MIN = 1.0, 0.15
#: Smoothing time of the read-out rate the operator anticipates with [s].
RATE_TIME = 0.01


def approach(error: float) -> float:
    """Fraction of the set speed at ``error`` [N] from the target: 1 beyond APPROACH_BAND, down to
    APPROACH_MIN at the target (an operator slows down as the read-out nears the target)."""
    return min(1.0, max(APPROACH_MIN, error / APPROACH_BAND))


class ClutchHand:
    """The scripted hand's clutch button: when the console asks to align (status ALIGN), the hand
    presses button ``bit`` for ``hold`` [s] and lets go, which re-anchors the master where the hand
    is. A negative ``bit``: the hand never clutches. ``count`` is the number of presses."""

    def __init__(self, bit: int, hold: float):
        self.bit, self.hold = int(bit), float(hold)
        self.count = 0
        self._wanted = False
        self._until: float | None = None    # [s] end of the press under way

    def on_console(self, status) -> None:
        """ALIGN asks for one press (not while one is under way)."""
        if getattr(status, "name", status) == "ALIGN" and self._until is None and self.bit >= 0:
            self._wanted = True

    def buttons(self, t: float) -> int:
        """The button bits at time ``t`` [s]: ``1 << bit`` while pressed, else 0."""
        if self._wanted:
            self._wanted, self._until = False, t + self.hold
            self.count += 1
        if self._until is not None:
            if t < self._until:
                return 1 << self.bit
            self._until = None
        return 0


class ScriptedOperator:
    """A :class:`~master.device.HapticDevice` and :class:`~master.device.OperatorView` driven by a script.

    Parameters
    ----------
    segments : sequence of Segment
        The protocol, executed in order.
    speed : float
        Intended hand speed along the device axis [m/s], > 0.
    arm_stiffness : float
        Arm stiffness k_a [N/m], > 0, used when ``arm`` is None.
    arm : ArmParameters, optional
        The arm and device (:mod:`master.arm`); default ``ArmParameters(stiffness=arm_stiffness)``.
    static_arm : bool
        The massless spring ``p = p_intended + F / k_a`` instead (comparisons only; module docstring).
    dwell : float
        Pause at each reversal [s], >= 0.
    start_delay : float
        Wait after control is engaged before the first segment [s], >= 0 (lets the force ramp in).
    segment_timeout : float
        Give up a segment that has not reached its target after this long [s], > 0 (counted in
        ``timeouts``; the script goes on with the next one).

    Attributes
    ----------
    finished : bool
        The whole protocol has been executed.
    marker : int
        Marker of the current segment (the one moving, or the one just finished while dwelling).
    timeouts : int
        Segments abandoned after ``segment_timeout``.
    """

    def __init__(self, segments, speed: float = 0.025, arm_stiffness: float = 300.0, dwell: float = 0.2,
                 start_delay: float = 0.5, segment_timeout: float = 15.0, clutch_bit: int = 1,
                 clutch_time: float = 0.05, arm: ArmParameters | None = None, static_arm: bool = False):
        self.segments = tuple(segments)
        if not self.segments:
            raise ConfigError("protocol: a scripted operator needs at least one segment")
        for name, v, zero_ok in (("speed", speed, False), ("arm_stiffness", arm_stiffness, False),
                                 ("dwell", dwell, True), ("start_delay", start_delay, True),
                                 ("segment_timeout", segment_timeout, False)):
            if not (math.isfinite(v) and (v >= 0 if zero_ok else v > 0)):
                raise ConfigError(f"scripted operator: {name} must be a finite number "
                                  f"{'>= 0' if zero_ok else '> 0'}, got {v!r}")
        self.speed, self.dwell = float(speed), float(dwell)
        self.arm_params = arm or ArmParameters(stiffness=float(arm_stiffness))
        self.k_arm = self.arm_params.stiffness
        self.arm = HumanArm(self.arm_params)
        self.static_arm = bool(static_arm)
        self.start_delay, self.segment_timeout = float(start_delay), float(segment_timeout)
        self.intended = 0.0          # [m]
        self.velocity = 0.0          # intended speed [m/s]
        self._T_last: float | None = None
        self._rate = 0.0             # smoothed dT_in/dt [N/s]
        a = self.arm_params
        self._lead = 0.0 if static_arm else (a.damping + a.device_damping) / a.stiffness   # [s]
        self.force = 0.0             # rendered force [N]
        self.index = -1              # current segment; -1 before the start
        self.direction = 0           # +1 pulling, -1 releasing, 0 still
        self.marker = 0
        self.finished = False
        self.timeouts = 0
        self._T_in: float | None = None
        self._engaged = False
        self._t_prev: float | None = None
        self._wait_until: float | None = None   # start delay / dwell end [s]
        self._t_segment = 0.0
        self.clutch = ClutchHand(clutch_bit, clutch_time)

    # -- OperatorView ------------------------------------------------------------------------------
    def on_console(self, status) -> None:
        """The console's status (:class:`master.console.ConsoleStatus`): ALIGN makes the operator clutch."""
        self.clutch.on_console(status)

    @property
    def clutches(self) -> int:
        """Clutch presses so far."""
        return self.clutch.count

    def watch(self, T_in: float | None, engaged: bool) -> None:
        """Latest proximal tension [N] (None: none yet) and whether control is engaged."""
        self._T_in = T_in if T_in is None or math.isfinite(T_in) else None
        self._engaged = bool(engaged)

    # -- HapticDevice ------------------------------------------------------------------------------
    def read(self, t: float) -> DeviceState:
        """Advance the script to time ``t`` [s] and return the hand position."""
        dt = 0.0 if self._t_prev is None else max(0.0, t - self._t_prev)
        self._t_prev = t
        self.velocity = 0.0
        if self._engaged and not self.finished and self._T_in is not None:
            self._advance(t, dt, self._T_in)
        buttons = self.clutch.buttons(t)
        if self.static_arm:
            # p_hand = p_intended + F / k_arm   (massless spring)
            p = self.intended + self.force / self.k_arm
        else:
            # (m_a + m_d) dv/dt = k_a (p_i - p) + b_a (v_i - v) + F - b_d v - F_c sgn(v)
            p = self.arm.step(dt, self.intended, self.velocity, self.force)
        return DeviceState(t=t, position=p, buttons=buttons)

    def set_force(self, force: float, t: float) -> None:
        self.force = float(force) if math.isfinite(force) else 0.0

    def close(self) -> None:
        self.force = 0.0

    # -- script ------------------------------------------------------------------------------------
    def _advance(self, t: float, dt: float, T_in: float) -> None:
        self.velocity = 0.0                      # intended hand speed [m/s], set below while moving
        if self._T_last is not None and dt > 0:  # read-out rate [N/s], smoothed over RATE_TIME
            self._rate += dt / (RATE_TIME + dt) * ((T_in - self._T_last) / dt - self._rate)
        self._T_last = T_in
        if self.index < 0:                       # first engaged reading: wait, then start
            if self._wait_until is None:
                self._wait_until = t + self.start_delay
            if t < self._wait_until:
                return
            self._start(0, t, T_in)
            return
        if self._wait_until is not None:         # dwelling after a segment
            if t < self._wait_until:
                return
            self._wait_until = None
            if self.index + 1 >= len(self.segments):
                self.finished, self.direction = True, 0
                return
            self._start(self.index + 1, t, T_in)
            return
        seg = self.segments[self.index]
        # the operator anticipates: the hand lags its intention by ~(b_a + b_d) / k_a seconds, so it
        # stops the intention when the read-out, carried on at its present rate for that long, reaches
        # the target (a person stops early when the read-out moves fast)
        T_seen = T_in + self._rate * self._lead
        reached = T_seen >= seg.target if self.direction > 0 else T_seen <= seg.target
        if reached or t - self._t_segment > self.segment_timeout:
            self.timeouts += 0 if reached else 1
            self.direction = 0
            self._wait_until = t + self.dwell
            return
        # slow down near the target (a hand with mass lags its intention: stopping at full speed would
        # carry the tendon on by ~b v / k of hand travel, several newtons where the tendon sticks)
        self.velocity = self.direction * self.speed * approach(abs(seg.target - T_seen))
        self.intended += self.velocity * dt

    def _start(self, index: int, t: float, T_in: float) -> None:
        seg = self.segments[index]
        self.index, self.marker, self._t_segment = index, seg.marker, t
        self._wait_until = None
        self.direction = 1 if seg.target > T_in else -1

    @property
    def progress(self) -> str:
        """Human-readable position in the script, for logs."""
        if self.finished:
            return "done"
        if self.index < 0:
            return "waiting"
        return f"segment {self.index + 1}/{len(self.segments)} -> {self.segments[self.index].target:g} N"
