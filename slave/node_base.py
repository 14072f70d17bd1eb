"""The cycle and the watchdog of the instrument side (:class:`slave.node.SlaveNode`, every instrument).

The same whatever the instrument's axes (:mod:`slave.axis`):

* one cycle per :meth:`SlaveNodeBase.step` at ``rig.rate_hz``: the same instant twice does nothing;
  a cycle whose wall-clock period exceeds ``5 / rig.rate_hz`` (a stall) is counted and advances the
  ramps and the rig by that much only, never by a jump;
* the master's heartbeat saying STOPPING is noted (and ends the node with ``stop_on_master_stop``);
* CALIBRATING runs the node's power-up routine, every other state follows the latest accepted
  command by one set of watchdog rules (:meth:`SlaveNodeBase._decide`): none yet, older than
  ``slave.watchdog_ms`` or the master's liveliness token gone -> SAFE; ``engaged=False`` -> READY
  (hold); entering ENGAGED from another state only when the command is close to where the axes are
  (the node's ``_too_far``; refused commands counted once each), else ENGAGED. A command is accepted
  when it fits the instrument (one target per axis), is newer than the last accepted one and lies
  within range. What each decision does to the motors is each axis's: a single tendon holds and
  relaxes toward its pretension when SAFE, the pair controller of a joint relaxes both tendons to
  their set tension;
* the tension limit, in the node's own loop whatever the link and the master do: a cycle whose measured
  proximal tension ``|T_in|`` of any tendon of any axis (the load cell of a tendon or of a pair; the
  cable tension read off the spindle's torque) exceeds ``slave.max_tension`` (or reads NaN) goes SAFE
  in that cycle (:meth:`SlaveNodeBase._check_tension`; counted as ``tension_trips``, the reason logged,
  kept as the SAFE reason and as ``last_tension_trip`` in the stats) and relaxes from the next motor
  command on. The SAFE holds, whatever the commands, until a fresh command with ``engaged=False``
  arrives while every ``|T_in|`` is below :data:`REARM_FRACTION` (90 %) of the limit: the master has
  let go (it goes SAFE when the slave's heartbeat says SAFE); the slave is then READY and engaging
  again follows the ordinary rules;
* one estimate published per control cycle, a Heartbeat at ``slave.heartbeat_hz``;
* ``calibration.json`` in the run directory, and the counters of the run summary.
"""
from __future__ import annotations

import json
import logging
from collections.abc import Callable
from dataclasses import dataclass
from enum import Enum
from pathlib import Path
from typing import TYPE_CHECKING, Any

from teleop.config.bounds import REARM_FRACTION
from teleop.config.schema import Config
from teleop.node import NodeBase
from teleop.wire.codec import next_seq
from teleop.wire.messages import Command, Side, SideState

if TYPE_CHECKING:
    from teleop.session.transport import Received

__all__ = ["SlaveLinks", "SlaveNodeBase", "Decision"]


class Decision(Enum):
    """What the latest accepted command asks of the instrument this cycle (:meth:`SlaveNodeBase._decide`)."""

    SAFE = "safe"            # no fresh command: the node's safe behaviour (state SAFE)
    HOLD = "hold"            # the master is not engaged: hold the last applied targets (state READY)
    REFUSED = "refused"      # engaging too far from where the axes are: state unchanged, hold
    ENGAGED = "engaged"      # follow the command's targets (state ENGAGED)


@dataclass
class SlaveLinks:
    """The slave's side of the transport (real: :mod:`teleop.session.transport`; tests: in-memory fakes).

    estimate, heartbeat : objects with ``put(msg)``.
    command, master_heartbeat : latest-wins subscribers with ``latest()`` and ``age(now)`` [s].
    crtk : the CRTK side (:class:`teleop.ros2.side.SlaveCrtk`) or None: handed the state and the followed
        command at the end of each cycle (it stores them; a thread publishes them on ROS 2).
    refused_links : callable returning the number of connections the side's listener refused, or None.
    """

    estimate: Any
    heartbeat: Any
    command: Any
    master_heartbeat: Any
    master_alive: Callable[[], bool] | None = None
    crtk: Any = None    # with ros2.enabled: offer(state, accepted command) each cycle (teleop/ros2/side.py)
    refused_links: Callable[[], int] | None = None   # connections the listener refused (credentials, certificate)


