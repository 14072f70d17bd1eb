"""An antagonistic tendon pair as one axis of a joint instrument: joint angle in, joint torque and angle out.

* Power-up: :class:`slave.pair_calibrate.PairCalibration` pulls every tendon into its joint limit
  (all joints at once, both directions); every joint estimator replays the routine's proximal
  samples so that its profile memory matches the tendons'. A reloaded calibration starts the
  estimators at rest and new pair controllers where the motors are.
* Command: the joint angle [rad], accepted within the joint's limits widened by pi + twice the
  stretch of its tendons at ``calibration.target_tension`` over r. The command moves the puller's
  motor by r per radian (the joint lags by the stretch, which the estimate reports), relative to
  where it took over (bumpless), so command and joint angle drift apart by the friction dead zones;
  what bounds the tendons is the motors' travel: every motor command is clipped to the zero pose
  +- (r max(|limits|) + twice that stretch + 2 mm). Engaging needs the commanded angle within
  ``slave.engage_tolerance / r`` of the estimated one (the master anchors at the slave's angle).
* SAFE: no command for the pair controller: both motors hold where they are measured to be when SAFE begins
  (never where the last command was taking them), then both tendons relax to their set tension (rate limited
  by ``slave.relax_speed``) and the joint returns toward rest.
* Each cycle: the pair controller's two motor commands, then
  :class:`~estimator.online.pair.PairEstimator` on the two load cells and encoders (never the
  truth) -> the axis's state (effort = torque_hat [N m], position = angle_hat [rad], both tendons);
  the joint's columns of ``slave_joints.csv`` and its Rerun series. The estimators of all the joints
  step in one compiled call per cycle (:class:`~estimator.online.pair_bank.PairBank`, the same numbers
  as each joint's own step) once each has had its first sample, and so do the pair controllers
  (:class:`~slave.pair_control_bank.PairControlBank`).
"""
from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from estimator.band import NOISE_BAND_SIGMAS
from estimator.online.pair import PairEstimator, PairSample
from estimator.online.pair_bank import PairBank, can_bank
from estimator.phase import Phase
from slave.axis import SlaveAxis
from slave.calibration_file import from_results, sheath_models
from slave.pair_calibrate import PairCalibration, set_tension
from slave.pair_control import PairController
from slave.pair_control_bank import PairControlBank
from slave.rig import TENDONS, InstrumentTruth, Rig, RigState
from teleop.config.schema import Config, JointConfig
from teleop.wire.messages import AxisState, TendonState

__all__ = ["PairAxis", "joint_csv_columns"]

log = logging.getLogger("teleop.slave")

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


