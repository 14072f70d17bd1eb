"""The master (operator-side) node: device -> Command, latest Estimate -> safe device force.

One :meth:`MasterNode.step` per cycle (1 kHz), given the time by the caller:

1. show the operator the latest proximal tension (simulated operators only), read the device;
2. safety state from the links: the estimate is fresh (younger than ``master.watchdog_ms``), the
   slave's heartbeat is fresh (younger than ``max(watchdog_ms, 3 heartbeat periods)``), says READY
   or ENGAGED, and its liveliness token (when watched) is present. All true: ENGAGED (on entry the
   motion map is anchored at the slave's current ``x_in``, so the tendon does not jump, and the
   force ramps in). Any false while engaged: SAFE, zero force at once, commands sent with
   ``engaged=False`` (the slave holds). Recovery re-engages with a fresh anchor and ramp;
3. publish ``Command(seq, t_master, x_in_cmd, engaged, marker)`` and keep its send time by seq in a
   ring buffer; an Estimate echoing ``cmd_seq`` gives the round-trip latency without clock sync;
4. render ``-force_scale * T_out_hat`` ramped, clamped, slew-limited (:class:`master.mapping.ForceMap`);
5. publish a Heartbeat at ``slave.heartbeat_hz`` (both sides use that rate).

When the device reports ``finished`` (a scripted operator at the end of its protocol) the node
disengages, announces STOPPING for ``stop_linger`` seconds and sets :attr:`done`.
"""
from __future__ import annotations

import json
import logging
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from master.device import HapticDevice, OperatorView
from master.mapping import ForceMap, MotionMap
from teleop.clock import Clock, Pacer
from teleop.codec import next_seq
from teleop.config import Config
from teleop.messages import Command, Estimate, Heartbeat, Side, SideState

__all__ = ["MasterLinks", "MasterNode", "RING_SIZE"]

log = logging.getLogger("teleop.master")
RING_SIZE = 4096            # command send times kept for the latency echo (4 s at 1 kHz)
_SLAVE_OK = (SideState.READY, SideState.ENGAGED)


@dataclass
class MasterLinks:
    """The master's side of the transport (real: :mod:`teleop.transport`; tests: in-memory fakes).

    command, heartbeat : objects with ``put(msg)``.
    estimate, slave_heartbeat : latest-wins subscribers with ``latest() -> Received | None``
        (``.message``, ``.t_recv``) and ``age(now) -> float`` [s].
    slave_alive : callable returning whether the slave's liveliness token is present, or None.
    """

    command: Any
    heartbeat: Any
    estimate: Any
    slave_heartbeat: Any
    slave_alive: Callable[[], bool] | None = None


