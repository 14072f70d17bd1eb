"""A jaw driven by one input spindle through a cable pair, as one axis: jaw angle in, jaw torque and angle out.

* Power-up: :class:`slave.spindle_calibrate.SpindleCalibration` strokes every spindle over its open
  jaw and fits each cable's K from the spindle torque band (proximal signals only); every estimator
  replays the routine's samples so that its profile memory matches the cables'. A reloaded
  calibration starts the estimators at rest where the spindles are.
* Command: the jaw angle [rad], accepted within the jaw's limits widened by pi. The spindle turns by
  (target - the target where it took over) / n_k from where it took over (bumpless), n_k = r_p / r_d,
  clipped to the rest angle +- (max |limits| / n_k + 0.5 rad). Engaging needs the commanded angle within
  ``slave.engage_tolerance / r_d`` of the estimate (the master anchors at the slave's angle).
* SAFE: the spindle returns toward its rest angle at ``slave.relax_speed / r_p`` [rad/s].
* Each cycle: :class:`estimator.online.spindle_estimator.SpindleEstimator` on the spindle's angle and torque
  (never the truth) -> the axis's state (effort = jaw torque [N m], position = jaw angle [rad], per cable
  the estimated proximal tension as T_in, its distal tension, elongation and phase); the joint's
  columns of ``slave_joints.csv`` (:func:`slave.pair_axis.joint_csv_columns`; a cable's x_in is
  +-r_p times the spindle angle) and its Rerun series.
"""
from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from estimator.online.spindle import SpindleParams
from estimator.online.spindle_estimator import SpindleEstimator
from slave.axis import SlaveAxis
from slave.calibration_file import InstrumentCalibration
from slave.pair_axis import joint_csv_columns
from slave.pair_calibrate import tendon_wrap_shape
from slave.rig import InstrumentTruth, Rig, RigState
from slave.spindle_calibrate import SpindleCalibration
from teleop.config.schema import Config, JointConfig
from teleop.wire.messages import AxisState, TendonState

__all__ = ["SpindleAxis", "spindle_params"]

log = logging.getLogger("teleop.slave")


def spindle_params(joint: JointConfig, K: tuple[float, float]) -> SpindleParams:
    """The spindle pair model of a jaw: rho = r_d / r_p, n_k = r_p / r_d, Q = 2 P r_p [N m], the cables'
    friction exponents ``K`` (a, b), lam = (c_a + c_b) / (4 r_p^2) [rad/(N m)] with c = L/EA [m/N]."""
    rp, rd = joint.spindle_radius, joint.pulley_radius
    c = [t.geometry().length / t.EA for t in (joint.tendons.a, joint.tendons.b)]
    return SpindleParams(rho=rd / rp, Q=2.0 * joint.pretension * rp, K_a=K[0], K_b=K[1], n_k=rp / rd,
                         lam=(c[0] + c[1]) / (4.0 * rp * rp))


