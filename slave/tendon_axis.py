"""A single tendon as the one axis of an instrument: motor position in, distal tension and elongation out.

* Power-up: :class:`slave.calibrate.JointLimitCalibration` pulls the tendon into its joint limit;
  the :class:`~estimator.online.distal.DistalEstimator` built on the fitted
  :class:`~estimator.sheath.SheathModel` replays the routine's proximal samples so that its
  tension-profile memory matches the tendon's. A reloaded calibration starts it at rest (uniform
  pretension).
* Command: ``x_in_cmd`` [m], accepted within ``[slave.x_in_min, slave.x_in_max]``; engaging needs
  ``|x_in_cmd - x_in| <= slave.engage_tolerance`` (measured x_in), so a master that has not
  re-aligned never makes the tendon jump.
* SAFE (the single-tendon version of "hold the joints, relax the tendons to pretension"): the motor
  holds where it is measured to be when SAFE begins (never where the last command was taking it), then moves in the
  release direction only, at ``slave.relax_speed``, while the measured proximal tension is above ``sheath.pretension +
  RELAX_BAND``; it never pulls and never goes below ``slave.x_in_min``. Releasing a single tendon lets its joint go back
  under its return spring: the instrument goes limp, away from the tissue, with no stored energy; the speed bound keeps
  that motion slow and smooth.
* A model file (``estimator.model``, ``--model``; :mod:`slave.tendon_model`): its per-cycle estimator runs beside
  the base one from the same start and gives the axis's estimate, except in the cycles where it leaves the
  physical range, where the base estimator's stands in (counted as ``model.fallbacks`` in the stats, logged once).
* Each cycle: ``estimator.step(T_in, x_in, t)`` (proximal sensors only) -> the axis's state (effort
  = T_out_hat [N], position = x_out_hat [m]) and the profile at ``estimator.profile_points`` points;
  one row of ``slave.csv`` in the measured-data format (docs/reference/formats.md), Rerun every
  ``recording.log_every`` cycles (estimate against truth when the rig has it).
"""
from __future__ import annotations

import logging
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from estimator.band import NOISE_BAND_SIGMAS
from estimator.online.distal import DistalEstimator
from estimator.sheath import SheathModel
from slave.axis import SlaveAxis
from slave.calibrate import JointLimitCalibration
from slave.calibration_file import from_tendon_result, tendon_model
from slave.estimator_model import configured_model
from slave.rig import Rig, RigState, RigTruth
from teleop.config.schema import Config
from teleop.wire.messages import AxisState, TendonState

if TYPE_CHECKING:
    from slave.tendon_model import ModelRunner

__all__ = ["TendonAxis", "CSV_COLUMNS", "CSV_TRUTH_COLUMNS", "csv_columns", "RELAX_BAND"]

log = logging.getLogger("teleop.slave")

#: Columns of the slave's recording (measured-data format; truth columns only with a simulated rig).
CSV_TRUTH_COLUMNS = ("x_out", "T_out", "elongation")
CSV_COLUMNS = ("time", "x_in", "T_in", "x_out", "T_out", "elongation", "T_out_hat", "elongation_hat",
               "x_out_hat", "phase", "marker", "cmd_seq", "x_in_cmd", "state", "t_node", "t_cmd_recv")
#: SAFE stops relaxing when the measured T_in is within this of the pretension [N] (load-cell noise margin).
RELAX_BAND = 0.2


def csv_columns(has_truth: bool) -> tuple[str, ...]:
    """The recording's columns: :data:`CSV_COLUMNS`, without the truth ones for a hardware rig."""
    return CSV_COLUMNS if has_truth else tuple(c for c in CSV_COLUMNS if c not in CSV_TRUTH_COLUMNS)


