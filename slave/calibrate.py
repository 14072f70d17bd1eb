"""The slave's power-up joint-limit initialisation (Phee et al. 2009, Sec. IV), as a step() routine.

Sequence, one :meth:`JointLimitCalibration.step` per control cycle:

1. ``set_load(tissue=False)``: nothing but the joint's own spring and its limit at the tip;
2. PULL: ramp the proximal command at ``calibration.speed`` from the present position until the load
   cell reads ``T_in >= calibration.target_tension`` (at most ``max_travel`` of travel);
3. fit: :func:`estimator.offline.calibration.calibrate_joint_limit` on the recorded (x_in, T_in) of the pull,
   with L = sheath length, EA from the tendon datasheet and, if ``calibration.use_route``, the wrap
   shape of the configured route (else constant curvature, as in the paper);
4. RELEASE: ramp the command back to the starting position at ``release_factor`` times the speed,
   then hold ``settle`` seconds (zero tension again when the tendon started slack);
5. restore the configured tissue load; :attr:`done`.

Every proximal sample of the routine is kept (:attr:`history`), so that the estimator built from the
calibrated model can replay it and start with the tension-profile memory the tendon really has.
Only proximal sensors are read; the ground truth is never touched.
"""
from __future__ import annotations

import math
from enum import Enum

import numpy as np

from estimator.errors import CalibrationError
from estimator.offline.calibration import CalibrationResult, calibrate_joint_limit
from slave.rig import Rig, RigState
from teleop.config.schema import Config

__all__ = ["CalStage", "JointLimitCalibration", "route_wrap_shape", "wrap_shape", "check_settings"]


class CalStage(Enum):
    START = "start"
    PULL = "pull"
    RELEASE = "release"
    SETTLE = "settle"
    DONE = "done"


def wrap_shape(geom, n_points: int = 257) -> np.ndarray | None:
    """Normalised cumulative wrap angle theta(s)/theta_total of a sheath geometry, shape (n_points,).

    None for a straight sheath (no wrap, the shape is undefined).
    """
    if geom.total_angle <= 0:
        return None
    s = np.linspace(0.0, geom.length, n_points)
    return np.asarray(geom.wrap_angle(s), dtype=float) / geom.total_angle


def route_wrap_shape(cfg: Config, n_points: int = 257) -> np.ndarray | None:
    """:func:`wrap_shape` of the configured route (``sheath``), shape (n_points,); None when straight."""
    return wrap_shape(cfg.sheath.geometry(), n_points)


def check_settings(c) -> None:
    """Range checks of the routine's ``calibration`` settings (speed, target tension).

    Raises
    ------
    CalibrationError
        ``speed`` not a finite speed > 0 m/s, or ``target_tension`` not > 0 N.
    """
    if not (math.isfinite(c.speed) and c.speed > 0):
        raise CalibrationError(f"calibration.speed must be a finite speed > 0 m/s, got {c.speed!r}")
    if not (math.isfinite(c.target_tension) and c.target_tension > 0):
        raise CalibrationError(f"calibration.target_tension must be > 0 N, got {c.target_tension!r}")