class MasterNode:
    """Master side of one tendon's teleoperation loop.

    Parameters
    ----------
    cfg : Config
        ``master`` (rate, mapping, watchdog) and ``slave.heartbeat_hz`` are used.
    device : HapticDevice
        Optionally also an :class:`~master.device.OperatorView` and with ``finished``/``marker``
        attributes (scripted operators).
    links : MasterLinks
    stop_linger : float
        Time the STOPPING state is announced before :attr:`done` [s].
    """

    def __init__(self, cfg: Config, device: HapticDevice, links: MasterLinks, *, stop_linger: float = 0.2):
        self.cfg = cfg
        self.device = device
        self.links = links
        self.motion = MotionMap(cfg.master.mapping.motion_scale)
        self.forces = ForceMap.from_config(cfg.master.mapping)
        self.watchdog = cfg.master.watchdog_ms * 1e-3
        self.hb_period = 1.0 / cfg.slave.heartbeat_hz
        self.hb_timeout = max(self.watchdog, 3.0 * self.hb_period)
        self.stop_linger = float(stop_linger)
        self.state = SideState.STARTING
        self.done = False
        self.seq = 0
        self.hb_seq = 0
        self._next_hb = -math.inf
        self._t_stop: float | None = None
        self._sent_seq = np.full(RING_SIZE, -1, dtype=np.int64)
        self._sent_t = np.zeros(RING_SIZE)
        self._last_est_seq: int | None = None
        self._last_echo: int | None = None
        self.rtts: list[float] = []
        self.force = 0.0
        self.commands_sent = 0
        self.estimates_new = 0
        self.safe_events = 0
        self.engage_count = 0
        self.last_reason = "starting"
        self.pacer_stats: dict[str, float] = {}

    # ------------------------------------------------------------------------------------------------
    def _peer_status(self, now: float) -> tuple[Estimate | None, bool, str]:
        """(latest estimate or None, all links healthy, reason if not)."""
        rec = self.links.estimate.latest()
        est = None if rec is None else rec.message
        hb_rec = self.links.slave_heartbeat.latest()
        if hb_rec is None or self.links.slave_heartbeat.age(now) > self.hb_timeout:
            return est, False, "slave heartbeat missing"
        if self.links.slave_alive is not None and not self.links.slave_alive():
            return est, False, "slave liveliness token gone"
        if hb_rec.message.state not in _SLAVE_OK:
            return est, False, f"slave {hb_rec.message.state.name}"
        if est is None or self.links.estimate.age(now) > self.watchdog:
            return est, False, "estimate stale"
        return est, True, "ok"

    def _latency(self, now: float) -> None:
        rec = self.links.estimate.latest()
        if rec is None or rec.message.seq == self._last_est_seq:
            return
        est = rec.message
        self._last_est_seq = est.seq
        self.estimates_new += 1
        if est.cmd_seq == self._last_echo:
            return
        self._last_echo = est.cmd_seq
        i = est.cmd_seq % RING_SIZE
        if self._sent_seq[i] == est.cmd_seq:
            t_recv = getattr(rec, "t_recv", now)
            self.rtts.append(t_recv - self._sent_t[i])

    def step(self, now: float) -> None:
        """One master cycle at time ``now`` [s] (see the module docstring)."""
        if self.done:
            return
        self._latency(now)
        est, healthy, reason = self._peer_status(now)
        engaged = self.state == SideState.ENGAGED
        if isinstance(self.device, OperatorView):
            self.device.watch(None if est is None else est.T_in, engaged)
        dev = self.device.read(now)
        finished = bool(getattr(self.device, "finished", False))

        # ---- state machine ----
        if finished or self._t_stop is not None:
            if self._t_stop is None:
                self._t_stop = now
                self.forces.disengage()
                self.motion.open_clutch()
                self._set_state(SideState.STOPPING, now, "protocol finished")
            if now - self._t_stop >= self.stop_linger:
                self.done = True
        elif healthy and dev.operator_present and math.isfinite(dev.position):
            if self.state != SideState.ENGAGED:
                # anchor at the slave's present x_in: engaging never makes the tendon jump
                self.motion.anchor(dev.position, est.x_in)
                self.forces.engage()
                self.engage_count += 1
                self._set_state(SideState.ENGAGED, now, "slave ready, estimate fresh")
        else:
            if not healthy:
                self.last_reason = reason
            elif not dev.operator_present:
                self.last_reason = "operator not present"
            if self.state == SideState.ENGAGED:
                self.safe_events += 1
                self.forces.disengage()
                self.motion.open_clutch()
                self._set_state(SideState.SAFE, now, self.last_reason)
            elif self.state == SideState.STARTING:
                self._set_state(SideState.READY, now, "device read")
        engaged = self.state == SideState.ENGAGED

        # ---- command ----
        x_cmd = self.motion.command(dev.position) if engaged else self.motion.last
        marker = int(getattr(self.device, "marker", 0)) if engaged else 0
        self.links.command.put(Command(self.seq, now, x_cmd, engaged, marker))
        i = self.seq % RING_SIZE
        self._sent_seq[i], self._sent_t[i] = self.seq, now
        self.seq = next_seq(self.seq)
        self.commands_sent += 1

        # ---- force ----
        T_out_hat = math.nan if est is None else est.T_out_hat
        self.force = self.forces.step(T_out_hat, now, fresh=engaged and healthy)
        self.device.set_force(self.force, now)

        # ---- heartbeat ----
        if now >= self._next_hb:
            self.links.heartbeat.put(Heartbeat(Side.MASTER, self.hb_seq, now, self.state))
            self.hb_seq = next_seq(self.hb_seq)
            self._next_hb = now + self.hb_period if self._next_hb == -math.inf else max(
                self._next_hb + self.hb_period, now)

    def _set_state(self, state: SideState, now: float, why: str) -> None:
        if state != self.state:
            log.info("master %s -> %s at t=%.3f s: %s", self.state.name, state.name, now, why)
            self.state = state

    # ------------------------------------------------------------------------------------------------
    def run(self, clock: Clock, *, max_duration: float | None = None) -> None:
        """Pace :meth:`step` at ``master.rate_hz`` until :attr:`done` (or ``max_duration`` [s])."""
        pacer = Pacer(clock, self.cfg.master.rate_hz)
        t0 = clock.now()
        try:
            while not self.done:
                now = pacer.wait()
                self.step(now)
                if max_duration is not None and now - t0 >= max_duration:
                    break
        finally:
            self.pacer_stats = pacer.stats()
            self.device.set_force(0.0, clock.now())

    def latency_stats(self) -> dict[str, float | int | None]:
        """Round-trip latency from the command echo [ms]: n, p50, p99, max (None without samples)."""
        if not self.rtts:
            return {"n": 0, "p50_ms": None, "p99_ms": None, "max_ms": None}
        r = np.asarray(self.rtts) * 1e3
        return {"n": int(r.size), "p50_ms": float(np.percentile(r, 50)), "p99_ms": float(np.percentile(r, 99)),
                "max_ms": float(r.max())}

    def stats(self) -> dict[str, Any]:
        """Counters for the run summary (JSON-serialisable)."""
        est_sub = self.links.estimate
        return {
            "side": "master",
            "state": self.state.name,
            "commands_sent": self.commands_sent,
            "estimates_received": int(getattr(est_sub, "count", self.estimates_new)),
            "estimate_decode_errors": int(getattr(est_sub, "errors", 0)),
            "estimates_new_seen": self.estimates_new,
            "engage_count": self.engage_count,
            "safe_events": self.safe_events,
            "last_reason": self.last_reason,
            "latency_rtt": self.latency_stats(),
            "pacer": dict(self.pacer_stats),
            "operator_timeouts": int(getattr(self.device, "timeouts", 0)),
            "finished": bool(getattr(self.device, "finished", False)),
        }

    def write_stats(self, path: str | Path) -> None:
        """Write :meth:`stats` as JSON to ``path``."""
        Path(path).write_text(json.dumps(self.stats(), indent=2) + "\n", encoding="utf-8")
