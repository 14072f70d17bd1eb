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

The link side (estimate acceptance, echo, link health, STOPPING, summary counters) is shared with
the joint-instrument master: :mod:`master.node_base`; heartbeat, state changes and pacing with
every node: :mod:`teleop.node`.
"""
from __future__ import annotations

import math
from typing import Any

from master.console import Console, ConsoleStatus
from master.device import HapticDevice, OperatorView
from master.mapping import ForceMap, MotionMap, clamp_force
from master.node_base import RING_SIZE, MasterLinks, MasterNodeBase
from master.passivity import PassivityController
from teleop.clock import Clock
from teleop.config import Config
from teleop.messages import Command, Estimate, SideState

__all__ = ["MasterLinks", "MasterNode", "RING_SIZE", "CSV_COLUMNS", "CSV_UNITS"]

#: The master's recording, one row per cycle (measured-data format: x_in is the command sent, T_in the
#: slave's latest accepted proximal tension, 0 before any).
CSV_COLUMNS = ("time", "x_in", "T_in", "position", "T_out_hat", "force_cmd", "force", "energy", "state",
               "console", "t_est_recv", "echo_age", "cmd_seq")
CSV_UNITS = {"position": "m", "T_out_hat": "N", "force_cmd": "N", "force": "N", "energy": "J", "state": "SideState",
             "console": "ConsoleStatus", "t_est_recv": "s", "echo_age": "s", "cmd_seq": "-"}
_LINK_REASONS = ("slave", "estimate", "command echo")


class MasterNode(MasterNodeBase):
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
        super().__init__(cfg, device, links, stop_linger=stop_linger,
                         counts=("estimates_rejected_range", "estimates_out_of_order", "estimates_duplicate"))
        self.recorder = recorder
        m = cfg.master.mapping
        self.motion = MotionMap(m.motion_scale)
        self.forces = ForceMap.from_config(m)
        self.console = Console(self.motion, m.align_tolerance, m.clutch_button)
        self.passivity = PassivityController(m.force_limit, enabled=m.passivity)
        self.limit = m.force_limit
        self._p_prev: float | None = None
        self.force_cmd = 0.0
        self.max_abs_force = 0.0
        self.force = 0.0

    # ------------------------------------------------------------------------------------------------
    def _in_range(self, est: Estimate, now: float) -> bool:
        if abs(est.T_out_hat) <= self.max_tension and abs(est.T_in) <= self.max_tension:
            return True
        self.counts["estimates_rejected_range"] += 1
        self._warn(now, "rejected estimate %d: T_in %.6g N, T_out_hat %.6g N beyond master.max_tension %g N",
                   est.seq, est.T_in, est.T_out_hat, self.max_tension)
        return False

    def _disengage_all(self) -> None:
        self.forces.disengage()
        self.console.stop()

    def step(self, now: float) -> None:
        """One master cycle at time ``now`` [s] (see the module docstring)."""
        if self.done:
            return
        self._receive(now)
        est, healthy, reason = self._peer_status(now)
        engaged = self.state == SideState.ENGAGED
        if isinstance(self.device, OperatorView):
            self.device.watch(None if est is None else est.T_in, engaged)
        dev = self.device.read(now)
        finished = bool(getattr(self.device, "finished", False))

        # ---- state machine (console: deadman, clutch, alignment) ----
        if not self._stopping(now, finished):
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
                    if self.state == SideState.ENGAGED:      # a safe event
                        self._set_state(SideState.SAFE, now, self.last_reason)
                    elif self.state == SideState.STARTING:
                        self._set_state(SideState.READY, now, "device read")
                else:
                    self._set_state(SideState.READY, now, self.last_reason)
        engaged = self.state == SideState.ENGAGED

        # ---- command ----
        x_cmd = self.motion.command(dev.position) if engaged else self.motion.last
        marker = int(getattr(self.device, "marker", 0)) if engaged else 0
        self._send_command(Command(self.seq, now, x_cmd, engaged, marker), now)

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
        self._heartbeat(now)

    # ------------------------------------------------------------------------------------------------
    def _run_ended(self, clock: Clock) -> None:
        self.device.set_force(0.0, clock.now())

    def _stats_detail(self) -> dict[str, Any]:
        return {
            **self.counts,
            "console": self.console.status.name,
            "clutches": self.console.clutches,
            "align_refusals": self.console.refusals,
            "max_abs_force": self.max_abs_force,
            "force_limit": self.limit,
            "passivity": {"enabled": self.passivity.enabled, **{
                k: getattr(self.passivity.stats, k) for k in ("energy", "dissipated", "active_steps", "steps")}},
            "latency_rtt": self.latency_stats(),
        }
