"""Joint-limit calibration of every tendon of an instrument, both directions, from proximal signals only.

The seed paper's initialisation (Phee et al. 2009, Sec. IV; :mod:`estimator.offline.calibration`) run on each
tendon of each antagonistic pair: pulling tendon a turns the joint into its upper limit, pulling b
into its lower one. Per joint, one :meth:`PairCalibration.command` per control cycle, all joints at
once (they are mechanically independent):

1. ``set_load(tissue=False)`` on the instrument: only the joint's spring and its limits at the tip;
2. for tendon a, then b: PULL - the pair controller (:class:`slave.pair_control.PairController`)
   with a joint command ramped so that the puller's motor moves at ``calibration.speed`` while the
   antagonist keeps its set tension from its own load cell; every (x_in, T_in) of the puller is kept
   until its load cell reads ``calibration.target_tension``. Fit: the knee of T_in(x_in) where the
   joint meets its limit, M_e the slope of x_in on T_in beyond it, K from M_e by Newton's method
   (eq. (13)) with L, EA and - if ``calibration.use_route`` - the route shape of that tendon;
3. RELEASE - the command ramps back to 0 at ``release_factor`` times the speed; then SETTLE: both
   tendons at their set tension for ``settle`` seconds;
4. when every joint is done, the configured tissue load is restored.

The antagonist's feedforward (joint motion estimated from the puller) uses a provisional estimator
with K = 0 (elastic tendons, no friction known yet). The ground truth is never read.
"""
from __future__ import annotations

from enum import Enum

import numpy as np

from estimator.errors import CalibrationError
from estimator.offline.calibration import CalibrationResult, calibrate_joint_limit
from estimator.online.pair import PairEstimator
from estimator.sheath import SheathModel
from slave.calibrate import check_settings, wrap_shape
from slave.pair_control import PairController
from slave.rig import TENDONS, Rig, RigState
from teleop.config.schema import Config, JointConfig, TendonConfig, joint_set_tension

__all__ = ["PairStage", "tendon_wrap_shape", "set_tension", "PairCalibration"]


class PairStage(Enum):
    PULL = "pull"
    RELEASE = "release"
    SETTLE = "settle"
    DONE = "done"


def tendon_wrap_shape(tendon: TendonConfig, n_points: int = 257) -> np.ndarray | None:
    """theta(s)/theta_total of a tendon's route, shape (n_points,); None for a straight sheath."""
    return wrap_shape(tendon.geometry(), n_points)


def set_tension(cfg: Config, joint: JointConfig) -> float:
    """The antagonist's set tension of a joint [N] (:func:`teleop.config.schema.joint_set_tension`)."""
    return joint_set_tension(cfg, joint)


class _Joint:
    """The routine of one joint (both directions)."""

    def __init__(self, cfg: Config, joint: JointConfig, x_init, release_factor: float, settle: float,
                 max_travel: float):
        c = cfg.calibration
        self.joint = joint
        self.r = joint.pulley_radius
        self.rate = c.speed / self.r                 # [rad/s] of command = speed [m/s] of the puller
        self.release_rate = release_factor * self.rate
        self.settle = settle
        self.max_travel = max_travel
        self.target = c.target_tension
        pc = cfg.pair_control
        self.ctl = PairController(self.r, set_tension(cfg, joint), pc.tension_gain, pc.switch_band,
                                  cfg.slave.relax_speed, x_init, feedforward=pc.feedforward)
        model_a, model_b = (SheathModel(K=0.0, compliance=t.geometry().length / t.EA)
                            for t in (joint.tendons.a, joint.tendons.b))
        self.est = PairEstimator(model_a, model_b, self.r, pretension=joint.pretension)
        self.side = 0
        self.stage = PairStage.PULL
        self.c = 0.0
        self.t_settle = 0.0
        self.pull: list[tuple[float, float]] = []
        self.results: dict[str, CalibrationResult] = {}
        self.shapes = {t: tendon_wrap_shape(getattr(joint.tendons, t)) if c.use_route else None for t in TENDONS}

    def command(self, x_in, T_in, t: float, dt: float) -> tuple[float, float]:
        s = self.est.step(T_in[0], x_in[0], T_in[1], x_in[1], t)
        sgn = 1.0 if self.side == 0 else -1.0
        if self.stage == PairStage.PULL:
            if self.ctl.mode != 0 or abs(self.c) > 0:
                self.pull.append((float(x_in[self.side]), float(T_in[self.side])))
            if T_in[self.side] >= self.target:
                self._fit()
                self.stage = PairStage.RELEASE
            elif abs(self.c) * self.r > self.max_travel:
                name = self.joint.name
                raise CalibrationError(
                    f"calibration of joint {name!r}, tendon {TENDONS[self.side]}: "
                    f"pulled {self.max_travel * 1e3:.0f} mm without reaching "
                    f"calibration.target_tension = {self.target:g} N (T_in = {T_in[self.side]:.2f} N); "
                    f"no joint limit found")
            else:
                self.c += sgn * self.rate * dt
        elif self.stage == PairStage.RELEASE:
            self.c = sgn * max(0.0, sgn * self.c - self.release_rate * dt)
            if self.c == 0.0:
                self.stage, self.t_settle = PairStage.SETTLE, t
        elif self.stage == PairStage.SETTLE and t - self.t_settle >= self.settle:
            if self.side == 0:
                self.side, self.stage, self.pull = 1, PairStage.PULL, []
            else:
                self.stage = PairStage.DONE
        cmd = self.c if self.stage in (PairStage.PULL, PairStage.RELEASE) else None
        return self.ctl.step(cmd, T_in, dt, s.x_out)

    def _fit(self) -> None:
        name = TENDONS[self.side]
        tendon = getattr(self.joint.tendons, name)
        x, T = (np.asarray(v) for v in zip(*self.pull, strict=False)) if self.pull else (np.zeros(0), np.zeros(0))
        # tendon b is pulled by turning the joint to - angles: its x_in still grows (+ = toward the actuator)
        try:
            self.results[name] = calibrate_joint_limit(x, T, L=tendon.geometry().length, EA=tendon.EA,
                                                       wrap_shape=self.shapes[name])
        except CalibrationError as e:
            raise CalibrationError(f"calibration of joint {self.joint.name!r}, tendon {name}: {e}") from None


