"""The slave (instrument-side) node of every instrument: latest Command -> axes -> rig -> estimators -> Estimate.

An instrument is a list of axes (:mod:`slave.axis`): a single tendon is one
:class:`~slave.tendon_axis.TendonAxis`, a joint instrument one :class:`~slave.pair_axis.PairAxis` per
antagonistic pair. One :meth:`SlaveNode.step` per cycle (``rig.rate_hz``), given the time by the
caller:

* CALIBRATING (from power-up, when no calibration was given; the life cycle of
  :mod:`slave.calibration_file`): the kind's routine drives the rig (one tendon into its joint limit,
  every tendon of every pair both directions, or every spindle over its stroke); no command is accepted and no estimate
  is sent. When it is done, the axes' estimators are built on the fit and replay the routine's proximal samples so that
  their tension-profile memory matches the tendons'; the fit is saved as calibration data (``calibration_file``) and
  ``calibration.json`` is written. With a calibration (reloaded from ``<calibration.dir>/<instrument>.yaml``, by default
  in the per-user data directory) the node starts SAFE at once, its estimators at rest, and ``calibration.json`` holds
  the reloaded values.
* Then, each cycle, the latest Command decides (latest wins; the watchdog rules are
  :meth:`slave.node_base.SlaveNodeBase._decide`):

  ========================================  ==========  =======================================
  latest accepted command                   state       every axis
  ========================================  ==========  =======================================
  none, older than ``slave.watchdog_ms``,   SAFE        its safe behaviour: a single tendon holds
  or the master's liveliness token gone                 then relaxes toward its pretension; a pair
                                                        relaxes both tendons to the set tension
  fresh, ``engaged=False``                  READY       holds the last applied target
  fresh, ``engaged=True``                   ENGAGED     follows its target (``x_in_cmd`` [m] of a
                                                        tendon, the angle [rad] of a joint)
  any, once a measured ``|T_in|`` passed    SAFE        its safe behaviour, from the cycle
  ``slave.max_tension``, until a fresh                  that samples it on
  ``engaged=False`` with every ``|T_in|``
  back below it
  ========================================  ==========  =======================================

  A command is *accepted* only when it has one target per axis, is newer than the last accepted one
  (sequence number, uint32 wrap: duplicates and reordered old messages are counted and ignored) and
  every target lies within its axis's range (out of range: counted and ignored). Only accepted
  commands feed the watchdog, so a stream of corrupt or impossible commands ends in SAFE within the
  watchdog time. Entering ENGAGED from another state needs every target close to where its axis is
  (:meth:`slave.axis.SlaveAxis.too_far`): a master that has not re-aligned never makes the
  instrument jump.

  the rig's sensors as sampled at the cycle's start, each axis's estimator already run on them (on the
  proximal sensors, never the truth) -> the tension limit -> the command decided -> Estimate (one
  AxisState per axis; the single tendon's profile at ``estimator.profile_points`` points), published;
  then, in the cycle's second phase, the axes' motor commands, rig.step on them (the instrument moves
  until the next cycle samples it, as a real one does between two samples), one CSV row per cycle
  (``slave.csv`` of a single tendon in the measured-data format, ``slave_joints.csv`` of a joint
  instrument), Rerun every ``recording.log_every`` cycles, and the estimators on the new sample. Only the
  decision and the message stand between a command's arrival and the estimate it is echoed in; the
  numbers are those of estimating at the cycle's start. The first cycle after start-up or calibration
  only moves the rig: the estimators have already seen its last state, so it sends no estimate and
  records no row.
* A Heartbeat at ``slave.heartbeat_hz`` carries the state. With ``stop_on_master_stop`` the node
  sets :attr:`done` when the master's heartbeat says STOPPING.

The cycle, the watchdog's reasons and the summary counters: :mod:`slave.node_base`; heartbeat, state
changes and pacing, shared with every node: :mod:`teleop.node`.
"""
from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

from slave.axis import SlaveAxis
from slave.calibration_file import InstrumentCalibration, save_calibration
from slave.kinds import axis_kind
from slave.node_base import Decision, SlaveLinks, SlaveNodeBase
from slave.rig import Rig, RigState, sensor_fault
from slave.tendon_axis import TendonAxis
from teleop.config.schema import Config
from teleop.wire.codec import prepare_estimate
from teleop.wire.messages import Command, Estimate, SideState

__all__ = ["SlaveNode", "recording", "warm_up"]

log = logging.getLogger(__name__)


