"""The master (operator-side) node of every instrument: device -> command, latest estimate -> safe forces.

An instrument is a list of axes (:mod:`master.axes`): one for a single tendon (positions in m),
one per antagonistic pair for a joint instrument (angles in rad); both speak the one Command and
Estimate of :mod:`teleop.wire.messages` with one entry per axis. Every axis gets the whole console, the force map and a
passivity controller; the node is ENGAGED only while every axis's console is. One :meth:`MasterNode.step` per cycle (1
kHz), given the time by the caller:

1. show the operator the latest proximal tension (simulated operators only), read the device;
2. link health: the last *accepted* estimate is fresh (younger than ``master.watchdog_ms``), the
   command it echoes was sent less than ``2 watchdog_ms`` ago (the round trip: catches delay and loss
   on the way out too, without synchronised clocks; budget ``2 watchdog_ms``, one per leg, so a
   process stall on top of an allowed one-way delay does not trip it), the slave's heartbeat is fresh (younger than
   ``max(watchdog_ms, 3 heartbeat periods)``) and says READY or ENGAGED, and its liveliness token
   (when watched) is present. An estimate is accepted when its seq is newer than the last accepted
   one (duplicates and reordered ones are counted and ignored) and ``|T_in|``, ``|T_out_hat|`` are
   below ``master.max_tension`` (else counted as rejected). While the newest estimate carries a
   tension beyond ``master.max_tension`` no command is sent (step 4): a tendon driven into its limit
   is not held there; the slave's watchdog relaxes the instrument within ``slave.watchdog_ms``;
3. the console of each axis (:mod:`master.console`: deadman, clutch, alignment; the deadman and the
   clutch button are shared, the alignment is checked per axis in its own unit) decides ENGAGED;
   an axis still engaged while another is not is dropped, so that it is checked again. Entering it
   re-anchors or checks the alignment and restarts the force ramp and the passivity observer.
   Leaving it because of the links or the deadman: SAFE, zero force at once, commands sent with
   ``engaged=False`` (the slave holds); clutch or misalignment: READY. A SAFE caused by a tension
   (the newest estimate beyond ``master.max_tension``, or the slave going SAFE on an estimate whose
   measured ``|T_in|`` is beyond ``slave.max_tension``) *latches*: the instrument does not engage again,
   whatever the links and the alignment say, until the operator releases the deadman or presses the
   clutch (:attr:`MasterNode.tension_latched`); a hand that keeps pushing does not drive the tendon
   into its limit again;
4. unless the newest estimate is beyond ``master.max_tension`` (step 2), publish the command (``Command(seq, t_master,
   targets, engaged, marker)``, one target per axis: ``x_in_cmd`` of a tendon, the angle of a joint) and keep its send
   time by seq in a ring buffer; an Estimate echoing ``cmd_seq`` gives the round-trip latency;
5. render ``-force_scale * T_k`` on each axis (``T_out_hat`` of a tendon, ``effort_hat / r`` (torque / r) of a pair)
   ramped, clamped, slew-limited (:class:`master.mapping.ForceMap`), then through the passivity controller
   (:mod:`master.passivity`, velocity from successive device positions; ``master.mapping.passivity``), then clamped
   again: no force above ``master.mapping.force_limit`` ever reaches the device;
6. publish a Heartbeat at ``slave.heartbeat_hz`` (both sides use that rate), record one CSV row.

Steps 1-4 are the cycle's first phase (:meth:`MasterNode.step_send`), 5-6 its second
(:meth:`MasterNode.step_after`): two arms stepped in one loop send both commands before either renders.

When the device reports ``finished`` (a scripted operator at the end of its protocol) the node
disengages, announces STOPPING for ``stop_linger`` seconds and sets :attr:`done`.

The link side (estimate acceptance, echo, link health, STOPPING, summary counters) is
:mod:`master.node_base`; heartbeat, state changes and pacing are shared with every node:
:mod:`teleop.node`. A device reports ``position`` (one axis) or ``positions`` (several) and takes
``set_force`` or ``set_forces``.
"""
from __future__ import annotations