class TendonAxis(SlaveAxis):
    """The one axis of a single-tendon instrument (module docstring).

    Parameters
    ----------
    cfg : Config
        ``sheath`` (length, pretension), ``estimator``, ``slave`` (x_in range, relax speed, engage
        tolerance), ``recording`` (Rerun rates).
    state : RigState
        The rig's present state (the motor holds there until a command comes).

    Attributes
    ----------
    estimator : DistalEstimator or None
        None until calibrated (or given a model).
    x_hold : float
        The motor command being held [m].
    """

    name = "tendon"
    routine_text = "the tendon pulled into its joint limit"

    def __init__(self, cfg: Config, state: RigState):
        self.cfg = cfg
        self.index = 0
        self.L = cfg.sheath.geometry().length
        self.s_points = np.linspace(0.0, self.L, cfg.estimator.profile_points)
        self.x_hold = float(state.x_in)
        self.x_cmd = self.x_hold                 # the last motor command [m]
        self.relaxing = False                    # SAFE: the motor held at the measured x_in, then released
        self.estimator: DistalEstimator | None = None
        self.sample: Any = None                  # the last DistalSample
        self.profile = np.zeros(0)
        self.x_min, self.x_max = cfg.slave.x_in_min, cfg.slave.x_in_max
        self.relax_speed = cfg.slave.relax_speed
        self.relax_to = cfg.sheath.pretension + RELAX_BAND
        self.engage_tolerance = cfg.slave.engage_tolerance
        self.runner: ModelRunner | None = None   # the model file's estimator (estimator.model), or None
        # load the compiled kernels now, not in the first real-time cycle
        DistalEstimator(SheathModel(K=0.5, compliance=1e-4), n_nodes=2).step(1.0, 0.0, 0.0)

    def start(self, model: SheathModel, state: RigState | None = None, tension_noise: float = 0.0) -> None:
        """The estimator on ``model``, at rest (uniform pretension); stepped once on ``state`` when given.
        ``tension_noise`` [N]: the calibration's noise sigma of T_in, used for the noise band unless the config's
        ``estimator.tension_noise`` is set (0: no band)."""
        e = self.cfg.estimator
        sigma = tension_noise if e.tension_noise is None else e.tension_noise
        self.estimator = DistalEstimator(model, n_nodes=e.n_nodes, pretension=self.cfg.sheath.pretension,
                                         hold_rate=e.hold_rate, rate_time_constant=e.rate_time_constant,
                                         tension_noise=sigma)
        if sigma > 0:
            log.info("estimator noise band: %.3f N (T_in noise sigma %.4f N, %s)", NOISE_BAND_SIGMAS * sigma, sigma,
                     "calibration" if e.tension_noise is None else "estimator.tension_noise")
        else:
            log.info("estimator without a noise band (%s)", "estimator.tension_noise = 0" if e.tension_noise == 0
                     else "the calibration has no tension_noise: recalibrate to measure it")
        mf = configured_model(self.cfg)
        self.runner = None
        if mf is not None:
            from slave.tendon_model import ModelRunner, tendon_model_estimator  # the catalogue: with a model only
            est = tendon_model_estimator(mf, sigma, e.rate_time_constant, self.cfg.rig.rate_hz)
            self.runner = ModelRunner(mf, est, self.name)
        if state is not None:
            self._estimate(state.T_in, state.x_in, state.t)

    def _estimate(self, T_in: float, x_in: float, t: float) -> None:
        """One cycle of the base estimator and, with a model file, its estimator: the axis's sample and profile."""
        assert self.estimator is not None
        self.sample = self.estimator.step(T_in, x_in, t)
        if self.runner is None:
            self.profile = self.estimator.profile_samples(len(self.s_points))
            return
        self.sample = self.runner.step(T_in, x_in, t, self.sample)
        prof = self.runner.estimator.profile
        self.profile = np.interp(np.linspace(0.0, 1.0, len(self.s_points)), np.linspace(0.0, 1.0, prof.size), prof)

    # ---- per kind ----------------------------------------------------------------------------------
    @classmethod
    def build(cls, cfg: Config, rig: Rig) -> list[SlaveAxis]:
        return [cls(cfg, rig.state)]

    @classmethod
    def routine(cls, cfg: Config, rig: Rig) -> JointLimitCalibration:
        return JointLimitCalibration(cfg, rig)

    @classmethod
    def routine_step(cls, routine: JointLimitCalibration, rig: Rig, state: RigState, dt: float) -> RigState:
        state = rig.step(routine.command(state, dt), dt)
        routine.observe(state)
        return state

    @classmethod
    def calibration_of(cls, cfg: Config, routine: JointLimitCalibration) -> Any:
        assert routine.result is not None
        return from_tendon_result(cfg, routine.result)

    @classmethod
    def finish_routine(cls, axes: Sequence[SlaveAxis], routine: JointLimitCalibration,
                       state: RigState) -> tuple[Any, dict]:
        ax = axes[0]
        assert isinstance(ax, TendonAxis) and routine.result is not None
        ax.start(routine.result.model, tension_noise=routine.result.tension_noise)
        est = ax.estimator
        assert est is not None
        # replay the routine (compiled batch): the estimator's memory = the tendon's proximal history
        t_h, x_h, T_h = routine.history
        est.replay(np.asarray(t_h[:-1]), np.asarray(x_h[:-1]), np.asarray(T_h[:-1]))
        if ax.runner is not None:       # the model's estimator through the same history, one cycle at a time
            for T, x, t in zip(T_h[:-1], x_h[:-1], t_h[:-1], strict=True):
                ax.runner.estimator.step(T, x, t)
        ax._estimate(T_h[-1], x_h[-1], t_h[-1])
        ax.x_hold = routine.x_cmd
        r = routine.result
        log.info("calibrated: K = %.4f, M_e = %.4e m/N (knee at T_in = %.2f N)", r.K, r.M_e, r.knee_T_in)
        return cls.calibration_of(ax.cfg, routine), routine.as_dict()

    @classmethod
    def start_loaded(cls, axes: Sequence[SlaveAxis], calibration: Any, state: RigState) -> dict:
        ax = axes[0]
        assert isinstance(ax, TendonAxis)
        ax.start(tendon_model(calibration, ax.cfg), state, calibration.tendon.tension_noise)
        t = calibration.tendon
        return {"K": t.K, "M_e_m_per_N": t.M_e, "compliance_m_per_N": t.compliance, "knee_x_in_m": t.knee_x_in,
                "knee_T_in_N": t.knee_T_in, "residual_rms_m": t.residual_rms, "n_samples": t.n_samples,
                "target_tension_N": calibration.target_tension, "use_route": calibration.use_route,
                "date": calibration.date}

    @classmethod
    def rig_command(cls, motors: list) -> float:
        return motors[0]

    @classmethod
    def recording(cls, cfg: Config, rig: Rig) -> tuple[str, tuple[str, ...], dict[str, str]]:
        """``slave.csv``: :func:`csv_columns` (truth only when ``rig`` has it) and metadata."""
        has_truth = rig.state.truth is not None
        meta = {"source": "teleop slave", "instrument": cfg.instrument.id, "rig": cfg.rig.type,
                "truth": "x_out, T_out, elongation are simulator ground truth (evaluation only)" if has_truth
                else "none"}
        return "slave.csv", csv_columns(has_truth), meta

    @classmethod
    def csv_row(cls, state: RigState, common: tuple, axes: Sequence[SlaveAxis]) -> list:
        ax = axes[0]
        assert isinstance(ax, TendonAxis)
        marker, cmd_seq, side_state, t_node, t_recv = common
        tr, s = state.truth, ax.sample
        truth = [tr.x_out, tr.T_out, tr.elongation] if tr is not None else []
        return [state.t, state.x_in, state.T_in, *truth, s.T_out, s.elongation, s.x_out, int(s.phase), marker,
                cmd_seq, ax.x_cmd, side_state, t_node, t_recv]

    @classmethod
    def stats(cls, axes: Sequence[SlaveAxis]) -> dict[str, Any]:
        """``model``: the model file's entry (:meth:`slave.tendon_model.ModelRunner.stats`), when one runs."""
        runners = [ax.runner for ax in axes if isinstance(ax, TendonAxis) and ax.runner is not None]
        return {"model": runners[0].stats()} if runners else {}

    @classmethod
    def warm_up(cls, cfg: Config) -> None:
        from estimator.offline.calibration import calibrate_joint_limit  # noqa: F401  (import cost, too)
        from slave.simulated import SimulatedRig

        rig = SimulatedRig.from_config(cfg)
        est = DistalEstimator(SheathModel(K=0.5, compliance=1e-4), n_nodes=8)
        for k in range(4):
            rs = rig.step(1e-4 * k, 1.0 / cfg.rig.rate_hz)
            est.step(rs.T_in, rs.x_in, 1e-3 * k)
        rig.set_load(tissue=not cfg.rig.simulated.load.tissue)
        rig.close()

    # ---- per axis ----------------------------------------------------------------------------------
    def out_of_range(self, target: float) -> str | None:
        if self.x_min <= target <= self.x_max:
            return None
        return f"x_in_cmd {target:.6g} m outside [{self.x_min:g}, {self.x_max:g}] m (slave.x_in_min/max)"

    def too_far(self, target: float, state: RigState) -> str | None:
        gap = abs(target - state.x_in)
        if gap <= self.engage_tolerance:
            return None
        return (f"x_in_cmd {target:.6g} m is {1e3 * gap:.3g} mm from x_in "
                f"(tolerance {1e3 * self.engage_tolerance:.3g} mm)")

    def motor(self, relax: bool, target: float | None, state: RigState, dt: float) -> float:
        if relax:
            if not self.relaxing:               # SAFE begins: hold the measured position, not the last target
                self.relaxing, self.x_hold = True, float(state.x_in)
            if self.relax_speed > 0 and state.T_in > self.relax_to and self.x_hold > self.x_min:
                # release only, at most relax_speed dt per cycle, never below x_in_min
                self.x_hold = max(self.x_min, self.x_hold - self.relax_speed * dt)
        else:
            self.relaxing = False
            if target is not None:
                self.x_hold = target
        self.x_cmd = self.x_hold
        return self.x_hold

    def observe(self, state: RigState) -> tuple[AxisState, tuple[float, ...]]:
        self._estimate(state.T_in, state.x_in, state.t)
        s = self.sample
        tendon = TendonState(state.T_in, state.x_in, s.T_out, s.elongation, s.phase)
        return AxisState(s.T_out, s.x_out, (tendon,)), tuple(float(v) for v in self.profile)

    def log_calibration(self, rerun: Any, cycles: int, log_every: int, state: RigState) -> None:
        """The calibration pull as it happens (the CSV starts when the estimator does)."""
        if cycles % log_every:
            return
        tr = state.truth
        rerun.log_scalars(state.t, T_in=state.T_in, T_out_true=None if tr is None else tr.T_out,
                          elongation_true=None if tr is None else tr.elongation)

    def log_rerun(self, rerun: Any, cycles: int, state: RigState, everything: bool = False) -> None:
        """Every ``log_every`` cycles the scalars and phase (~0.1 ms); every ``profile_every``-th of those
        windows also the profile (~0.5 ms), half a window apart so that no single cycle carries both."""
        n = self.cfg.recording.log_every
        k = cycles % n
        s = self.sample
        tr = state.truth if isinstance(state.truth, RigTruth) else None
        if (k == 0 and (cycles // n) % self.cfg.recording.profile_every == 0) or everything:
            T_true = None
            if tr is not None and tr.profile.size:       # a rig behind Zenoh sends no profile
                u = np.linspace(0.0, 1.0, tr.profile.size)
                T_true = np.interp(self.s_points / self.L, u, tr.profile)
            rerun.log_profile(state.t, self.s_points, self.profile, T_true)
        if k == n // 2 or everything:
            rerun.log_scalars(state.t, T_in=state.T_in, T_out_hat=s.T_out,
                              T_out_true=None if tr is None else tr.T_out, elongation_hat=s.elongation,
                              elongation_true=None if tr is None else tr.elongation)
            rerun.log_phase(state.t, s.phase.label)