class JointLimitCalibration:
    """Joint-limit initialisation of one tendon, driven one cycle at a time.

    Parameters
    ----------
    cfg : Config
        ``calibration`` (target_tension [N], speed [m/s], use_route), ``sheath`` (route -> L and wrap
        shape, EA [N]), ``rig.simulated.load.tissue`` (restored at the end).
    rig : Rig
    max_travel : float
        Give up (CalibrationError) when the pull has gone this far without reaching the target [m].
    release_factor : float
        Release speed as a multiple of the pull speed [-].
    settle : float
        Hold at the starting position after the release [s].

    Attributes
    ----------
    stage : CalStage
    result : CalibrationResult or None
        Set when the pull has been fitted.
    history : tuple (t, x_in, T_in) of lists
        Every proximal sample seen, times [s], displacements [m], tensions [N].
    """

    def __init__(self, cfg: Config, rig: Rig, *, max_travel: float = 0.08, release_factor: float = 3.0,
                 settle: float = 0.2):
        c = cfg.calibration
        check_settings(c)
        self.cfg = cfg
        self.rig = rig
        self.max_travel = float(max_travel)
        self.release_speed = release_factor * c.speed
        self.settle = float(settle)
        self.stage = CalStage.START
        self.result: CalibrationResult | None = None
        self.x_start = 0.0
        self.x_cmd = 0.0
        self._t_settle = 0.0
        self._pull_from = 0
        self._pull_to = 0
        self.t_hist: list[float] = []
        self.x_hist: list[float] = []
        self.T_hist: list[float] = []

    @property
    def done(self) -> bool:
        return self.stage == CalStage.DONE

    @property
    def history(self) -> tuple[list[float], list[float], list[float]]:
        return self.t_hist, self.x_hist, self.T_hist

    def command(self, state: RigState, dt: float) -> float:
        """The proximal command [m] for the next rig step, given the last rig state and period ``dt`` [s].

        Raises
        ------
        CalibrationError
            The pull went ``max_travel`` without reaching the target tension, or the fit failed.
        """
        c = self.cfg.calibration
        if self.stage == CalStage.START:
            self.rig.set_load(tissue=False)
            self.x_start = self.x_cmd = self.rig.state.x_in
            self._pull_from = len(self.t_hist)
            self.stage = CalStage.PULL
            return self.x_cmd
        if self.stage == CalStage.PULL:
            if state.T_in >= c.target_tension:
                self._pull_to = len(self.t_hist)
                self._fit()
                self.stage = CalStage.RELEASE
            elif self.x_cmd - self.x_start >= self.max_travel:
                raise CalibrationError(
                    f"calibration: pulled {self.max_travel * 1e3:.0f} mm without reaching "
                    f"calibration.target_tension = {c.target_tension:g} N (T_in = {state.T_in:.2f} N); "
                    f"no joint limit found")
            else:
                self.x_cmd += c.speed * dt
                return self.x_cmd
        if self.stage == CalStage.RELEASE:
            self.x_cmd = max(self.x_start, self.x_cmd - self.release_speed * dt)
            if self.x_cmd <= self.x_start and abs(state.x_in - self.x_start) < 1e-5:
                self.stage = CalStage.SETTLE
                self._t_settle = state.t
            return self.x_cmd
        if self.stage == CalStage.SETTLE and state.t - self._t_settle >= self.settle:
            self.rig.set_load(tissue=bool(self.cfg.rig.simulated.load.tissue))
            self.stage = CalStage.DONE
        return self.x_cmd

    def observe(self, state: RigState) -> None:
        """Record one proximal sample (call after every rig step of the routine)."""
        self.t_hist.append(state.t)
        self.x_hist.append(state.x_in)
        self.T_hist.append(state.T_in)

    def _fit(self) -> None:
        x = np.asarray(self.x_hist[self._pull_from:self._pull_to])
        T = np.asarray(self.T_hist[self._pull_from:self._pull_to])
        geom = self.cfg.sheath.geometry()
        shape = route_wrap_shape(self.cfg) if self.cfg.calibration.use_route else None
        self.result = calibrate_joint_limit(x, T, L=geom.length, EA=self.cfg.sheath.EA, wrap_shape=shape)

    def as_dict(self) -> dict:
        """The calibration result plus the routine's settings, for calibration.json."""
        if self.result is None:
            raise CalibrationError("calibration has not been fitted yet")
        c = self.cfg.calibration
        geom = self.cfg.sheath.geometry()
        out = self.result.as_dict()
        out.update({"target_tension_N": c.target_tension, "speed_m_per_s": c.speed, "use_route": c.use_route,
                    "L_m": geom.length, "EA_N": self.cfg.sheath.EA, "pull_samples": self._pull_to - self._pull_from,
                    "x_start_m": self.x_start})
        return out