class SlaveNodeBase(NodeBase):
    """The cycle, watchdog and summary of a slave node (module docstring).

    The node (:class:`slave.node.SlaveNode`) implements :meth:`_calibration_step`, :meth:`_control_step`,
    ``_in_range(cmd, now)``, ``_fits(cmd, now)``, :meth:`_too_far` and :meth:`_stats_detail`.

    Parameters
    ----------
    cfg : Config
        ``slave`` (watchdog, heartbeat) and ``rig.rate_hz`` are used here.
    links : SlaveLinks
    run_dir : path or None
        Where ``calibration.json`` goes.
    stop_on_master_stop : bool
        Finish when the master announces STOPPING.
    counts : iterable of str
        The node's event counters.
    """

    side = Side.SLAVE
    log = logging.getLogger("teleop.slave")
    names: tuple[str, ...] = ()             # the axes' names, in order (the node's)

    def __init__(self, cfg: Config, links: SlaveLinks, *, run_dir: str | Path | None, stop_on_master_stop: bool,
                 counts):
        super().__init__(cfg.slave.heartbeat_hz, counts)
        self.cfg = cfg
        self.links = links
        self.run_dir = None if run_dir is None else Path(run_dir)
        self.stop_on_master_stop = stop_on_master_stop
        self.watchdog = cfg.slave.watchdog_ms * 1e-3
        self.period = 1.0 / cfg.rig.rate_hz
        self.max_dt = 5.0 * self.period     # longest step the ramps and the rig advance in one cycle [s]
        self.stalls = 0                     # cycles whose wall-clock period exceeded max_dt
        self._t_prev: float | None = None
        self.cmd_seq = 0
        self.marker = 0
        self.cycles = 0
        self.commands_applied = 0
        self.master_stopped = False
        self._accepted: Received[Command] | None = None   # last accepted command
        self.max_tension = cfg.slave.max_tension
        self.tension_high = False           # the last measured |T_in| of some tendon is not below REARM_FRACTION
        self.tension_fault: str | None = None   # why a tension trip holds SAFE, None when none does
        self.sensor_faulty = False          # the rig's newest sample is not one to estimate or control on
        self.sensor_fault: str | None = None    # why a sensor fault holds SAFE, None when none does
        self.last_tension_trip: str | None = None   # the reason of the run's last tension trip (stats)
        self._refused: Received[Command] | None = None    # last command refused for engaging too far away
        self._phase: SideState | None = None   # the state a cycle's first phase ran in, until its second

    @property
    def rate_hz(self) -> float:
        return self.cfg.rig.rate_hz

    def _cycle_source(self):
        """The command subscriber when the master runs at the slave's rate: each cycle starts as a command
        arrives (teleop.timing.clock.LockedPacer), not up to a period later."""
        return self.links.command if self.cfg.master.rate_hz == self.rate_hz else None

    # ---- the cycle ---------------------------------------------------------------------------------
    def _cycle_dt(self, now: float) -> float | None:
        """Start a cycle at ``now`` [s]: its time step [s] (stalls clipped to ``max_dt``), or None when
        there is nothing to do (done, or the same instant twice)."""
        if self.done:
            return None
        dt = self.period if self._t_prev is None else now - self._t_prev
        if not dt > 0:          # same instant twice: nothing to advance
            return None
        if dt > self.max_dt:    # a stalled cycle must not turn into a jump of the ramps and the rig
            self.stalls += 1
            dt = self.max_dt
        self._t_prev = now
        self.cycles += 1
        hb = self.links.master_heartbeat.latest()
        if hb is not None and hb.message.state == SideState.STOPPING:
            self.master_stopped = True
            if self.stop_on_master_stop:
                self.done = True
        return dt

    def step_send(self, now: float) -> None:
        """A slave cycle's first phase at ``now`` [s]: the command decided on the rig's estimated sample and the
        estimate published (see the module docstrings)."""
        dt = self._cycle_dt(now)
        self._phase = None if dt is None else self.state
        if dt is None:
            return
        if self.state == SideState.CALIBRATING:
            self._calibration_step(now, dt)
        else:
            self._control_step(now, dt)

    def step_after(self, now: float) -> None:
        """A slave cycle's second phase at ``now`` [s]: the motor commands, the rig moved, the recordings and
        the next sample estimated (a control cycle), the heartbeat and the CRTK state."""
        phase, self._phase = self._phase, None
        if phase is None:
            return
        if phase != SideState.CALIBRATING:
            self._control_after(now)
        self._heartbeat(now)
        crtk = self.links.crtk
        if crtk is not None:
            crtk.offer(self.state, self._accepted, self.tension_fault is not None)

    def _calibration_step(self, now: float, dt: float) -> None:
        """One cycle of the power-up calibration routine."""
        raise NotImplementedError

    def _control_step(self, now: float, dt: float) -> None:
        """A control cycle's first phase: the tension limit and the decision on the rig's estimated sample,
        :meth:`_publish`."""
        raise NotImplementedError

    def _control_after(self, now: float) -> None:
        """A control cycle's second phase, after its estimate is published: the motor commands, the rig moved
        on them, the cycle's rows recorded, the new sample estimated (default: nothing)."""

    # ---- commands and estimates --------------------------------------------------------------------
    def _accept(self, now: float) -> None:
        """Look at the latest received command once: accept it when it fits, is newer and within range."""
        last = None if self._accepted is None else self._accepted.message.seq
        rec = self._take(self.links.command, last, "commands", now)
        if rec is not None:
            self._accepted = rec

    def _command_fault(self, now: float) -> str | None:
        """Why the latest accepted command cannot be followed (SAFE), or None when it can."""
        rec = self._accepted
        if rec is None:
            return "no command"
        if now - rec.t_recv > self.watchdog:
            return "command stale"
        alive = self.links.master_alive
        if alive is not None and not alive():
            return "master liveliness token gone"
        return None

    def _operator_let_go(self, still: bool) -> bool:
        """Whether a latched fault ends now: its condition is gone (``still`` false) and the latest command is
        not engaged (the operator let go)."""
        rec = self._accepted
        return not still and rec is not None and not rec.message.engaged

    def _tension_hold(self) -> str | None:
        """Why a tension trip still holds SAFE (with a fresh command), or None: none does, or it ends now
        because the command is not engaged and every measured ``|T_in|`` is below :data:`REARM_FRACTION` of
        ``slave.max_tension``."""
        if self.tension_fault is not None and self._operator_let_go(self.tension_high):
            self.tension_fault = None
        return self.tension_fault

    def _sensor_hold(self) -> str | None:
        """Why a sensor fault still holds SAFE, or None: none does, or it ends now because the readings are
        good again and the latest command is not engaged (the operator let go, as after a tension trip)."""
        if self.sensor_fault is not None and self._operator_let_go(self.sensor_faulty):
            self.sensor_fault = None
        return self.sensor_fault

    def _check_tension(self, axes, now: float) -> None:
        """The tension limit on this cycle's measured proximal tensions (module docstring).

        Parameters
        ----------
        axes : sequence of AxisState
            This cycle's state of every axis; each tendon's ``T_in`` [N] is its measured proximal tension.
        now : float
            The cycle's time [s].
        """
        limit = self.max_tension
        peak, where = 0.0, ""                   # the largest |T_in| [N] (NaN: a failed load cell) and its tendon
        for ax_state, name in zip(axes, self.names, strict=False):
            n = len(ax_state.tendons)
            for k, tendon in enumerate(ax_state.tendons):
                T = abs(tendon.T_in)
                if not T <= peak:               # NaN wins
                    peak, where = T, name if n == 1 else f"{name}.{'ab'[k]}"
        self.tension_high = not peak < REARM_FRACTION * limit
        if peak <= limit:
            return
        why = f"tension {peak:.4g} N of {where} beyond slave.max_tension {limit:g} N"
        if self.tension_fault is None:
            self.counts["tension_trips"] += 1
            self.last_tension_trip = why
        self.tension_fault = why
        self.marker = 0
        self._set_state(SideState.SAFE, now, why)

    def _too_far(self, cmd) -> str | None:
        """Why engaging on ``cmd`` would move the instrument too far at once (for the warning), or None."""
        raise NotImplementedError

    def _decide(self, now: float):
        """The watchdog rules of every slave applied to the latest accepted command (module docstring).

        Returns
        -------
        (Decision, detail)
            ``(SAFE, why)``, or ``(HOLD | REFUSED | ENGAGED, command)``. States, ``cmd_seq``,
            ``marker``, ``commands_applied`` and the ``engage_refused`` count are updated here.
        """
        self._accept(now)
        why = self._command_fault(now) or self._tension_hold() or self._sensor_hold()
        if why is not None:
            if why == "command stale" and self.state != SideState.SAFE:
                self.counts["commands_stale"] += 1
            self._set_state(SideState.SAFE, now, why)
            self.marker = 0
            return Decision.SAFE, why
        rec = self._accepted
        if rec is None:     # _command_fault answers "no command" then
            raise RuntimeError("slave watchdog: no accepted command past the command-fault check")
        cmd = rec.message
        self.cmd_seq = cmd.seq
        if not cmd.engaged:
            self._set_state(SideState.READY, now, "master not engaged")
            self.marker = 0
            return Decision.HOLD, cmd
        if self.state != SideState.ENGAGED:
            far = self._too_far(cmd)
            if far is not None:
                if rec is not self._refused:
                    self._refused = rec
                    self.counts["engage_refused"] += 1
                self._warn(now, "engaged command %d refused: %s", cmd.seq, far)
                return Decision.REFUSED, cmd
        self._set_state(SideState.ENGAGED, now, "master engaged")
        self.marker = cmd.marker
        self.commands_applied += 1
        return Decision.ENGAGED, cmd

    def _publish(self, msg) -> None:
        """Publish the estimate of this cycle (built with seq :attr:`seq`)."""
        self.links.estimate.put(msg)
        self.seq = next_seq(self.seq)

    # ---- files and summary -------------------------------------------------------------------------
    def _write_calibration_json(self, data: dict) -> None:
        """``calibration.json`` in the run directory (none without one)."""
        if self.run_dir is not None:
            self.run_dir.mkdir(parents=True, exist_ok=True)
            (self.run_dir / "calibration.json").write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")

    def _stats_detail(self) -> dict[str, Any]:
        """The node's own counters, between the command counters and the pacer in :meth:`stats`."""
        raise NotImplementedError

    def refusals(self) -> dict[str, int]:
        """Every command-class message refused, by reason (the stats' ``refusals``): ``foreign_source`` (another
        session than the locked master's, :class:`teleop.session.link_security.SourceLock`), ``decode_error`` (commands
        and master heartbeats that did not decode), ``wrong_axes``, ``out_of_range``, ``step``
        (``slave.max_step``), ``out_of_order``, ``duplicate``, ``engage_too_far``, ``stale`` (the command stream
        went stale: SAFE), ``ros2_servo`` and ``ros2_state_command`` (refused ROS 2 commands), and
        ``no_credentials``: connections the side's listener refused for a wrong user/password or certificate
        (:class:`teleop.session.refusal_watch.RefusalWatch`, 0 without one)."""
        cmd, hb, crtk, c = self.links.command, self.links.master_heartbeat, self.links.crtk, self.counts
        lock = getattr(getattr(cmd, "primary", cmd), "source_lock", None)
        return {"foreign_source": 0 if lock is None else int(lock.foreign),
                "decode_error": int(getattr(cmd, "errors", 0)) + int(getattr(hb, "errors", 0)),
                "wrong_axes": c["commands_wrong_axes"], "out_of_range": c["commands_rejected_range"],
                "step": c["commands_step_refused"], "out_of_order": c["commands_out_of_order"],
                "duplicate": c["commands_duplicate"], "engage_too_far": c["engage_refused"],
                "stale": c["commands_stale"],
                "ros2_servo": int(getattr(crtk, "servo_refused", 0)),
                "ros2_state_command": int(getattr(crtk, "state_commands_refused", 0)),
                "no_credentials": 0 if self.links.refused_links is None else self.links.refused_links()}

    def stats(self) -> dict[str, Any]:
        """Counters for the run summary (JSON-serialisable)."""
        cmd = self.links.command
        return {
            "side": "slave",
            "state": self.state.name,
            "cycles": self.cycles,
            "estimates_sent": self.seq,
            "commands_received": int(getattr(cmd, "count", 0)),
            "command_decode_errors": int(getattr(cmd, "errors", 0)),
            "commands_applied": self.commands_applied,
            **self._stats_detail(),
            "refusals": self.refusals(),
            "pacer": dict(self.pacer_stats),
        }