import math
from typing import Any

from master.axes import InstrumentAxes
from master.console import Console, ConsoleStatus
from master.device import DeviceState
from master.kinds import instrument_axes
from master.mapping import ForceMap, MotionMap, clamp_force
from master.node_base import MasterLinks, MasterNodeBase
from master.passivity import PassivityController
from master.protocols import experiment_label
from teleop.config.schema import Config
from teleop.timing.clock import Clock
from teleop.wire.messages import SideState

__all__ = ["MasterNode", "csv_columns", "csv_units"]

_WAITING = {ConsoleStatus.WAIT_OPERATOR: "operator not present", ConsoleStatus.CLUTCH: "clutch held"}


def csv_columns(cfg: Config) -> tuple[str, ...]:
    """Columns of the master's recording for the configured instrument (:mod:`master.axes`)."""
    return instrument_axes(cfg).csv_columns()


def csv_units(cfg: Config) -> dict[str, str]:
    """Units of :func:`csv_columns`."""
    return instrument_axes(cfg).csv_units()


class MasterNode(MasterNodeBase):
    """Master side of an instrument's teleoperation loop, one axis or several (module docstring).

    Parameters
    ----------
    cfg : Config
        ``master`` (rate, mapping, watchdog, max_tension), ``slave.heartbeat_hz``; for a joint
        instrument ``instrument.joints`` (pulley radii) and ``pair_control.axes``.
    device : a haptic device: ``read(t)`` -> a state with ``position`` [m] (one axis) or ``positions``
        (one per device axis), ``buttons``, ``operator_present``; ``set_force(f, t)`` or
        ``set_forces(forces, t)`` [N]. Optionally ``watch(view, engaged)`` (simulated operators: the
        proximal tension, or per joint the pair's), ``on_console(status)``, ``finished``, ``marker``.
    links : MasterLinks
    stop_linger : float
        Time the STOPPING state is announced before :attr:`done` [s].
    recorder : object with ``write(row)`` (a :class:`teleop.recording.measured.CsvRecorder` with
        :func:`csv_columns`), or None.
    axes : InstrumentAxes, optional
        The instrument's axes (default :func:`master.axes.instrument_axes` of ``cfg``).
    rerun : object with ``log_master`` (a :class:`teleop.rerun.logger.RerunLogger` made with
        ``wall_clock=True``), or None: master-side series for the live view every ``recording.log_every``
        cycles.

    Attributes
    ----------
    consoles, motion, forces, passivity : list, one per axis.
    force, force_cmd : list of float, the last rendered and mapped force per axis [N].
    status : ConsoleStatus, of the instrument (the lowest of the axes').
    over_tension : bool, the newest estimate carries a tension beyond ``master.max_tension`` (no command
        is sent while it does).
    tension_latched : bool, a SAFE caused by a tension holds until the deadman is released or the clutch
        pressed (module docstring, step 3); ``tension_latches`` counts them.
    """

    def __init__(self, cfg: Config, device, links: MasterLinks, *, stop_linger: float = 0.2, recorder=None,
                 axes: InstrumentAxes | None = None, rerun=None):
        super().__init__(cfg, device, links, stop_linger=stop_linger,
                         counts=("estimates_rejected_range", "estimates_out_of_order", "estimates_duplicate",
                                 "estimates_wrong_instrument"))
        self.recorder = recorder
        self.rerun = rerun                       # master-side series for the live view, or None
        self._rerun_count = 0
        self.axes = axes or instrument_axes(cfg)
        m = cfg.master.mapping
        r = self.axes.radius
        self.motion = [MotionMap(m.motion_scale / rk) for rk in r]
        self.forces = [ForceMap.from_config(m) for _ in r]
        self.consoles = [Console(mm, m.align_tolerance / rk, m.clutch_button, unit_length=rk)
                         for mm, rk in zip(self.motion, r, strict=False)]
        self.passivity = [PassivityController(m.force_limit, enabled=m.passivity, reserve=m.passivity_reserve)
                          for _ in r]
        self.limit = m.force_limit
        self.status = ConsoleStatus.WAIT_SLAVE
        self.align_refusals = 0                  # engage attempts refused for a misaligned axis
        self._p_prev: list[float | None] = [None] * len(r)
        self._period = 1.0 / cfg.master.rate_hz
        self.force_cmd = [0.0] * len(r)
        self.force = [0.0] * len(r)
        self.max_abs_force = 0.0
        self.over_tension = False                # the newest estimate is beyond master.max_tension: no command
        self.slave_limit = cfg.slave.max_tension  # [N] the slave's own limit on a measured |T_in|
        self.tension_latched = False             # a SAFE caused by a tension: no engaging until let go
        self._since_safe = False                 # SAFE from ENGAGED, the deadman held since: a tension latches
        self.tension_latches = 0
        self._cycle: tuple | None = None         # the first phase's results, until the second phase

    @property
    def device(self):
        """The haptic device; its optional hooks (``watch``, ``on_console``, ``set_forces``) are looked up
        once when it is set, not every cycle."""
        return self._device

    @device.setter
    def device(self, device) -> None:
        self._device = device
        self._watch = getattr(device, "watch", None)
        self._on_console = getattr(device, "on_console", None)
        self._set_forces = getattr(device, "set_forces", None)

    # ------------------------------------------------------------------------------------------------
    def _fits(self, est, now: float) -> bool:
        if self.axes.fits(est):
            return True
        self.counts["estimates_wrong_instrument"] += 1
        return False

    def _in_range(self, est, now: float) -> bool:
        self.over_tension = not all(abs(v) <= self.max_tension for v in self.axes.tensions(est))
        if not self.over_tension:
            return True
        self.counts["estimates_rejected_range"] += 1
        self._warn(now, "rejected estimate %d: a tension beyond master.max_tension %g N", est.seq, self.max_tension)
        return False

    def _tension_caused(self, est) -> bool:
        """Whether a SAFE now is caused by a tension: the newest estimate is beyond ``master.max_tension``,
        or a measured ``|T_in|`` of the last accepted one is beyond ``slave.max_tension``."""
        if self.over_tension:
            return True
        return est is not None and any(not abs(t.T_in) <= self.slave_limit for a in est.axes for t in a.tendons)

    def _tension_latch(self, dev, healthy: bool, reason: str) -> tuple[bool, str]:
        """The link health the consoles see: not healthy while the tension latch holds. Releasing the
        deadman or pressing the clutch ends the latch, and ends the watch of :meth:`_latch_on_tension`."""
        if self._since_safe and (not dev.operator_present or self.consoles[0].clutch_held(dev)):
            self._since_safe = self.tension_latched = False
        if self.tension_latched:
            return False, "tension latch: release the deadman or press the clutch to engage again"
        return healthy, reason

    def _latch_on_tension(self, was_engaged: bool, est) -> None:
        """Latch a SAFE caused by a tension (module docstring, step 3). From ENGAGED -> SAFE until the
        operator lets go or the arm engages again, each cycle looks at the newest estimate: the slave's
        estimate of the cycle it tripped may arrive a cycle after its heartbeat saying SAFE."""
        if self.state == SideState.ENGAGED:
            self._since_safe = False
        elif was_engaged and self.state == SideState.SAFE:
            self._since_safe = True
        if self._since_safe and not self.tension_latched and self._tension_caused(est):
            self.tension_latched = True
            self.tension_latches += 1
            self.log.warning("master SAFE on a tendon's tension (%s): engaging again needs the deadman released "
                             "or the clutch pressed", self.last_reason)

    def _disengage_all(self) -> None:
        for f, c in zip(self.forces, self.consoles, strict=False):
            f.disengage()
            c.stop()
        self.status = ConsoleStatus.STOPPING

    def _positions(self, dev) -> list[float]:
        """The device position of each instrument axis [m] (NaN for a missing device axis)."""
        ps = getattr(dev, "positions", None)
        ps = (dev.position,) if ps is None else tuple(ps)
        return [float(ps[a]) if a < len(ps) else math.nan for a in self.axes.device_axes]

    def _consoles(self, now: float, dev, pos: list[float], healthy: bool, reason: str, est) -> None:
        """Every axis's console, then the instrument's state (module docstring, step 3)."""
        q = [None] * len(pos) if est is None else self.axes.slave_positions(est)
        for c, p, qk in zip(self.consoles, pos, q, strict=False):
            # a one-axis device's own state when it holds this very position (no new object per cycle)
            d = dev if type(dev) is DeviceState and dev.position is p else \
                DeviceState(dev.t, p, dev.buttons, dev.operator_present)
            c.update(d, healthy, qk)
        status = min(c.status for c in self.consoles)
        self.align_refusals += status == ConsoleStatus.ALIGN and self.status != ConsoleStatus.ALIGN
        self.status = status
        if self._on_console is not None:
            self._on_console(status)
        if status == ConsoleStatus.ENGAGED:
            if self.state != SideState.ENGAGED:      # ramp and passivity observer start afresh
                for f, pc in zip(self.forces, self.passivity, strict=False):
                    f.engage()
                    pc.reset()
                self.engage_count += 1
                self._set_state(SideState.ENGAGED, now, "slave ready, links fresh, aligned")
            return
        for c, f in zip(self.consoles, self.forces, strict=False):
            if self.state == SideState.ENGAGED:
                f.disengage()
            c.drop()                                  # an engaged axis is checked again with the others
        worst = next(c for c in self.consoles if c.status == status)
        many = len(self.consoles) > 1
        axis = f"{self.axes.names[self.consoles.index(worst)]}: " if many else ""
        self.last_reason = (reason if not healthy else "no slave position") if status == ConsoleStatus.WAIT_SLAVE \
            else _WAITING.get(status) or axis + worst.prompt()
        if status == ConsoleStatus.ALIGN:
            self._warn(now, "master: %s", self.last_reason)
        if status in (ConsoleStatus.WAIT_SLAVE, ConsoleStatus.WAIT_OPERATOR):
            if self.state == SideState.ENGAGED:      # a safe event
                self._set_state(SideState.SAFE, now, self.last_reason)
            elif self.state == SideState.STARTING:
                self._set_state(SideState.READY, now, "device read")
        else:
            self._set_state(SideState.READY, now, self.last_reason)

    def step_send(self, now: float) -> None:
        """A master cycle's first phase at ``now`` [s]: the estimate looked at, the device read, the
        console, the command sent (see the module docstring)."""
        self._cycle = None
        if self.done:
            return
        self._receive(now)
        est, healthy, reason = self._peer_status(now)
        if self._watch is not None:
            self._watch(self.axes.view(est), self.state == SideState.ENGAGED)
        dev = self.device.read(now)
        pos = self._positions(dev)
        if not self._stopping(now, bool(getattr(self.device, "finished", False))):
            healthy, reason = self._tension_latch(dev, healthy, reason)
            was_engaged = self.state == SideState.ENGAGED
            self._consoles(now, dev, pos, healthy, reason, est)
            self._latch_on_tension(was_engaged, est)
        engaged = self.state == SideState.ENGAGED

        # ---- command ----
        q = [mm.command(p) if engaged else mm.last for mm, p in zip(self.motion, pos, strict=False)]
        marker = int(getattr(self.device, "marker", 0)) if engaged else 0
        if not self.over_tension:                # a tendon at its limit: the slave's watchdog relaxes it
            self._send_command(self.axes.command(self.seq, now, q, engaged, marker), now)
        self._cycle = (est, healthy, engaged, pos, q, marker)

    def step_after(self, now: float) -> None:
        """A master cycle's second phase at ``now`` [s]: forces rendered, recordings, heartbeat, CRTK state."""
        if self._cycle is None:
            return
        (est, healthy, engaged, pos, q, marker), self._cycle = self._cycle, None
        # ---- forces, per axis: map (scale, ramp, clamp, slew) -> passivity controller -> clamp ----
        dt = self._period if self._t_prev is None else now - self._t_prev
        self._t_prev = now
        rendered = [math.nan] * len(pos) if est is None else self.axes.rendered(est)
        for k, (fm, pc, p, T) in enumerate(zip(self.forces, self.passivity, pos, rendered, strict=False)):
            self.force_cmd[k] = fm.step(T, now, fresh=engaged and healthy)
            prev = self._p_prev[k]
            p = p if math.isfinite(p) else math.nan
            v = 0.0 if prev is None else (p - prev) / dt if dt > 0 else math.nan
            if math.isfinite(p):
                self._p_prev[k] = p
            self.force[k] = clamp_force(pc.step(self.force_cmd[k], v, dt), self.limit)
            self.max_abs_force = max(self.max_abs_force, abs(self.force[k]))
        self._render(self.force, now)
        if self.recorder is not None:
            self._record(now, est, q, pos, rendered, marker)
        if self.rerun is not None:
            self._log_rerun(now, q, marker)

        # ---- heartbeat, CRTK ----
        self._heartbeat(now)
        crtk = self.links.crtk
        if crtk is not None:
            crtk.offer(self.state, pos, tuple(self.force))

    def _render(self, forces: list[float], now: float) -> None:
        """Send one force per instrument axis to its device axis [N]."""
        set_forces = self._set_forces
        if set_forces is None:
            self.device.set_force(forces[0], now)
            return
        out = [0.0] * (max(self.axes.device_axes, default=-1) + 1)
        for a, f in zip(self.axes.device_axes, forces, strict=False):
            out[a] = f
        set_forces(out, now)

    def _record(self, now: float, est, q, pos, rendered, marker: int) -> None:
        rec = self._accepted
        common = (int(self.state), int(self.status), 0.0 if rec is None else rec.t_recv,
                  -1.0 if self._t_echo is None else now - self._t_echo, self.seq - 1 & 0xFFFFFFFF, marker)
        slave = [math.nan] * len(q) if est is None else self.axes.slave_positions(est)
        axes = [(qk, _fin(sk), _fin(p), _fin(T), fc, f, pc.energy) for qk, sk, p, T, fc, f, pc in
                zip(q, slave, pos, rendered, self.force_cmd, self.force, self.passivity, strict=False)]
        self.recorder.write(self.axes.csv_row(now, est, common, axes))

    def _log_rerun(self, now: float, q, marker: int) -> None:
        """Every ``recording.log_every`` cycles: command, rendered and mapped force of every axis
        (``master/<axis>/...`` when there are several), the last round trip (command -> estimate echo)
        [s], the console state and the experiment (marker)."""
        self._rerun_count += 1
        if self._rerun_count % self.cfg.recording.log_every:
            return
        experiment = experiment_label(marker, self.axes.names)
        rtt = self.rtt.last
        many = len(q) > 1
        for k, name in enumerate(self.axes.names):
            self.rerun.log_master(now, x_in_cmd=q[k], force=self.force[k], force_cmd=self.force_cmd[k],
                                  rtt=rtt if k == 0 else None, console=self.status.name, experiment=experiment,
                                  **({"axis": name} if many else {}))

    # ------------------------------------------------------------------------------------------------
    def _run_ended(self, clock: Clock) -> None:
        self._render([0.0] * len(self.force), clock.now())

    def _stats_detail(self) -> dict[str, Any]:
        ps = [p.stats for p in self.passivity]
        return {
            **self.counts,
            "axes": list(self.axes.names),
            "console": self.status.name,
            "clutches": max(c.clutches for c in self.consoles),     # every axis re-anchors on a release
            "align_refusals": self.align_refusals,
            "tension_latches": self.tension_latches,
            "max_abs_force": self.max_abs_force,
            "force_limit": self.limit,
            "passivity": {"enabled": all(p.enabled for p in self.passivity),
                          **{k: sum(getattr(s, k) for s in ps) for k in ("energy", "dissipated", "active_steps")},
                          "steps": max(s.steps for s in ps)},
            "latency_rtt": self.latency_stats(),
            "recording": getattr(self.recorder, "path", None) and str(self.recorder.path),
        }


def _fin(v: float) -> float:
    return v if math.isfinite(v) else 0.0