def recording(cfg: Config, rig: Rig) -> tuple[str, tuple[str, ...], dict[str, str]]:
    """The slave's recording of the configured instrument: file name, columns and metadata (of the rig's own
    axis kind when it has one, ``rig.axis_kind``)."""
    return (getattr(rig, "axis_kind", None) or axis_kind(cfg)).recording(cfg, rig)


def warm_up(cfg: Config) -> None:
    """Compile the rig's and the estimators' numba kernels before the real-time loop starts.

    With an empty numba cache (a fresh checkout) the first call of each kernel takes seconds; done
    inside the loop it would stall the first cycles. Uses throwaway objects: nothing is kept.
    """
    axis_kind(cfg).warm_up(cfg)


class SlaveNode(SlaveNodeBase):
    """Slave side of an instrument's teleoperation loop, one axis or several (module docstring).

    Parameters
    ----------
    cfg : Config
        ``instrument.joints`` given: a joint instrument, else a single tendon.
    rig : Rig
        Of the instrument's tendon shape (:mod:`slave.rig`).
    links : SlaveLinks
    recorder : object with ``write(row)`` (a :class:`teleop.recording.measured.CsvRecorder` with the columns of
        :func:`recording`), or None.
    rerun : a :class:`teleop.rerun.logger.RerunLogger`, or None.
    run_dir : Path or None
        Where calibration.json goes.
    stop_on_master_stop : bool
        Finish when the master announces STOPPING.
    calibrate : bool
        Run the power-up routine unless ``calibration`` is given (False: a single tendon uses
        ``model`` at once, for tests and benchmarks).
    model : SheathModel, optional
        The single tendon's model when ``calibrate`` is False.
    calibration : InstrumentCalibration, optional
        Reloaded calibration data of this instrument (:mod:`slave.calibration_file`); the node starts
        SAFE with it.
    calibration_file : path, optional
        Where the power-up calibration is saved.

    Attributes
    ----------
    axes : list of SlaveAxis
    rig_state : RigState
        The rig's last state.
    routine : the power-up routine, or None.
    calibration : InstrumentCalibration or None

    Raises
    ------
    ValueError
        ``calibrate=False`` without a calibration: a single tendon without ``model``, or a joint
        instrument (it has no such shortcut).
    """

    def __init__(self, cfg: Config, rig: Rig, links: SlaveLinks, *, recorder=None, rerun=None,
                 run_dir: str | Path | None = None, stop_on_master_stop: bool = False,
                 calibrate: bool = True, model=None, calibration: InstrumentCalibration | None = None,
                 calibration_file: str | Path | None = None):
        super().__init__(cfg, links, run_dir=run_dir, stop_on_master_stop=stop_on_master_stop,
                         counts=("commands_rejected_range", "commands_wrong_axes", "commands_out_of_order",
                                 "commands_duplicate", "commands_step_refused", "commands_speed_limited",
                                 "commands_stale", "engage_refused", "tension_trips", "sensor_faults"))
        self.rig = rig
        self.recorder = recorder
        self.rerun = rerun
        self.kind = getattr(rig, "axis_kind", None) or axis_kind(cfg)     # a rig may bring its own kind (recording)
        self.rig_state: RigState = rig.state
        self.axes: list[SlaveAxis] = self.kind.build(cfg, rig)
        self.names = tuple(a.name for a in self.axes)
        self.last_safe_reason: str | None = None
        self.max_step, self.max_speed = cfg.slave.max_step, cfg.slave.max_speed   # [m], [m/s] of tendon travel
        self._followed: tuple | None = None    # the targets followed in the last ENGAGED cycle (speed limit)
        self.calibration_file = None if calibration_file is None else Path(calibration_file)
        self.calibration: InstrumentCalibration | None = calibration
        self.routine: Any = None
        self.calibrated = False
        self._how = "given model"
        self._now = 0.0
        self._observed: RigState = rig.state   # the state this cycle's estimate came from
        self._next: tuple | None = None        # the rig's newest sample and its estimate, for the next cycle
        self._pending: tuple | None = None     # this cycle's (relax, targets, time step), until the second phase
        self._rig_command: Any = None          # the last motor commands sent: held while a sensor is at fault
        if calibration is not None:
            data = self.kind.start_loaded(self.axes, calibration, self.rig_state)
            self._write_calibration_json({**data, "loaded_from": str(self.calibration_file or "")})
            self._started("loaded")
            self._set_state(SideState.SAFE, None, "calibration loaded; no command yet")
        elif calibrate:
            self.routine = self.kind.routine(cfg, rig)
            self._set_state(SideState.CALIBRATING, None, "power-up calibration")
        else:
            if model is None or not isinstance(self.axes[0], TendonAxis):
                raise ValueError("SlaveNode(calibrate=False) needs a single tendon and a SheathModel in model=")
            self.axes[0].start(model)
            self.calibrated = True
            self._set_state(SideState.SAFE, None, "no command yet")

    # ------------------------------------------------------------------------------------------------
    def _started(self, how: str) -> None:
        """The axes run on a calibration (``how``: power-up or loaded); first full Rerun log now: its
        one-off set-up cost (tens of ms) stays out of the engaged loop."""
        self.calibrated, self._how = True, how
        if self.rerun is not None:
            for ax in self.axes:
                ax.log_rerun(self.rerun, self.cycles, self.rig_state, everything=True)

    def _finish_calibration(self, now: float) -> None:
        self.calibration, data = self.kind.finish_routine(self.axes, self.routine, self.rig_state)
        if self.calibration_file is not None:
            save_calibration(self.calibration, self.calibration_file)
        self._write_calibration_json(data)
        self._started("power-up")
        self._set_state(SideState.SAFE, now, "calibrated; waiting for commands")

    def _set_state(self, state: SideState, now: float | None, why: str) -> None:
        if state != self.state:
            self.last_safe_reason = why if state == SideState.SAFE else None
        super()._set_state(state, now, why)

    # ---- commands ----------------------------------------------------------------------------------
    def _fits(self, cmd, now: float) -> bool:
        if isinstance(cmd, Command) and len(cmd.targets) == len(self.axes):
            return True
        self.counts["commands_wrong_axes"] += 1
        self._warn(now, "rejected command: expected a Command with one target per axis (%d: %s)", len(self.axes),
                   ", ".join(self.names))
        return False

    def _in_range(self, cmd: Command, now: float) -> bool:
        for ax, target in zip(self.axes, cmd.targets, strict=False):
            why = ax.out_of_range(target)
            if why is not None:
                self.counts["commands_rejected_range"] += 1
                self._warn(now, "rejected command %d: %s", cmd.seq, why)
                return False
        return self._step_within(cmd, now)

    def _step_within(self, cmd: Command, now: float) -> bool:
        """Whether every target of ``cmd`` lies within ``slave.max_step`` of tendon travel of the last accepted
        command's when both are engaged (counted as ``commands_step_refused`` if not). A command not engaged
        moves nothing; after one, or after a gap longer than ``slave.watchdog_ms``, there is nothing to step
        from: the engage check (:meth:`_too_far`) judges the command against the measured axes instead."""
        rec = self._accepted
        if rec is None or now - rec.t_recv > self.watchdog or not (cmd.engaged and rec.message.engaged):
            return True
        for ax, target, before in zip(self.axes, cmd.targets, rec.message.targets, strict=False):
            step = abs(target - before) * ax.tendon_per_unit
            if not step <= self.max_step:
                self.counts["commands_step_refused"] += 1
                self._warn(now, "refused command %d: %s would move a tendon %.3g mm at once (slave.max_step %.3g mm)",
                           cmd.seq, ax.name, 1e3 * step, 1e3 * self.max_step)
                return False
        return True

    def _speed_limited(self, targets: tuple, dt: float) -> tuple:
        """The targets the axes follow this cycle: each moves from the last followed one toward the command's
        by at most ``slave.max_speed dt`` of tendon travel (counted as ``commands_speed_limited`` cycles)."""
        prev, out = self._followed, targets
        if prev is not None:
            lims = [self.max_speed * dt / ax.tendon_per_unit for ax in self.axes]
            out = tuple(t if abs(t - p) <= lim else (p + lim if t > p else p - lim)
                        for t, p, lim in zip(targets, prev, lims, strict=False))
            if out != tuple(targets):
                self.counts["commands_speed_limited"] += 1
        self._followed = out
        return out

    def _too_far(self, cmd: Command) -> str | None:
        far = [w for w in (ax.too_far(t, self.rig_state) for ax, t in zip(self.axes, cmd.targets, strict=False))
               if w is not None]
        return "; ".join(far) if far else None

    def _decision(self, now: float, dt: float) -> tuple[bool, tuple]:
        """The watchdog's decision on the latest accepted command (:meth:`_decide`) as (relax, one target
        or None per axis): SAFE (also an engage refused while SAFE) -> relax, ENGAGED -> the targets (speed
        limited, :meth:`_speed_limited`), else hold (no target)."""
        decision, detail = self._decide(now)
        relax = decision is Decision.SAFE or (decision is Decision.REFUSED and self.state == SideState.SAFE)
        if relax and self.last_safe_reason is None:
            self.last_safe_reason = detail if decision is Decision.SAFE else "engaged command too far"
        self.marker = 0 if relax else self.marker
        if decision is Decision.ENGAGED:
            return relax, self._speed_limited(detail.targets, dt)
        self._followed = None
        return relax, (None,) * len(self.axes)

    # ---- the cycle ---------------------------------------------------------------------------------
    def _calibration_step(self, now: float, dt: float) -> None:
        routine = self.routine
        self.rig_state = self.kind.routine_step(routine, self.rig, self.rig_state, dt)
        if self.rerun is not None:
            for ax in self.axes:
                ax.log_calibration(self.rerun, self.cycles, self.cfg.recording.log_every, self.rig_state)
        if routine.done:
            self._finish_calibration(now)

    def _control_step(self, now: float, dt: float) -> None:
        self._now = now
        sample = self._next
        if sample is None:
            # the first cycle after start-up or calibration: the estimators have seen the rig's last state
            self._pending = (*self._decision(now, dt), dt)
            return
        # the rig's sensors as sampled when it stepped at the end of the last cycle, already estimated there
        self._observed, axes, profiles = sample
        self._check_tension(axes, now)                  # past slave.max_tension: SAFE in this cycle
        self._pending = (*self._decision(now, dt), dt)
        self._publish(Estimate(self.seq, self.cmd_seq, now, axes, profiles))

    def _control_after(self, now: float) -> None:
        """The cycle's motor commands and the rig stepped on them (the instrument moves until the next cycle
        samples it, as a real one does), the cycle's row of the state its estimate came from, then the
        estimators on the new sample, ready for the next cycle's estimate."""
        st, recorded = self._observed, self._next is not None
        pending, self._pending = self._pending, None
        if pending is not None:
            relax, targets, dt = pending
            if self.sensor_faulty and self._rig_command is not None:
                command = self._rig_command         # no reading to control on: the motors hold where they are
            else:
                command = self.kind.rig_command(self.kind.motor_all(self.axes, relax, targets, self.rig_state, dt))
            self._rig_command = command
            self.rig_state = self.rig.step(command, dt)
            if self._sensor_check(now):
                self._next = None                   # nothing estimated on it, no estimate sent next cycle
                return
        if recorded:
            if self.recorder is not None:
                common = (self.marker, self.cmd_seq, int(self.state), now,
                          0.0 if self._accepted is None else self._accepted.t_recv)
                self.recorder.write(self.kind.csv_row(st, common, self.axes))
            if self.rerun is not None:
                for ax in self.axes:
                    ax.log_rerun(self.rerun, self.cycles, st)
        if pending is not None:
            observed = self.kind.observe_all(self.axes, self.rig_state)
            axes, profiles = tuple(a for a, _ in observed), tuple(p for _, p in observed if p)
            prepare_estimate(axes, profiles)        # its body encoded now: the send packs the header only
            self._next = (self.rig_state, axes, profiles)

    def _sensor_check(self, now: float) -> bool:
        """Whether the rig's newest sample is at fault (:func:`slave.rig.sensor_fault`); the first faulty
        sample of a fault counts (``sensor_faults``), is logged and holds SAFE until :meth:`_sensor_hold`
        releases it."""
        why = sensor_fault(self.rig_state)
        self.sensor_faulty = why is not None
        if why is None:
            return False
        if self.sensor_fault is None:
            self.counts["sensor_faults"] += 1
            log.error("sensor fault: %s; motors held, SAFE until the readings are good and the operator lets go",
                      why)
        self.sensor_fault = why
        return True

    # ---- summary -----------------------------------------------------------------------------------
    def _stats_detail(self) -> dict[str, Any]:
        return {
            **self.counts,
            "safe_events": self.safe_events,
            "last_safe_reason": self.last_safe_reason,
            "last_tension_trip": self.last_tension_trip,
            "stalls": self.stalls,
            "master_stopped": self.master_stopped,
            "calibrated": self.calibrated,
            "calibration": self._how if self.calibrated else "none yet",
            "axes": list(self.names),
            **self.kind.stats(self.axes),
        }