class PairAxis(SlaveAxis):
    """One joint of a joint instrument, turned by an antagonistic pair (module docstring).

    Parameters
    ----------
    cfg : Config
        ``calibration.target_tension``, ``estimator``, ``pair_control``, ``slave`` (relax speed,
        engage tolerance), ``recording.log_every``.
    joint : JointConfig
    index : int
        The joint's row in the rig's ``(n_joints, 2)`` arrays.

    Attributes
    ----------
    estimator : PairEstimator or None
    controller : PairController or None
    sample : PairSample or None
        The last estimate.
    bank : PairBank or None
        The bank stepping the estimators of all the instrument's joints (shared by its axes).
    control_bank : PairControlBank or None
        The bank stepping the pair controllers of all the instrument's joints (shared by its axes).
    hold : float or None
        The angle command being followed [rad]; None: relax.
    """

    routine_text = "every tendon pulled into its joint limit, both directions of each pair"

    def __init__(self, cfg: Config, joint: JointConfig, index: int):
        self.cfg, self.joint, self.index, self.name = cfg, joint, index, joint.name
        self.r = self.tendon_per_unit = float(joint.pulley_radius)
        stretch = cfg.calibration.target_tension * max(t.geometry().length / t.EA
                                                       for t in (joint.tendons.a, joint.tendons.b))
        self.cmd_range = (joint.limits[0] - math.pi - 2 * stretch / self.r,
                          joint.limits[1] + math.pi + 2 * stretch / self.r)
        self.travel = self.r * max(abs(v) for v in joint.limits) + 2 * stretch + 0.002
        self.estimator: PairEstimator | None = None
        self.controller: PairController | None = None
        self.sample: Any = None
        self.hold: float | None = None
        self.bank: PairBank | None = None
        self.control_bank: PairControlBank | None = None

    def start(self, models, history, tension_noise: tuple[float, float] = (0.0, 0.0)) -> None:
        """The joint estimator on ``models`` (tendon a, b), the travel limits about the first sample of
        ``history`` (power-up rest), then the replay of ``history`` [(t, x_in, T_in), ...] (rig arrays).
        ``tension_noise`` [N]: the calibration's noise sigma of each tendon's T_in (the noise band), unless the
        config's ``estimator.tension_noise`` is set."""
        e, j, i = self.cfg.estimator, self.joint, self.index
        if self.bank is not None:
            self.bank.release()
        noise = tension_noise if e.tension_noise is None else (e.tension_noise, e.tension_noise)
        self.estimator = PairEstimator(models[0], models[1], self.r, n_nodes=e.n_nodes, pretension=j.pretension,
                                        hold_rate=e.hold_rate, rate_time_constant=e.rate_time_constant,
                                        tension_noise=noise)
        log.info("%s: estimator noise band %.3f N on tendon a, %.3f N on b (T_in noise sigma from the %s)", j.name,
                 NOISE_BAND_SIGMAS * noise[0], NOISE_BAND_SIGMAS * noise[1],
                 "calibration" if e.tension_noise is None else "estimator.tension_noise")
        x0 = history[0][1]
        assert self.controller is not None
        if self.cfg.pair_control.backlash_compensation:      # the dead zone paid out from the calibrated models
            self.controller.band_compliance = (models[0].reversal_compliance, models[1].reversal_compliance)
            self.controller.band_width = self.cfg.pair_control.backlash_width
            self.controller.friction_exponent = (models[0].K, models[1].K)
            log.info("%s: backlash compensation, reversal compliance %.3e m/N (a), %.3e m/N (b) over +/- %g rad",
                     j.name, *self.controller.band_compliance, self.controller.band_width)
        self.controller.x_limits = tuple((x0[i, k] - self.travel, x0[i, k] + self.travel) for k in range(2))
        for t, x, T in history:       # replay: the estimator's memory = its tendons' proximal history
            self.sample = self.estimator.step(T[i, 0], x[i, 0], T[i, 1], x[i, 1], t)

    # ---- per kind ----------------------------------------------------------------------------------
    @classmethod
    def build(cls, cfg: Config, rig: Rig) -> list[SlaveAxis]:
        return [cls(cfg, j, i) for i, j in enumerate(cfg.instrument.joints)]

    @classmethod
    def routine(cls, cfg: Config, rig: Rig) -> PairCalibration:
        return PairCalibration(cfg, rig)

    @classmethod
    def routine_step(cls, routine: PairCalibration, rig: Rig, state: RigState, dt: float) -> RigState:
        return rig.step(routine.command(state, dt), dt)

    @classmethod
    def calibration_of(cls, cfg: Config, routine: PairCalibration) -> Any:
        return from_results(cfg, routine.results)

    @classmethod
    def finish_routine(cls, axes: Sequence[SlaveAxis], routine: PairCalibration,
                       state: RigState) -> tuple[Any, dict]:
        cfg = axes[0].cfg
        calibration = cls.calibration_of(cfg, routine)
        history = routine.history + [(state.t, state.x_in, state.T_in)]
        for ax, ctl, models, (_, tend) in zip(axes, routine.controllers(), sheath_models(calibration, cfg),
                                              calibration.joints, strict=False):
            assert isinstance(ax, PairAxis)
            ax.controller = ctl
            ax.start(models, history, (tend["a"].tension_noise, tend["b"].tension_noise))
        for name, tend in calibration.joints:
            log.info("calibrated %s: K_a = %.4f, K_b = %.4f, M_e,a = %.4e, M_e,b = %.4e m/N", name,
                     tend["a"].K, tend["b"].K, tend["a"].M_e, tend["b"].M_e)
        return calibration, calibration.as_dict()

    @classmethod
    def start_loaded(cls, axes: Sequence[SlaveAxis], calibration: Any, state: RigState) -> dict:
        for ax, models, (_, tend) in zip(axes, sheath_models(calibration, axes[0].cfg), calibration.joints,
                                         strict=False):
            assert isinstance(ax, PairAxis)
            pc, j = ax.cfg.pair_control, ax.joint
            ax.controller = PairController(ax.r, set_tension(ax.cfg, j), pc.tension_gain, pc.switch_band,
                                           ax.cfg.slave.relax_speed, tuple(state.x_in_cmd[ax.index]),
                                           feedforward=pc.feedforward)
            ax.start(models, [(state.t, state.x_in, state.T_in)], (tend["a"].tension_noise, tend["b"].tension_noise))
        return calibration.as_dict()

    @classmethod
    def rig_command(cls, motors: list) -> list:
        return motors

    @classmethod
    def recording(cls, cfg: Config, rig: Rig) -> tuple[str, tuple[str, ...], dict[str, str]]:
        """``slave_joints.csv``, :func:`joint_csv_columns` (truth columns always: a row leaves them out
        only when the rig has no truth) and metadata."""
        names = [j.name for j in cfg.instrument.joints]
        meta = {"source": "teleop slave", "instrument": cfg.instrument.id, "joints": " ".join(names),
                "truth": "torque, angle, T_out, elongation are simulator ground truth (evaluation only)"}
        return "slave_joints.csv", joint_csv_columns(names, True), meta

    @classmethod
    def csv_row(cls, state: RigState, common: tuple, axes: Sequence[SlaveAxis]) -> list:
        marker, cmd_seq, side_state, t_node, t_recv = common
        tr = state.truth if isinstance(state.truth, InstrumentTruth) else None
        row = [state.t, marker, cmd_seq, side_state, t_node, t_recv]
        x_in, T_in, x_cmd = (np.asarray(v).tolist() for v in (state.x_in, state.T_in, state.x_in_cmd))
        if tr is not None:      # plain floats: one conversion per array, none per value
            torque, theta, T_out, elong = (v.tolist() for v in (tr.torque, tr.theta, tr.T_out, tr.elongation))
        cb = _active_control_bank(axes)
        modes = cb.mode.tolist() if cb is not None else [int(ax.controller.mode) for ax in axes
                                                         if isinstance(ax, PairAxis) and ax.controller is not None]
        for ax, mode in zip(axes, modes, strict=False):
            assert isinstance(ax, PairAxis)
            i, s = ax.index, ax.sample
            row += [0.0 if ax.hold is None else ax.hold, mode, s.torque, s.angle]
            row += [torque[i], theta[i]] if tr is not None else []
            for k in range(2):
                row += [x_in[i][k], T_in[i][k], x_cmd[i][k], s.T_out[k], s.elongation[k], int(s.phase[k])]
                row += [T_out[i][k], elong[i][k]] if tr is not None else []
        return row

    @classmethod
    def stats(cls, axes: Sequence[SlaveAxis]) -> dict[str, Any]:
        cb = _active_control_bank(axes)
        return {"joints": [a.name for a in axes],
                "side_switches": cb.switches.tolist() if cb is not None else
                [a.controller.switches for a in axes if isinstance(a, PairAxis) and a.controller is not None]}

    @classmethod
    def warm_up(cls, cfg: Config) -> None:
        from estimator.sheath import SheathModel
        from slave.pair_rig import SimulatedInstrument

        SimulatedInstrument(cfg.instrument.joints[:1], cfg.rig.simulated).step([[1e-4, 1e-4]], 1e-3)
        m = SheathModel(K=0.5, compliance=1e-4)
        est = PairEstimator(m, m, 0.004, n_nodes=4)
        est.step(1.0, 0.0, 0.5, 0.0, 0.0)
        est.step(1.1, 0.0, 0.5, 0.0, 1e-3)      # the compiled step (every sample after the first)
        PairBank([est]).step(np.array([[1.2, 0.5]]), np.zeros((1, 2)), 2e-3)     # and the banks' loops
        PairControlBank([PairController(0.004, 0.25, 0.01, 0.01, 0.05, (0.0, 0.0))]).step(
            np.zeros(1), np.ones((1, 2)), 1e-3, np.zeros((1, 2)))

    @classmethod
    def motor_all(cls, axes: Sequence[SlaveAxis], relax: bool, targets: Sequence[float | None], state: RigState,
                  dt: float) -> Any:
        """:meth:`motor` of every joint, the pair controllers stepped together by their :class:`PairControlBank`
        when they can be (the same numbers; module docstring): the motor commands [m], shape (n_joints, 2)."""
        bank = _control_bank_of(axes, state)
        if bank is None:
            return [ax.motor(relax, t, state, dt) for ax, t in zip(axes, targets, strict=False)]
        holds, x_out = [], []
        for ax, t in zip(axes, targets, strict=False):
            assert isinstance(ax, PairAxis)
            if relax:
                if ax.hold is not None:         # SAFE begins: the motors from their measured positions
                    bank.X[ax.index] = state.x_in[ax.index]
                ax.hold = None
            elif t is not None:
                ax.hold = t
            holds.append(math.nan if ax.hold is None else ax.hold)
            x_out.append(ax.sample.x_out)
        return bank.step(np.array(holds, dtype=np.float64), state.T_in, dt, np.array(x_out, dtype=np.float64)).copy()

    @classmethod
    def observe_all(cls, axes: Sequence[SlaveAxis], state: RigState) -> list[tuple[AxisState, tuple[float, ...]]]:
        """:meth:`observe` of every joint, the estimators stepped together by their :class:`PairBank` when
        they can be (the same numbers; module docstring)."""
        bank = _bank_of(axes, state)
        if bank is None:
            return [ax.observe(state) for ax in axes]
        out = bank.step(state.T_in, state.x_in, state.t).tolist()
        T, X = state.T_in.tolist(), state.x_in.tolist()
        res: list[tuple[AxisState, tuple[float, ...]]] = []
        for ax, o, (Ta, Tb), (xa, xb) in zip(axes, out, T, X, strict=False):
            pa, pb = _PHASES[int(o[10])], _PHASES[int(o[11])]
            assert isinstance(ax, PairAxis)
            ax.sample = PairSample(o[0], o[1], (o[2], o[3]), (o[4], o[5]), (o[6], o[7]), o[8], o[9], (pa, pb))
            tendons = (TendonState(Ta, xa, o[2], o[4], pa), TendonState(Tb, xb, o[3], o[5], pb))
            res.append((AxisState(o[0], o[1], tendons), ()))
        return res

    # ---- per axis ----------------------------------------------------------------------------------
    def out_of_range(self, target: float) -> str | None:
        lo, hi = self.cmd_range
        if lo <= target <= hi:
            return None
        return f"{self.name} angle {target:.4g} rad outside [{lo:.3g}, {hi:.3g}] rad"

    def too_far(self, target: float, state: RigState) -> str | None:
        if abs(target - self.sample.angle) * self.r <= self.cfg.slave.engage_tolerance:
            return None
        return f"{self.name} angle {target:.4g} rad too far from the estimate {self.sample.angle:.4g} rad"

    def motor(self, relax: bool, target: float | None, state: RigState, dt: float) -> Any:
        assert self.controller is not None
        if relax:
            if self.hold is not None:           # SAFE begins: the motors from their measured positions
                self.controller.x_cmd = [float(x) for x in state.x_in[self.index]]
            self.hold = None
        elif target is not None:
            self.hold = target
        Ta, Tb = state.T_in[self.index].tolist()         # plain floats: cheaper arithmetic, the same values
        return self.controller.step(self.hold, (Ta, Tb), dt, self.sample.x_out)

    def observe(self, state: RigState) -> tuple[AxisState, tuple[float, ...]]:
        assert self.estimator is not None
        (Ta, Tb), (xa, xb) = state.T_in[self.index].tolist(), state.x_in[self.index].tolist()
        s = self.sample = self.estimator.step(Ta, xa, Tb, xb, state.t)
        return AxisState(s.torque, s.angle, (TendonState(Ta, xa, s.T_out[0], s.elongation[0], s.phase[0]),
                                             TendonState(Tb, xb, s.T_out[1], s.elongation[1], s.phase[1]))), ()

    def log_rerun(self, rerun: Any, cycles: int, state: RigState, everything: bool = False) -> None:
        """Every ``recording.log_every`` cycles the joint's torque and angle, estimate and truth; every
        ``recording.profile_every`` of those also both tendons' estimated tension profiles (the 3D view).
        The joints take turns in successive cycles so that no cycle queues more than one joint's log."""
        n = self.cfg.recording.log_every
        k, i, s = cycles % n, self.index, self.sample
        if not (everything or k == i % n):
            return
        tr = state.truth if isinstance(state.truth, InstrumentTruth) else None
        est = self.estimator
        show = everything or (cycles // n) % max(1, self.cfg.recording.profile_every) == 0
        rerun.log_joint(state.t, self.name, torque_hat=s.torque, angle_hat=s.angle,
                        torque_true=None if tr is None else float(tr.torque[i]),
                        angle_true=None if tr is None else float(tr.theta[i]),
                        profiles=(est.tendons[0].profile, est.tendons[1].profile) if show and est is not None else None)


_PHASES = tuple(Phase(k) for k in range(len(Phase)))


def _bank_of(axes: Sequence[SlaveAxis], state: RigState) -> PairBank | None:
    """The active bank of ``axes`` (one per joint, rows 0..n-1 of the rig's arrays in order), built when every
    estimator is ready for it; None while one is not (the joints step on their own)."""
    first = axes[0]
    if isinstance(first, PairAxis) and first.bank is not None and first.bank.active:
        return first.bank
    if not _rows_in_order(axes, state):
        return None
    ests = [ax.estimator for ax in axes if isinstance(ax, PairAxis) and ax.estimator is not None]
    if len(ests) != len(axes) or not all(can_bank(e) and e._bank is None for e in ests):
        return None
    bank = PairBank(ests)
    for ax in axes:
        assert isinstance(ax, PairAxis)
        ax.bank = bank
    return bank


def _rows_in_order(axes: Sequence[SlaveAxis], state: RigState) -> bool:
    """Whether ``axes`` are pair axes on rows 0..n-1 of the rig's arrays, in order (what a bank steps)."""
    return [ax.index if isinstance(ax, PairAxis) else -1 for ax in axes] == list(range(len(axes))) \
        and np.shape(state.T_in) == (len(axes), 2)


def _active_control_bank(axes: Sequence[SlaveAxis]) -> PairControlBank | None:
    """The active controller bank of ``axes``, if any (its rows are the axes in order)."""
    first = axes[0]
    cb = first.control_bank if isinstance(first, PairAxis) else None
    return cb if cb is not None and cb.active else None


def _control_bank_of(axes: Sequence[SlaveAxis], state: RigState) -> PairControlBank | None:
    """The controller bank of ``axes`` (rows 0..n-1 of the rig's arrays in order), built when every axis has a
    controller and an estimate and none is banked; a bank of controllers the axes no longer have is released."""
    ctls = [ax.controller for ax in axes if isinstance(ax, PairAxis)]
    cb = _active_control_bank(axes)
    if cb is not None:
        if len(ctls) == len(cb.controllers) and all(a is b for a, b in zip(ctls, cb.controllers, strict=False)):
            return cb
        cb.release()
    if not _rows_in_order(axes, state):
        return None
    ready = [c for c, ax in zip(ctls, axes, strict=False)
             if c is not None and c._bank is None and isinstance(ax, PairAxis) and ax.sample is not None]
    if len(ready) != len(axes):
        return None
    cb = PairControlBank(ready)
    for ax in axes:
        assert isinstance(ax, PairAxis)
        ax.control_bank = cb
    return cb
