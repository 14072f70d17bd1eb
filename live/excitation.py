"""The excitation motion of ``teleop calibrate --diagnose``, commanded through the slave like any other motion.

The diagnosis of a single tendon needs what its recordings hold (:mod:`study.scenarios`): pulls and releases at slow
and fast speeds, minor loops, staircases with holds and small oscillations, every block from and back to a rest. The
motion (:class:`ExcitationMotion`) is, one command per cycle:

1. a hold at the measured start (the encoders' rest);
2. a probe: a slow pull at ``calibration.speed`` until the measured ``T_in`` reaches the excitation's top tension
   (:func:`top_tension`: ``calibration.target_tension``, at most half of ``slave.max_tension``), or the travel reaches
   ``slave.x_in_max``; where ``T_in`` first passed the rest tension (:data:`REST_FRACTION` of the top) is the rest
   position, where the probe stopped the top;
3. back to the start, then :func:`study.scenarios.protocol` between the start, the rest and the top for the rest of
   ``duration``; every step of the command within :data:`SPEED_FRACTION` of ``slave.max_speed`` and every command
   within ``[slave.x_in_min, slave.x_in_max]``.

:func:`run_excitation` sends each command to an in-process :class:`slave.node.SlaveNode` as an engaged
:class:`~teleop.wire.messages.Command` over a :class:`Loopback` link: the node's own checks judge it (range,
``slave.max_step``, ``slave.max_speed``, the engage tolerance, ``slave.max_tension``, the watchdog, sensor faults),
and a node that goes SAFE stops the excitation. :func:`leave_safe` stops commanding and runs the node until it is
SAFE and relaxed: every exit path ends there, Ctrl-C included.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from estimator.errors import CalibrationError
from teleop.config.schema import Config
from teleop.session.transport import Received
from teleop.wire.messages import Command, SideState

__all__ = ["Loopback", "ExcitationMotion", "top_tension", "run_excitation", "leave_safe", "REST_FRACTION",
           "SPEED_FRACTION", "START_HOLD_S"]

#: the rest tension of the excitation, as a share of its top tension [-]
REST_FRACTION = 0.25
#: the excitation's commands move at most this share of ``slave.max_speed`` [-]
SPEED_FRACTION = 0.8
#: the hold at the start, before the probe [s]
START_HOLD_S = 0.5
#: the commands keep this far inside ``[slave.x_in_min, slave.x_in_max]`` [m]
RANGE_MARGIN = 1e-4


class Loopback:
    """An in-process latest-wins link: a publisher and a subscriber in one (receive time: ``clock.now()``)."""

    def __init__(self, clock) -> None:
        self.clock = clock
        self.last: Received | None = None
        self.count = self.errors = 0

    def put(self, msg) -> None:
        self.last = Received(msg, self.clock.now())
        self.count += 1

    def latest(self) -> Received | None:
        return self.last

    def age(self, now: float) -> float:
        return math.inf if self.last is None else now - self.last.t_recv


def top_tension(cfg: Config) -> float:
    """The excitation's top proximal tension [N]: ``calibration.target_tension``, at most half of
    ``slave.max_tension``."""
    return min(cfg.calibration.target_tension, 0.5 * cfg.slave.max_tension)


class ExcitationMotion:
    """The motion of the module docstring, one command per cycle from the measured start ``x0`` [m].

    Parameters
    ----------
    cfg : Config
        ``calibration`` (speed, target_tension), ``slave`` (x_in range, max_speed, max_tension), ``rig.rate_hz``.
    x0 : float
        The measured proximal position at the start [m].
    duration : float
        Length of the motion [s], >= 5.
    seed : int
        Seeds the protocol's choices.

    Attributes
    ----------
    stage : str
        ``hold``, ``probe``, ``play`` or ``done``.
    x_rest, x_top : float or None
        The rest and top positions the probe found [m].
    """

    def __init__(self, cfg: Config, x0: float, duration: float, seed: int = 0):
        s = cfg.slave
        self.dt = 1.0 / cfg.rig.rate_hz
        self.x0, self.duration, self.seed = float(x0), float(duration), int(seed)
        self.lo, self.hi = s.x_in_min + RANGE_MARGIN, s.x_in_max - RANGE_MARGIN
        self.v_max = SPEED_FRACTION * s.max_speed
        self.probe_speed = min(cfg.calibration.speed, self.v_max)
        self.T_top = top_tension(cfg)
        self.T_rest = REST_FRACTION * self.T_top
        self.stage = "hold"
        self.x = min(max(self.x0, self.lo), self.hi)
        self.x_rest: float | None = None
        self.x_top: float | None = None
        self.t = 0.0
        self._play: np.ndarray | None = None
        self._k = 0

    def target(self, T_in: float) -> float | None:
        """The command of the next cycle [m] given the last measured proximal tension ``T_in`` [N]; None when the
        motion is over."""
        self.t += self.dt
        if self.stage == "hold":
            if self.t >= START_HOLD_S:
                self.stage = "probe"
            return self.x
        if self.stage == "probe":
            if self.x_rest is None and T_in >= self.T_rest:
                self.x_rest = self.x
            if T_in >= self.T_top or self.x + self.probe_speed * self.dt > self.hi:
                self.x_top = self.x
                self._play = self._plan()
                self.stage = "play"
            else:
                self.x += self.probe_speed * self.dt
                return self.x
        if self._play is not None and self._k < self._play.size:
            self.x = float(self._play[self._k])
            self._k += 1
            return self.x
        self.stage = "done"
        return None

    def _plan(self) -> np.ndarray:
        """The rest of the motion after the probe (module docstring, 3.), limited in speed and range."""
        from study.scenarios import protocol
        assert self.x_top is not None
        span = self.x_top - self.x0
        rest = (self.x_rest if self.x_rest is not None else self.x0 + REST_FRACTION * span) - self.x0
        back = max(int(math.ceil(abs(span) / (3.0 * self.probe_speed * self.dt))), 1)
        down = np.linspace(self.x_top, self.x0, back + 1)[1:]
        left = max(self.duration - self.t - back * self.dt, 5.0)
        rng = np.random.default_rng([self.seed, 5])
        rate = 1.0 / self.dt
        path = np.concatenate([down, self.x0 + protocol(left, rate, span, rng, x_rest=rest)])
        return limited(path, self.x_top, self.v_max * self.dt, self.lo, self.hi)


def limited(path: np.ndarray, start: float, step: float, lo: float, hi: float) -> np.ndarray:
    """``path`` [m] followed from ``start`` with at most ``step`` [m] per sample, within ``[lo, hi]``."""
    out = np.empty_like(path)
    x = start
    for k, p in enumerate(np.clip(path, lo, hi)):
        x += min(max(p - x, -step), step)
        out[k] = x
    return out


def run_excitation(node, motion: ExcitationMotion, tick: Callable[[], float],
                   row: Callable[[Any], None]) -> int:
    """Command ``motion`` through ``node`` (a :class:`slave.node.SlaveNode` whose links' command is a
    :class:`Loopback`), one engaged command per cycle, ``tick()`` giving each cycle's time [s]; ``row(state)`` is
    called with the rig's state after every cycle. Returns the cycles run.

    Raises
    ------
    CalibrationError
        The node did not follow (it went SAFE, or never engaged): the reason is the node's.
    """
    seq = cycles = 0
    engaged = False
    while True:
        x = motion.target(float(node.rig_state.T_in))
        if x is None:
            return cycles
        now = tick()
        seq += 1
        node.links.command.put(Command(seq, now, (x,), True, 0))
        node.step(now)
        cycles += 1
        if node.state == SideState.ENGAGED:
            engaged = True
        elif engaged or cycles > 10:
            why = node.last_safe_reason or f"the slave is {node.state.name}"
            raise CalibrationError(f"excitation stopped at {motion.t:.2f} s ({motion.stage}): {why}")
        row(node.rig_state)


def leave_safe(node, tick: Callable[[], float], limit_s: float) -> None:
    """Stop commanding ``node`` and run it until it is SAFE and its tendon relaxed (the measured ``T_in`` within the
    SAFE behaviour's band of the pretension), at most ``limit_s`` [s] of ``tick()`` time."""
    if node.state == SideState.CALIBRATING:
        return
    t_end = tick() + limit_s
    axis = node.axes[0]
    while True:
        now = tick()
        node.step(now)
        if node.state == SideState.SAFE and (float(node.rig_state.T_in) <= axis.relax_to or now >= t_end):
            return
        if now >= t_end:
            return