class SpindleAxis(SlaveAxis):
    """One spindle-driven jaw (module docstring).

    Parameters
    ----------
    cfg : Config
    joint : JointConfig
        With ``spindle_radius`` > 0.
    index : int
        The jaw's place in the rig's ``(n_joints,)`` arrays.
    """

    routine_text = "every spindle stroked over the open side of its jaw and back"

    def __init__(self, cfg: Config, joint: JointConfig, index: int):
        self.cfg, self.joint, self.index, self.name = cfg, joint, index, joint.name
        self.r_p, self.r_d = float(joint.spindle_radius), float(joint.pulley_radius)
        self.n_k = self.r_p / self.r_d
        self.tendon_per_unit = self.r_d
        self.cmd_range = (joint.limits[0] - math.pi, joint.limits[1] + math.pi)
        self.travel = max(abs(v) for v in joint.limits) / self.n_k + 0.5
        self.estimator: SpindleEstimator | None = None
        self.sample: Any = None
        self.rest = 0.0
        self.phi_cmd = 0.0
        self.anchor: tuple[float, float] | None = None
        self.hold: float | None = None

    def start(self, K: tuple[float, float], history) -> None:
        """The estimator with the cables' ``K``, rest at the first sample of ``history`` [(t, x_in, T_in)]
        (rig arrays), then the replay of ``history``."""
        j, e = self.joint, self.cfg.estimator
        self.rest = self.phi_cmd = float(history[0][1][self.index])
        c = tuple(t.geometry().length / t.EA for t in (j.tendons.a, j.tendons.b))
        n = int(e.n_nodes)
        shapes = tuple(tendon_wrap_shape(t, n + 1) for t in (j.tendons.a, j.tendons.b))
        self.estimator = SpindleEstimator(spindle_params(j, K), self.r_p, (c[0], c[1]), theta_ref=self.rest,
                                          n_nodes=n, rate_time_constant=e.rate_time_constant, hold_rate=e.hold_rate,
                                          shapes=(shapes[0], shapes[1]))
        for t, x, T in history:
            self.sample = self.estimator.step(float(T[self.index]), float(x[self.index]), t)
        self.phi_cmd = float(history[-1][1][self.index])

    # ---- per kind ----------------------------------------------------------------------------------
    @classmethod
    def build(cls, cfg: Config, rig: Rig) -> list[SlaveAxis]:
        return [cls(cfg, j, i) for i, j in enumerate(cfg.instrument.joints)]

    @classmethod
    def routine(cls, cfg: Config, rig: Rig) -> SpindleCalibration:
        return SpindleCalibration(cfg, rig)

    @classmethod
    def routine_step(cls, routine: SpindleCalibration, rig: Rig, state: RigState, dt: float) -> RigState:
        return rig.step(routine.command(state, dt), dt)

    @classmethod
    def calibration_of(cls, cfg: Config, routine: SpindleCalibration) -> Any:
        return routine.calibration()

    @classmethod
    def finish_routine(cls, axes: Sequence[SlaveAxis], routine: SpindleCalibration,
                       state: RigState) -> tuple[Any, dict]:
        calibration = routine.calibration()
        history = routine.history + [(state.t, np.array(state.x_in), np.array(state.T_in))]
        for ax, (name, cables) in zip(axes, calibration.joints, strict=False):
            assert isinstance(ax, SpindleAxis)
            ax.start((cables["a"].K, cables["b"].K), history)
            log.info("calibrated %s: K_a = %.4f, K_b = %.4f (spindle torque band)", name, cables["a"].K, cables["b"].K)
        return calibration, calibration.as_dict()

    @classmethod
    def start_loaded(cls, axes: Sequence[SlaveAxis], calibration: InstrumentCalibration, state: RigState) -> dict:
        for ax, (_, cables) in zip(axes, calibration.joints, strict=False):
            assert isinstance(ax, SpindleAxis)
            ax.start((cables["a"].K, cables["b"].K), [(state.t, np.array(state.x_in), np.array(state.T_in))])
        return calibration.as_dict()

    @classmethod
    def rig_command(cls, motors: list) -> np.ndarray:
        return np.array(motors, dtype=float)

    @classmethod
    def recording(cls, cfg: Config, rig: Rig) -> tuple[str, tuple[str, ...], dict[str, str]]:
        """``slave_joints.csv`` in the joint instrument's columns, and metadata."""
        names = [j.name for j in cfg.instrument.joints]
        meta = {"source": "teleop slave", "instrument": cfg.instrument.id, "joints": " ".join(names),
                "drive": "spindle: x_in = +-r_p spindle angle, T_in = estimated proximal cable tension",
                "truth": "torque, angle, T_out, elongation are simulator ground truth (evaluation only)"}
        return "slave_joints.csv", joint_csv_columns(names, True), meta

    @classmethod
    def csv_row(cls, state: RigState, common: tuple, axes: Sequence[SlaveAxis]) -> list:
        marker, cmd_seq, side_state, t_node, t_recv = common
        tr = state.truth if isinstance(state.truth, InstrumentTruth) else None
        row = [state.t, marker, cmd_seq, side_state, t_node, t_recv]
        phi, cmd = np.asarray(state.x_in).tolist(), np.asarray(state.x_in_cmd).tolist()
        for ax in axes:
            assert isinstance(ax, SpindleAxis)
            i, s = ax.index, ax.sample
            row += [0.0 if ax.hold is None else ax.hold, int(ax.anchor is not None), s.torque, s.angle]
            row += [float(tr.torque[i]), float(tr.theta[i])] if tr is not None else []
            for k, sign in enumerate((1.0, -1.0)):
                row += [sign * ax.r_p * (phi[i] - ax.rest), s.T_in[k], sign * ax.r_p * (cmd[i] - ax.rest),
                        s.T_out[k], s.elongation[k], int(s.phase[k])]
                row += [float(tr.T_out[i][k]), float(tr.elongation[i][k])] if tr is not None else []
        return row

    @classmethod
    def stats(cls, axes: Sequence[SlaveAxis]) -> dict[str, Any]:
        return {"joints": [a.name for a in axes], "drive": "spindle"}

    @classmethod
    def warm_up(cls, cfg: Config) -> None:
        from slave.spindle_rig import SpindleInstrument

        SpindleInstrument(cfg.instrument.joints[:1], cfg.rig.simulated).step([1e-4], 1e-3)
        est = SpindleEstimator(SpindleParams(Q=1.0), 0.005, (1e-4, 1e-4), n_nodes=4)
        est.step(0.0, 0.0, 0.0)
        est.step(0.1, 1e-3, 1e-3)

    # ---- per axis ----------------------------------------------------------------------------------
    def out_of_range(self, target: float) -> str | None:
        lo, hi = self.cmd_range
        if lo <= target <= hi:
            return None
        return f"{self.name} angle {target:.4g} rad outside [{lo:.3g}, {hi:.3g}] rad"

    def too_far(self, target: float, state: RigState) -> str | None:
        if abs(target - self.sample.angle) * self.r_d <= self.cfg.slave.engage_tolerance:
            return None
        return f"{self.name} angle {target:.4g} rad too far from the estimate {self.sample.angle:.4g} rad"

    def motor(self, relax: bool, target: float | None, state: RigState, dt: float) -> float:
        if relax:
            if self.hold is not None:           # SAFE begins: from the measured spindle angle, not the last target
                self.phi_cmd = float(state.x_in[self.index])
            self.hold, self.anchor = None, None
            step = self.cfg.slave.relax_speed / self.r_p * dt
            d = self.rest - self.phi_cmd
            self.phi_cmd += max(-step, min(step, d))
        elif target is not None:
            self.hold = target
            if self.anchor is None:
                self.anchor = (target, self.phi_cmd)
            phi = self.anchor[1] + (target - self.anchor[0]) / self.n_k
            self.phi_cmd = min(max(phi, self.rest - self.travel), self.rest + self.travel)
        else:
            self.anchor = None
        return self.phi_cmd

    def observe(self, state: RigState) -> tuple[AxisState, tuple[float, ...]]:
        assert self.estimator is not None
        i = self.index
        phi, tau = float(state.x_in[i]), float(state.T_in[i])
        s = self.sample = self.estimator.step(tau, phi, state.t)
        x = self.r_p * (phi - self.rest)
        return AxisState(s.torque, s.angle, (TendonState(s.T_in[0], x, s.T_out[0], s.elongation[0], s.phase[0]),
                                             TendonState(s.T_in[1], -x, s.T_out[1], s.elongation[1], s.phase[1]))), ()

    def log_rerun(self, rerun: Any, cycles: int, state: RigState, everything: bool = False) -> None:
        """Every ``recording.log_every`` cycles the jaw's torque and angle, estimate and truth; every
        ``recording.profile_every`` of those also both cables' estimated tension profiles."""
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
                        profiles=est.profiles if show and est is not None else None)
