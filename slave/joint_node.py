"""The slave node of a joint instrument: latest Command (one angle per joint) -> pair controllers -> instrument ->
joint estimators -> Estimate (one axis per joint), with the same watchdog rules as the single-tendon node.

One :meth:`JointSlaveNode.step` per cycle (``rig.rate_hz``), given the time by the caller:

* CALIBRATING when no calibration was given: :class:`slave.pair_calibrate.PairCalibration` pulls
  every tendon into its joint limit (all joints at once, both directions); the fit is saved as
  calibration data (``calibration_file``) and every joint estimator replays the routine's proximal
  samples so that its profile memory matches the tendons'. With a calibration (reloaded from
  ``configs/calibration/<instrument>.yaml``) the node starts SAFE at once.
* Then, each cycle, the latest Command decides (latest wins):

  ========================================  ==========  ===========================================
  latest accepted command                   state       every joint's pair controller gets
  ========================================  ==========  ===========================================
  none, older than ``slave.watchdog_ms``,   SAFE        no command: both tendons relax to their set
  or the master's liveliness token gone                 tension, the joint returns toward rest
  fresh, ``engaged=False``                  READY       the last applied angle (hold)
  fresh, ``engaged=True``                   ENGAGED     the commanded angle
  ========================================  ==========  ===========================================

  A command is *accepted* only when newer than the last accepted one (uint32 sequence), for this
  many joints, and with every angle within the joint's limits widened by pi + twice the stretch of
  its tendons at ``calibration.target_tension`` over r; others are counted and ignored. The command
  moves the puller's motor by r per radian (the joint lags by the stretch, which the estimate
  reports), relative to where it took over (bumpless), so command and joint angle drift apart by the
  friction dead zones; what bounds the tendons is the motors' travel: every motor command is
  clipped to the zero pose +- (r max(|limits|) + twice that stretch + 2 mm). Entering ENGAGED needs every commanded angle within ``slave.engage_tolerance / r``
  of the estimated one (the master anchors at the slave's angle when it engages).

  controllers -> instrument.step -> JointEstimator.step per joint (proximal sensors only, never the
  truth) -> Estimate -> one CSV row per cycle (``slave_joints.csv``) and Rerun every
  ``recording.log_every`` cycles.
* A Heartbeat at ``slave.heartbeat_hz``; with ``stop_on_master_stop`` the node finishes when the
  master's heartbeat says STOPPING.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from estimator.online.joint import JointEstimator
from slave.calibration_file import InstrumentCalibration, from_results, save_calibration, sheath_models
from slave.node_base import Decision, SlaveLinks, SlaveNodeBase
from slave.pair_calibrate import PairCalibration, set_tension
from slave.pair_control import PairController
from slave.rig import TENDONS, Rig, RigState
from teleop.config import Config
from teleop.messages import AxisState, Command, Estimate, SideState, TendonState

__all__ = ["JointSlaveNode", "joint_csv_columns", "recording", "warm_up"]

_TENDON_COLS = ("x_in", "T_in", "x_in_cmd", "T_out_hat", "elongation_hat", "phase")
_TENDON_TRUTH = ("T_out", "elongation")


def joint_csv_columns(names, has_truth: bool) -> tuple[str, ...]:
    """Columns of ``slave_joints.csv``: time (rig), marker, cmd_seq, state, t_node (the node's clock),
    t_cmd_recv (receive time of the applied command, 0 before any), then per joint ``<name>.cmd``,
    ``.mode``, ``.torque_hat``, ``.angle_hat`` (and ``.torque``, ``.angle`` truth) and per tendon
    ``<name>.<a|b>.x_in``, ``.T_in``, ``.x_in_cmd``, ``.T_out_hat``, ``.elongation_hat``, ``.phase``
    (and ``.T_out``, ``.elongation`` truth)."""
    cols = ["time", "marker", "cmd_seq", "state", "t_node", "t_cmd_recv"]
    for n in names:
        cols += [f"{n}.cmd", f"{n}.mode", f"{n}.torque_hat", f"{n}.angle_hat"]
        cols += [f"{n}.torque", f"{n}.angle"] if has_truth else []
        for t in TENDONS:
            cols += [f"{n}.{t}.{c}" for c in _TENDON_COLS]
            cols += [f"{n}.{t}.{c}" for c in _TENDON_TRUTH] if has_truth else []
    return tuple(cols)


def recording(cfg: Config, rig: Rig) -> tuple[str, tuple[str, ...], dict[str, str]]:
    """The slave's recording of a joint instrument: ``slave_joints.csv``, :func:`joint_csv_columns`
    (truth columns always: a row leaves them out only when the rig has no truth) and metadata."""
    names = [j.name for j in cfg.instrument.joints]
    meta = {"source": "teleop slave", "instrument": cfg.instrument.id, "joints": " ".join(names),
            "truth": "torque, angle, T_out, elongation are simulator ground truth (evaluation only)"}
    return "slave_joints.csv", joint_csv_columns(names, True), meta


def warm_up(cfg: Config) -> None:
    """Compile the instrument's and the joint estimators' numba kernels before the real-time loop
    starts (throwaway objects)."""
    from estimator.sheath import SheathModel
    from slave.joint_rig import SimulatedInstrument

    SimulatedInstrument(cfg.instrument.joints[:1], cfg.rig).step([[1e-4, 1e-4]], 1e-3)
    m = SheathModel(K=0.5, compliance=1e-4)
    JointEstimator(m, m, 0.004, n_nodes=4).step(1.0, 0.0, 0.5, 0.0, 0.0)


class JointSlaveNode(SlaveNodeBase):
    """Slave side of a joint instrument's teleoperation loop (module docstring).

    Parameters
    ----------
    cfg : Config
        With ``instrument.joints`` (1..4).
    instrument : Rig
    links : SlaveLinks
        ``command`` delivers :class:`~teleop.messages.Command`, ``estimate`` takes
        :class:`~teleop.messages.Estimate`.
    recorder : object with ``write(row)`` for :func:`joint_csv_columns`, or None.
    rerun : a :class:`teleop.rerun_log.RerunLogger`, or None.
    calibration : InstrumentCalibration, optional
        Reloaded calibration data; None: calibrate at power-up.
    calibration_file : path, optional
        Where the power-up calibration is saved.
    run_dir : path, optional
        Where ``calibration.json`` (fit vs routine settings) and the stats go.
    stop_on_master_stop : bool
    """

    def __init__(self, cfg: Config, instrument: Rig, links: SlaveLinks, *, recorder=None, rerun=None,
                 calibration: InstrumentCalibration | None = None, calibration_file: str | Path | None = None,
                 run_dir: str | Path | None = None, stop_on_master_stop: bool = False):
        super().__init__(cfg, links, run_dir=run_dir, stop_on_master_stop=stop_on_master_stop,
                         counts=("commands_rejected_range", "commands_wrong_axes", "commands_out_of_order",
                                 "commands_duplicate", "engage_refused"))
        self.instrument = instrument
        self.recorder, self.rerun = recorder, rerun
        self.joints = cfg.instrument.joints
        self.names = tuple(j.name for j in self.joints)
        self.r = np.array([j.pulley_radius for j in self.joints])
        stretch = [cfg.calibration.target_tension * max(t.geometry().length / t.EA for t in (j.tendons.a, j.tendons.b))
                   for j in self.joints]
        self.cmd_range = [(j.limits[0] - math.pi - 2 * e / j.pulley_radius, j.limits[1] + math.pi + 2 * e / j.pulley_radius)
                          for j, e in zip(self.joints, stretch)]
        self.travel = [j.pulley_radius * max(abs(v) for v in j.limits) + 2 * e + 0.002
                       for j, e in zip(self.joints, stretch)]
        self.calibration_file = None if calibration_file is None else Path(calibration_file)
        self.inst_state: RigState = instrument.state
        self.hold: tuple[float, ...] | None = None
        self.estimators: list[JointEstimator] = []
        self.samples: list = []
        self.controllers: list[PairController] = []
        self.calibration: InstrumentCalibration | None = calibration
        self.routine: PairCalibration | None = None
        if calibration is None:
            self.routine = PairCalibration(cfg, instrument)
            self._set_state(SideState.CALIBRATING, 0.0, "power-up joint-limit calibration, both directions")
        else:
            self._start(calibration, history=None)
            self._set_state(SideState.SAFE, 0.0, "calibration loaded; no command yet")

    # ---- set-up ------------------------------------------------------------------------------------
    def _start(self, calibration: InstrumentCalibration, history) -> None:
        e, pc = self.cfg.estimator, self.cfg.pair_control
        self.estimators = [JointEstimator(ma, mb, j.pulley_radius, n_nodes=e.n_nodes, pretension=j.pretension,
                                          hold_rate=e.hold_rate, rate_time_constant=e.rate_time_constant)
                           for j, (ma, mb) in zip(self.joints, sheath_models(calibration, self.cfg))]
        st = self.inst_state
        if history is None:
            self.controllers = [PairController(j.pulley_radius, set_tension(self.cfg, j), pc.tension_gain,
                                               pc.switch_band, self.cfg.slave.relax_speed, tuple(st.x_in_cmd[i]),
                                               feedforward=pc.feedforward) for i, j in enumerate(self.joints)]
            history = [(st.t, st.x_in, st.T_in)]
        # travel limits about the zero pose (the first sample: power-up rest)
        x0 = history[0][1]
        for i, c in enumerate(self.controllers):
            c.x_limits = tuple((x0[i, k] - self.travel[i], x0[i, k] + self.travel[i]) for k in range(2))
        for t, x, T in history:       # replay: each estimator's memory = its tendons' proximal history
            self.samples = [est.step(T[i, 0], x[i, 0], T[i, 1], x[i, 1], t) for i, est in enumerate(self.estimators)]
        # first Rerun log of every series now: its one-off set-up cost stays out of the engaged loop
        self._log_rerun(self.inst_state, everything=True)

    def _finish_calibration(self, now: float) -> None:
        routine = self.routine
        self.calibration = from_results(self.cfg, routine.results)
        self.controllers = routine.controllers()
        self._start(self.calibration, history=routine.history + [(self.inst_state.t, self.inst_state.x_in,
                                                                   self.inst_state.T_in)])
        if self.calibration_file is not None:
            save_calibration(self.calibration, self.calibration_file)
        self._write_calibration_json(self.calibration.as_dict())
        for name, tend in self.calibration.joints:
            self.log.info("calibrated %s: K_a = %.4f, K_b = %.4f, M_e,a = %.4e, M_e,b = %.4e m/N", name,
                          tend["a"].K, tend["b"].K, tend["a"].M_e, tend["b"].M_e)
        self._set_state(SideState.SAFE, now, "calibrated; waiting for commands")

    # ---- commands ----------------------------------------------------------------------------------
    def _fits(self, cmd, now: float) -> bool:
        if isinstance(cmd, Command) and len(cmd.targets) == len(self.joints):
            return True
        self.counts["commands_wrong_axes"] += 1
        self._warn(now, "rejected command: expected a Command with one angle per joint (%d)", len(self.joints))
        return False

    def _in_range(self, cmd: Command, now: float) -> bool:
        for j, a, (lo, hi) in zip(self.joints, cmd.targets, self.cmd_range):
            if not lo <= a <= hi:
                self.counts["commands_rejected_range"] += 1
                self._warn(now, "rejected command %d: %s angle %.4g rad outside [%.3g, %.3g] rad", cmd.seq, j.name, a,
                           lo, hi)
                return False
        return True

    def _too_far(self, cmd: Command) -> str | None:
        far = [abs(a - s.angle) * r > self.cfg.slave.engage_tolerance
               for a, s, r in zip(cmd.targets, self.samples, self.r)]
        return f"angles {[round(a, 4) for a in cmd.targets]} too far from the estimates" if any(far) else None

    def _commands(self, now: float) -> list[float | None]:
        """The watchdog's decision on the latest accepted command (:meth:`_decide`): one angle (or None:
        relax) per joint."""
        decision, detail = self._decide(now)
        if decision is Decision.SAFE:
            self.hold = None
        elif decision is Decision.ENGAGED:
            self.hold = tuple(detail.targets)
        return list(self.hold) if self.hold is not None else [None] * len(self.joints)

    # ---- the cycle ---------------------------------------------------------------------------------
    def _calibration_step(self, now: float, dt: float) -> None:
        x = self.routine.command(self.inst_state, dt)
        self.inst_state = self.instrument.step(x, dt)
        if self.routine.done:
            self._finish_calibration(now)

    def _control_step(self, now: float, dt: float) -> None:
        cmds = self._commands(now)
        st = self.inst_state
        x = [c.step(cmd, st.T_in[i], dt, s.x_out) for i, (c, cmd, s) in
             enumerate(zip(self.controllers, cmds, self.samples))]
        st = self.inst_state = self.instrument.step(x, dt)
        self.samples = [est.step(st.T_in[i, 0], st.x_in[i, 0], st.T_in[i, 1], st.x_in[i, 1], st.t)
                        for i, est in enumerate(self.estimators)]
        self._publish(self._message(now, st))
        self._record(st, cmds, now)

    def _message(self, now: float, st: RigState) -> Estimate:
        joints = tuple(AxisState(s.torque, s.angle, tuple(
            TendonState(float(st.T_in[i, k]), float(st.x_in[i, k]), s.T_out[k], s.elongation[k], s.phase[k])
            for k in range(2))) for i, s in enumerate(self.samples))
        return Estimate(self.seq, self.cmd_seq, now, joints)

    def _record(self, st: RigState, cmds, now: float) -> None:
        tr = st.truth
        if self.recorder is not None:
            row = [st.t, self.marker, self.cmd_seq, int(self.state), now,
                   0.0 if self._accepted is None else self._accepted.t_recv]
            for i, (s, c) in enumerate(zip(self.samples, cmds)):
                row += [0.0 if c is None else c, int(self.controllers[i].mode), s.torque, s.angle]
                row += [tr.torque[i], tr.theta[i]] if tr is not None else []
                for k in range(2):
                    row += [st.x_in[i, k], st.T_in[i, k], st.x_in_cmd[i, k], s.T_out[k], s.elongation[k], int(s.phase[k])]
                    row += [tr.T_out[i, k], tr.elongation[i, k]] if tr is not None else []
            self.recorder.write(row)
        self._log_rerun(st)

    def _log_rerun(self, st: RigState, everything: bool = False) -> None:
        """Every ``recording.log_every`` cycles each joint's torque and angle, estimate and truth (two
        series each); the 2 n_joints pairs take turns in successive cycles so that no cycle carries
        more than one pair (~0.1 ms per series). ``everything``: all of them now (set-up)."""
        if self.rerun is None:
            return
        k = self.cycles % self.cfg.recording.log_every
        tr = st.truth
        for i, (name, s) in enumerate(zip(self.names, self.samples)):
            if everything or k == (2 * i) % self.cfg.recording.log_every:
                self.rerun.log_scalars(st.t, **{f"{name}/torque_hat": s.torque,
                                                f"{name}/torque_true": None if tr is None else float(tr.torque[i])})
            if everything or k == (2 * i + 1) % self.cfg.recording.log_every:
                self.rerun.log_scalars(st.t, **{f"{name}/angle_hat": s.angle,
                                                f"{name}/angle_true": None if tr is None else float(tr.theta[i])})

    # ---- summary -----------------------------------------------------------------------------------
    def _stats_detail(self) -> dict[str, Any]:
        return {"safe_events": self.safe_events, "stalls": self.stalls, "master_stopped": self.master_stopped,
                "calibrated": self.calibration is not None, "joints": list(self.names),
                "side_switches": [c.switches for c in self.controllers], **self.counts}
