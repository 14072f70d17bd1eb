"""The master (operator-side) node: device -> Command, latest Estimate -> safe device force.

One :meth:`MasterNode.step` per cycle (1 kHz), given the time by the caller:

1. show the operator the latest proximal tension (simulated operators only), read the device;
2. link health: the last *accepted* estimate is fresh (younger than ``master.watchdog_ms``), the
   command it echoes was sent less than ``2 watchdog_ms`` ago (the round trip: catches delay and loss
   on the way out too, without synchronised clocks; budget ``2 watchdog_ms``, one per leg, so a
   process stall on top of an allowed one-way delay does not trip it), the slave's heartbeat is fresh (younger than
   ``max(watchdog_ms, 3 heartbeat periods)``) and says READY or ENGAGED, and its liveliness token
   (when watched) is present. An estimate is accepted when its seq is newer than the last accepted
   one (duplicates and reordered ones are counted and ignored) and ``|T_in|``, ``|T_out_hat|`` are
   below ``master.max_tension`` (else counted as rejected);
3. the console (:mod:`master.console`: deadman, clutch, alignment) decides ENGAGED. Entering it
   re-anchors or checks the alignment and restarts the force ramp and the passivity observer.
   Leaving it because of the links or the deadman: SAFE, zero force at once, commands sent with
   ``engaged=False`` (the slave holds); clutch or misalignment: READY;
4. publish ``Command(seq, t_master, x_in_cmd, engaged, marker)`` and keep its send time by seq in a
   ring buffer; an Estimate echoing ``cmd_seq`` gives the round-trip latency;
5. render ``-force_scale * T_out_hat`` ramped, clamped, slew-limited (:class:`master.mapping.ForceMap`),
   then through the passivity controller (:mod:`master.passivity`, velocity from successive device
   positions; ``master.mapping.passivity``), then clamped again: no force above
   ``master.mapping.force_limit`` ever reaches the device;
6. publish a Heartbeat at ``slave.heartbeat_hz`` (both sides use that rate), record one CSV row.

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

from master.console import Console, ConsoleStatus
from master.device import HapticDevice, OperatorView
from master.mapping import ForceMap, MotionMap, clamp_force
from master.passivity import PassivityController
from teleop.clock import Clock, Pacer
from teleop.codec import next_seq, seq_newer
from teleop.config import Config
from teleop.messages import Command, Estimate, Heartbeat, Side, SideState

__all__ = ["MasterLinks", "MasterNode", "RING_SIZE", "CSV_COLUMNS", "CSV_UNITS"]

log = logging.getLogger("teleop.master")
RING_SIZE = 4096            # command send times kept for the latency echo (4 s at 1 kHz)
_SLAVE_OK = (SideState.READY, SideState.ENGAGED)
#: The master's recording, one row per cycle (measured-data format: x_in is the command sent, T_in the
#: slave's latest accepted proximal tension, 0 before any).
CSV_COLUMNS = ("time", "x_in", "T_in", "position", "T_out_hat", "force_cmd", "force", "energy", "state",
               "console", "t_est_recv", "echo_age", "cmd_seq")
CSV_UNITS = {"position": "m", "T_out_hat": "N", "force_cmd": "N", "force": "N", "energy": "J", "state": "SideState",
             "console": "ConsoleStatus", "t_est_recv": "s", "echo_age": "s", "cmd_seq": "-"}
_LINK_REASONS = ("slave", "estimate", "command echo")


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
    recorder : object with ``write(row)`` (a :class:`teleop.recording.CsvRecorder` with
        :data:`CSV_COLUMNS`), or None.
    """

    def __init__(self, cfg: Config, device: HapticDevice, links: MasterLinks, *, stop_linger: float = 0.2,
                 recorder=None):
        self.cfg = cfg
        self.device = device
        self.links = links
        self.recorder = recorder
        m = cfg.master.mapping
        self.motion = MotionMap(m.motion_scale)
        self.forces = ForceMap.from_config(m)
        self.console = Console(self.motion, m.align_tolerance, m.clutch_button)
        self.passivity = PassivityController(m.force_limit, enabled=m.passivity)
        self.limit = m.force_limit
        self.max_tension = cfg.master.max_tension
        self._accepted = None                  # last accepted Received estimate
        self._seen = None
        self._t_echo: float | None = None      # send time of the last echoed command [s]
        self._p_prev: float | None = None
        self._t_prev: float | None = None
        self._t_warn = -math.inf
        self.force_cmd = 0.0
        self.max_abs_force = 0.0
        self.counts = dict.fromkeys(("estimates_rejected_range", "estimates_out_of_order", "estimates_duplicate"), 0)
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
        """(latest accepted estimate or None, all links healthy, reason if not)."""
        rec = self._accepted
        est = None if rec is None else rec.message
        hb_rec = self.links.slave_heartbeat.latest()
        if hb_rec is None or self.links.slave_heartbeat.age(now) > self.hb_timeout:
            return est, False, "slave heartbeat missing"
        if self.links.slave_alive is not None and not self.links.slave_alive():
            return est, False, "slave liveliness token gone"
        if hb_rec.message.state not in _SLAVE_OK:
            return est, False, f"slave {hb_rec.message.state.name}"
        if est is None or now - rec.t_recv > self.watchdog:
            return est, False, "estimate stale"
        if self._t_echo is None or now - self._t_echo > 2.0 * self.watchdog:
            return est, False, "command echo stale"
        return est, True, "ok"

    def _warn(self, now: float, msg: str, *args) -> None:
        if now - self._t_warn >= 1.0:
            self._t_warn = now
            log.warning(msg, *args)

    def _latency(self, now: float) -> None:
        """Accept the newest estimate (order, range); the echo gives the round trip."""
        rec = self.links.estimate.latest()
        if rec is None or rec is self._seen:
            return
        self._seen = rec
        est = rec.message
        if not seq_newer(est.seq, self._last_est_seq):
            self.counts["estimates_duplicate" if est.seq == self._last_est_seq else "estimates_out_of_order"] += 1
            return
        if not (abs(est.T_out_hat) <= self.max_tension and abs(est.T_in) <= self.max_tension):
            self.counts["estimates_rejected_range"] += 1
            self._warn(now, "rejected estimate %d: T_in %.6g N, T_out_hat %.6g N beyond master.max_tension %g N",
                       est.seq, est.T_in, est.T_out_hat, self.max_tension)
            return
        self._accepted = rec
        self._last_est_seq = est.seq
        self.estimates_new += 1
        i = est.cmd_seq % RING_SIZE
        if self._sent_seq[i] != est.cmd_seq:
            return
        self._t_echo = self._sent_t[i]
        if est.cmd_seq == self._last_echo:
            return
        self._last_echo = est.cmd_seq
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

        # ---- state machine (console: deadman, clutch, alignment) ----
        if finished or self._t_stop is not None:
            if self._t_stop is None:
                self._t_stop = now
                self.forces.disengage()
                self.console.stop()
                self._set_state(SideState.STOPPING, now, "protocol finished")
            if now - self._t_stop >= self.stop_linger:
                self.done = True
        else:
            status = self.console.update(dev, healthy, None if est is None else est.x_in)
            on_console = getattr(self.device, "on_console", None)
            if on_console is not None:
                on_console(status)
            if status == ConsoleStatus.ENGAGED:
                if self.console.engaged_now:      # ramp and passivity observer start afresh
                    self.forces.engage()
                    self.passivity.reset()
                    self.engage_count += 1
                    self._set_state(SideState.ENGAGED, now, "slave ready, links fresh, aligned")
            else:
                if self.console.released_now:
                    self.forces.disengage()
                self.last_reason = {ConsoleStatus.WAIT_SLAVE: reason if not healthy else "no slave position",
                                    ConsoleStatus.WAIT_OPERATOR: "operator not present",
                                    ConsoleStatus.CLUTCH: "clutch held"}.get(status) or self.console.prompt()
                if status == ConsoleStatus.ALIGN:
                    self._warn(now, "master: %s", self.last_reason)
                if status in (ConsoleStatus.WAIT_SLAVE, ConsoleStatus.WAIT_OPERATOR):
                    if self.state == SideState.ENGAGED:
                        self.safe_events += 1
                        self._set_state(SideState.SAFE, now, self.last_reason)
                    elif self.state == SideState.STARTING:
                        self._set_state(SideState.READY, now, "device read")
                else:
                    self._set_state(SideState.READY, now, self.last_reason)
        engaged = self.state == SideState.ENGAGED

        # ---- command ----
        x_cmd = self.motion.command(dev.position) if engaged else self.motion.last
        marker = int(getattr(self.device, "marker", 0)) if engaged else 0
        self.links.command.put(Command(self.seq, now, x_cmd, engaged, marker))
        i = self.seq % RING_SIZE
        self._sent_seq[i], self._sent_t[i] = self.seq, now
        self.seq = next_seq(self.seq)
        self.commands_sent += 1

        # ---- force: map (scale, ramp, clamp, slew) -> passivity controller -> clamp ----
        T_out_hat = math.nan if est is None else est.T_out_hat
        self.force_cmd = self.forces.step(T_out_hat, now, fresh=engaged and healthy)
        dt = 1.0 / self.cfg.master.rate_hz if self._t_prev is None else now - self._t_prev
        p = dev.position if math.isfinite(dev.position) else math.nan
        v = 0.0 if self._p_prev is None else (p - self._p_prev) / dt if dt > 0 else math.nan
        self._t_prev, self._p_prev = now, (p if math.isfinite(p) else self._p_prev)
        self.force = clamp_force(self.passivity.step(self.force_cmd, v, dt), self.limit)
        self.max_abs_force = max(self.max_abs_force, abs(self.force))
        self.device.set_force(self.force, now)
        if self.recorder is not None:
            rec = self._accepted
            self.recorder.write((now, x_cmd, 0.0 if est is None else est.T_in, p if math.isfinite(p) else 0.0,
                                 0.0 if est is None else est.T_out_hat, self.force_cmd, self.force,
                                 self.passivity.energy, int(self.state), int(self.console.status),
                                 0.0 if rec is None else rec.t_recv,
                                 -1.0 if self._t_echo is None else now - self._t_echo, self.seq - 1 & 0xFFFFFFFF))

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
            **self.counts,
            "console": self.console.status.name,
            "clutches": self.console.clutches,
            "align_refusals": self.console.refusals,
            "max_abs_force": self.max_abs_force,
            "force_limit": self.limit,
            "passivity": {"enabled": self.passivity.enabled, **{
                k: getattr(self.passivity.stats, k) for k in ("energy", "dissipated", "active_steps", "steps")}},
            "latency_rtt": self.latency_stats(),
            "pacer": dict(self.pacer_stats),
            "operator_timeouts": int(getattr(self.device, "timeouts", 0)),
            "finished": bool(getattr(self.device, "finished", False)),
        }

    def write_stats(self, path: str | Path) -> None:
        """Write :meth:`stats` as JSON to ``path``."""
        Path(path).write_text(json.dumps(self.stats(), indent=2) + "\n", encoding="utf-8")