class PairCalibration:
    """Both-direction joint-limit calibration of every joint of an instrument, driven one cycle at a time.

    Parameters
    ----------
    cfg : Config
        ``calibration`` (target_tension [N], speed [m/s], use_route), ``instrument.joints`` (routes,
        EA, pulley radii, pretension), ``pair_control`` (set tension, gain, band), ``slave.relax_speed``
        (rate limit of the tension loops).
    instrument : Rig
    release_factor : float
        Release speed as a multiple of the pull speed [-].
    settle : float
        Hold with both tendons at their set tension after each release [s].
    max_travel : float
        Give up (CalibrationError) when a pull has gone this far without reaching the target [m].

    Attributes
    ----------
    history : list of (t [s], x_in [m] (n_joints, 2), T_in [N] (n_joints, 2))
        Every proximal sample seen (to replay into the estimators afterwards).

    Raises
    ------
    CalibrationError
        A calibration setting out of range.
    """

    def __init__(self, cfg: Config, instrument: Rig, *, release_factor: float = 3.0, settle: float = 0.3,
                 max_travel: float = 0.03):
        check_settings(cfg.calibration)
        self.cfg = cfg
        self.instrument = instrument
        st = instrument.state
        self.joints = [_Joint(cfg, j, tuple(st.x_in_cmd[i]), release_factor, settle, max_travel)
                       for i, j in enumerate(cfg.instrument.joints)]
        self.history: list[tuple[float, np.ndarray, np.ndarray]] = []
        self.started = False
        self._done = False

    @property
    def done(self) -> bool:
        return self._done

    def command(self, state: RigState, dt: float) -> np.ndarray:
        """Motor commands [m], shape (n_joints, 2), for the next step, given the last state and period ``dt`` [s].

        Raises
        ------
        CalibrationError
            A pull went ``max_travel`` without reaching the target tension, or a fit failed (the
            message names the joint and tendon).
        """
        if not self.started:
            self.instrument.set_load(tissue=False)
            self.started = True
            state = self.instrument.state
        self.history.append((state.t, state.x_in.copy(), state.T_in.copy()))
        out = np.array([j.command(state.x_in[i], state.T_in[i], state.t, dt) for i, j in enumerate(self.joints)])
        if all(j.stage == PairStage.DONE for j in self.joints) and not self._done:
            tissue = {bool(self.cfg.rig.simulated.joint(j.name).load.tissue) for j in self.cfg.instrument.joints}
            self.instrument.set_load(tissue=tissue.pop() if len(tissue) == 1 else True)
            self._done = True
        return out

    @property
    def results(self) -> list[dict[str, CalibrationResult]]:
        """Per joint: {"a": CalibrationResult, "b": CalibrationResult} (filled as the pulls finish)."""
        return [j.results for j in self.joints]

    def controllers(self) -> list[PairController]:
        """The pair controllers of the routine (their motor commands go on after it)."""
        return [j.ctl for j in self.joints]
