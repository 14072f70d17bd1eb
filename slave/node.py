"""The slave (instrument-side) node: latest Command -> rig -> estimator -> Estimate, with a watchdog.

One :meth:`SlaveNode.step` per cycle (``rig.rate_hz``), given the time by the caller:

* CALIBRATING (from power-up, when no calibration was given: the same life cycle as a joint
  instrument's, :mod:`slave.calibration_file`): :class:`slave.calibrate.JointLimitCalibration` drives
  the rig; no command is accepted and no estimate is sent. When it is done, a
  :class:`DistalEstimator` is built on the calibrated :class:`SheathModel` and replays the routine's
  proximal samples so that its tension-profile memory matches the tendon's; the fit is saved as
  calibration data (``calibration_file``) and calibration.json is written. With a calibration
  (reloaded from ``configs/calibration/<instrument>.yaml``) the node starts SAFE at once, its
  estimator at rest (uniform pretension), and calibration.json holds the reloaded values.
* Then, each cycle, the latest Command decides (latest wins):

  ========================================  ==========  =======================================
  latest accepted command                   state       rig command
  ========================================  ==========  =======================================
  none, older than ``slave.watchdog_ms``,   SAFE        hold, then relax toward the pretension
  or the master's liveliness token gone
  fresh, ``engaged=False``                  READY       hold the last applied position
  fresh, ``engaged=True``                   ENGAGED     ``x_in_cmd``
  ========================================  ==========  =======================================

  A command is *accepted* only when it is newer than the last accepted one (sequence number, uint32
  wrap: duplicates and reordered old messages are counted and ignored) and ``x_in_cmd`` lies in
  ``[slave.x_in_min, slave.x_in_max]`` (out of range: counted and ignored). Only accepted commands
  feed the watchdog, so a stream of corrupt or impossible commands ends in SAFE within the watchdog
  time. Entering ENGAGED from another state needs ``|x_in_cmd - x_in| <= slave.engage_tolerance``
  (measured x_in): a master that has not re-aligned never makes the tendon jump.

  SAFE (the single-tendon version of "hold the joints, relax the tendons to pretension"): the motor
  holds where it was, then moves in the release direction only, at ``slave.relax_speed``, while
  the measured proximal tension is above ``sheath.pretension + RELAX_BAND``; it never pulls and never
  goes below ``slave.x_in_min``. Releasing a single tendon lets its joint go back under its return
  spring: the instrument goes limp, away from the tissue, with no stored energy, which is the safe
  state of a flexible instrument; the speed bound keeps that motion slow and smooth. (An
  antagonistic joint would instead lower both tensions to the pretension at a constant difference.)

  rig.step -> estimator.step(T_in, x_in, t) (proximal sensors only, never the truth) -> Estimate
  (with the profile at ``estimator.profile_points`` points) -> one CSV row per cycle and Rerun
  every ``recording.log_every`` cycles (estimate against truth when the rig has it).
* A Heartbeat at ``slave.heartbeat_hz`` carries the state. With ``stop_on_master_stop`` the node
  sets :attr:`done` when the master's heartbeat says STOPPING.

The cycle, the watchdog's reasons and the summary counters are shared with the joint-instrument
slave: :mod:`slave.node_base`; heartbeat, state changes and pacing with every node: :mod:`teleop.node`.
"""
from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np

from estimator.online.distal import DistalEstimator
from estimator.sheath import SheathModel, profile_batch
from slave.calibrate import JointLimitCalibration
from slave.calibration_file import InstrumentCalibration, from_tendon_result, save_calibration, tendon_model
from slave.node_base import Decision, SlaveLinks, SlaveNodeBase
from slave.rig import Rig, RigState
from teleop.codec import seq_newer
from teleop.config import Config
from teleop.messages import Command, SideState, tendon_estimate

__all__ = ["SlaveLinks", "SlaveNode", "CSV_COLUMNS", "CSV_TRUTH_COLUMNS", "csv_columns", "RELAX_BAND", "seq_newer",
           "recording", "warm_up"]

log = logging.getLogger("teleop.slave")

#: Columns of the slave's recording (measured-data format; truth columns only with a simulated rig).
CSV_TRUTH_COLUMNS = ("x_out", "T_out", "elongation")
CSV_COLUMNS = ("time", "x_in", "T_in", "x_out", "T_out", "elongation", "T_out_hat", "elongation_hat",
               "x_out_hat", "phase", "marker", "cmd_seq", "x_in_cmd", "state", "t_node", "t_cmd_recv")
#: SAFE stops relaxing when the measured T_in is within this of the pretension [N] (load-cell noise margin).
RELAX_BAND = 0.2


class SlaveNode(SlaveNodeBase):
    """Slave side of one tendon's teleoperation loop.

    Parameters
    ----------
    cfg : Config
    rig : Rig
    links : SlaveLinks
    recorder : object with ``write(row)`` (a :class:`teleop.recording.CsvRecorder` with ``columns``
        from :func:`csv_columns`), or None.
    rerun : object with ``log_profile``/``log_scalars``/``log_phase`` (a
        :class:`teleop.rerun_log.RerunLogger`), or None.
    run_dir : Path or None
        Where calibration.json goes.
    stop_on_master_stop : bool
        Finish when the master announces STOPPING.
    calibrate : bool
        Run the joint-limit routine first unless ``calibration`` is given (False: use ``model`` at
        once, for tests).
    model : SheathModel, optional
        The model when ``calibrate`` is False.
    calibration : InstrumentCalibration, optional
        Reloaded calibration data of this single tendon (:mod:`slave.calibration_file`); the node
        starts SAFE with its model.
    calibration_file : path, optional
        Where the power-up calibration is saved.
    """

    def __init__(self, cfg: Config, rig: Rig, links: SlaveLinks, *, recorder=None, rerun=None,
                 run_dir: str | Path | None = None, stop_on_master_stop: bool = False,
                 calibrate: bool = True, model=None, calibration=None,
                 calibration_file: str | Path | None = None):
        super().__init__(cfg, links, run_dir=run_dir, stop_on_master_stop=stop_on_master_stop,
                         counts=("commands_rejected_range", "commands_wrong_axes", "commands_out_of_order", "commands_duplicate",
                                 "engage_refused"))
        self.rig = rig
        self.recorder = recorder
        self.rerun = rerun
        self.L = cfg.sheath.geometry().length
        self.s_points = np.linspace(0.0, self.L, cfg.estimator.profile_points)
        self.x_hold = rig.state.x_in
        self.estimator: DistalEstimator | None = None
        self.routine: JointLimitCalibration | None = None
        self.rig_state: RigState = rig.state
        self.x_min, self.x_max = cfg.slave.x_in_min, cfg.slave.x_in_max
        self.relax_speed = cfg.slave.relax_speed
        self.relax_to = cfg.sheath.pretension + RELAX_BAND
        self.engage_tolerance = cfg.slave.engage_tolerance
        self.last_safe_reason: str | None = None
        self._now = 0.0
        # load the compiled kernels now, not in the first real-time cycle
        DistalEstimator(SheathModel(K=0.5, compliance=1e-4), n_nodes=2).step(1.0, 0.0, 0.0)
        self.calibration_file = None if calibration_file is None else Path(calibration_file)
        self.calibration: InstrumentCalibration | None = calibration
        if calibration is not None:
            self._make_estimator(tendon_model(calibration, cfg))
            self.estimator.step(self.rig_state.T_in, self.rig_state.x_in, self.rig_state.t)
            t = calibration.tendon
            self._write_calibration_json({
                "K": t.K, "M_e_m_per_N": t.M_e, "compliance_m_per_N": t.compliance, "knee_x_in_m": t.knee_x_in,
                "knee_T_in_N": t.knee_T_in, "residual_rms_m": t.residual_rms, "n_samples": t.n_samples,
                "target_tension_N": calibration.target_tension, "use_route": calibration.use_route,
                "date": calibration.date, "loaded_from": str(self.calibration_file or "")})
            self._set_state(SideState.SAFE, 0.0, "calibration loaded; no command yet")
        elif calibrate:
            self.routine = JointLimitCalibration(cfg, rig)
            self._set_state(SideState.CALIBRATING, 0.0, "power-up joint-limit initialisation")
        else:
            if model is None:
                raise ValueError("SlaveNode(calibrate=False) needs a SheathModel in model=")
            self._make_estimator(model)
            self._set_state(SideState.SAFE, 0.0, "no command yet")

    # ------------------------------------------------------------------------------------------------
    def _make_estimator(self, model) -> None:
        e = self.cfg.estimator
        self.estimator = DistalEstimator(model, n_nodes=e.n_nodes, pretension=self.cfg.sheath.pretension,
                                         hold_rate=e.hold_rate, rate_time_constant=e.rate_time_constant)

    def _finish_calibration(self, now: float) -> None:
        cal = self.routine
        self._make_estimator(cal.result.model)
        # replay the routine (compiled batch): the estimator's memory = the tendon's proximal history
        t_h, x_h, T_h = cal.history
        est = self.estimator
        _, _, est.profile[:] = profile_batch(est.profile, est.log_gain, est.weight, np.asarray(T_h, dtype=float))
        est.step(T_h[-1], x_h[-1], t_h[-1])
        self.x_hold = cal.x_cmd
        self.calibration = from_tendon_result(self.cfg, cal.result)
        if self.calibration_file is not None:
            save_calibration(self.calibration, self.calibration_file)
        self._write_calibration_json(cal.as_dict())
        # first full Rerun log now: its one-off set-up cost (tens of ms) stays out of the engaged loop
        self._log_rerun(self.rig_state, est.T_out, est.elongation, est.phase,
                        est.profile_samples(len(self.s_points)), everything=True)
        r = cal.result
        log.info("calibrated: K = %.4f, M_e = %.4e m/N (knee at T_in = %.2f N)", r.K, r.M_e, r.knee_T_in)
        self._set_state(SideState.SAFE, now, "calibrated; waiting for commands")

    def _set_state(self, state: SideState, now: float, why: str) -> None:
        if state != self.state:
            self.last_safe_reason = why if state == SideState.SAFE else None
        super()._set_state(state, now, why)

    def _fits(self, cmd, now: float) -> bool:
        if isinstance(cmd, Command) and len(cmd.targets) == 1:
            return True
        self.counts["commands_wrong_axes"] += 1
        self._warn(now, "rejected command: expected a Command with one target (x_in_cmd) for a single tendon")
        return False

    def _in_range(self, cmd: Command, now: float) -> bool:
        x_in_cmd = cmd.targets[0]
        if self.x_min <= x_in_cmd <= self.x_max:
            return True
        self.counts["commands_rejected_range"] += 1
        self._warn(now, "rejected command %d: x_in_cmd %.6g m outside [%g, %g] m (slave.x_in_min/max)",
                   cmd.seq, x_in_cmd, self.x_min, self.x_max)
        return False

    def _safe(self, now: float, why: str, dt: float) -> float:
        """SAFE: hold, then release toward the pretension (module docstring); the rig command [m]."""
        self._set_state(SideState.SAFE, now, why)
        if self.state == SideState.SAFE and self.last_safe_reason is None:
            self.last_safe_reason = why
        self.marker = 0
        if self.relax_speed > 0 and self.rig_state.T_in > self.relax_to and self.x_hold > self.x_min:
            # release only, at most relax_speed dt per cycle, never below x_in_min
            self.x_hold = max(self.x_min, self.x_hold - self.relax_speed * dt)
        return self.x_hold

    def _too_far(self, cmd: Command) -> str | None:
        x_in_cmd = cmd.targets[0]
        gap = abs(x_in_cmd - self.rig_state.x_in)
        if gap <= self.engage_tolerance:
            return None
        return (f"x_in_cmd {x_in_cmd:.6g} m is {1e3 * gap:.3g} mm from x_in "
                f"(tolerance {1e3 * self.engage_tolerance:.3g} mm)")

    def _command(self, now: float, dt: float = 0.0) -> float:
        """The watchdog's decision on the latest accepted command (:meth:`_decide`) as the rig command [m]."""
        decision, detail = self._decide(now)
        if decision is Decision.SAFE:
            return self._safe(now, detail, dt)
        if decision is Decision.REFUSED and self.state == SideState.SAFE:
            return self._safe(now, "engaged command too far from x_in", dt)
        if decision is Decision.ENGAGED:
            self.x_hold = detail.targets[0]
        return self.x_hold

    def _calibration_step(self, now: float, dt: float) -> None:
        cal = self.routine
        x_cmd = cal.command(self.rig_state, dt)
        self.rig_state = self.rig.step(x_cmd, dt)
        cal.observe(self.rig_state)
        self._record_calibration(self.rig_state, x_cmd)
        if cal.done:
            self._finish_calibration(now)

    def _control_step(self, now: float, dt: float) -> None:
        self._now = now
        x_cmd = self._command(now, dt)
        rs = self.rig_state = self.rig.step(x_cmd, dt)
        est = self.estimator.step(rs.T_in, rs.x_in, rs.t)
        profile = self.estimator.profile_samples(len(self.s_points))
        self._publish(tendon_estimate(self.seq, self.cmd_seq, now, rs.T_in, rs.x_in, est.T_out, est.elongation,
                                      est.x_out, est.phase, tuple(float(v) for v in profile)))
        self._record(rs, est, x_cmd, profile)

    def _record_calibration(self, rs: RigState, x_cmd: float) -> None:
        """Rerun only (the CSV starts when the estimator does): the calibration pull as it happens."""
        if self.rerun is None or self.cycles % self.cfg.recording.log_every:
            return
        tr = rs.truth
        self.rerun.log_scalars(rs.t, T_in=rs.T_in, T_out_true=None if tr is None else tr.T_out,
                               elongation_true=None if tr is None else tr.elongation)

    def _record(self, rs: RigState, est, x_cmd: float, profile: np.ndarray) -> None:
        tr = rs.truth
        if self.recorder is not None:
            truth = (tr.x_out, tr.T_out, tr.elongation) if tr is not None else ()
            self.recorder.write((rs.t, rs.x_in, rs.T_in, *truth, est.T_out, est.elongation, est.x_out,
                                 int(est.phase), self.marker, self.cmd_seq, x_cmd, int(self.state), self._now,
                                 0.0 if self._accepted is None else self._accepted.t_recv))
        self._log_rerun(rs, est.T_out, est.elongation, est.phase, profile)

    def _log_rerun(self, rs: RigState, T_out_hat: float, elongation_hat: float, phase, profile: np.ndarray,
                   everything: bool = False) -> None:
        """Every ``log_every`` cycles the scalars and phase (~0.1 ms); every ``profile_every``-th of those
        windows also the profile (~0.5 ms), half a window apart so that no single cycle carries both;
        ``everything`` logs both now."""
        if self.rerun is None:
            return
        n = self.cfg.recording.log_every
        k = self.cycles % n
        tr = rs.truth
        window = self.cycles // n
        if (k == 0 and window % self.cfg.recording.profile_every == 0) or everything:
            T_true = None
            if tr is not None and tr.profile.size:       # a rig behind Zenoh sends no profile
                u = np.linspace(0.0, 1.0, tr.profile.size)
                T_true = np.interp(self.s_points / self.L, u, tr.profile)
            self.rerun.log_profile(rs.t, self.s_points, profile, T_true)
        if k == n // 2 or everything:
            self.rerun.log_scalars(rs.t, T_in=rs.T_in, T_out_hat=T_out_hat,
                                   T_out_true=None if tr is None else tr.T_out,
                                   elongation_hat=elongation_hat,
                                   elongation_true=None if tr is None else tr.elongation)
            self.rerun.log_phase(rs.t, phase.label)

    # ------------------------------------------------------------------------------------------------
    def _stats_detail(self) -> dict[str, Any]:
        return {
            **self.counts,
            "safe_events": self.safe_events,
            "stalls": self.stalls,
            "master_stopped": self.master_stopped,
            "calibrated": self.estimator is not None,
            "calibration": "power-up" if self.routine is not None else "loaded" if self.calibration is not None
            else "given model",
        }


def csv_columns(has_truth: bool) -> tuple[str, ...]:
    """The recording's columns: :data:`CSV_COLUMNS`, without the truth ones for a hardware rig."""
    return CSV_COLUMNS if has_truth else tuple(c for c in CSV_COLUMNS if c not in CSV_TRUTH_COLUMNS)


def recording(cfg: Config, rig: Rig) -> tuple[str, tuple[str, ...], dict[str, str]]:
    """The slave's recording of a single tendon: file name, columns (:func:`csv_columns`, truth only
    when ``rig`` has it) and metadata."""
    has_truth = rig.state.truth is not None
    meta = {"source": "teleop slave", "instrument": cfg.instrument.id, "rig": cfg.rig.type,
            "truth": "x_out, T_out, elongation are simulator ground truth (evaluation only)" if has_truth else "none"}
    return "slave.csv", csv_columns(has_truth), meta


def warm_up(cfg: Config) -> None:
    """Compile the rig's and the estimator's numba kernels before the real-time loop starts.

    With an empty numba cache (a fresh checkout) the first call of each kernel takes seconds; done
    inside the loop it would stall the first cycles. Uses throwaway objects: nothing is kept.
    """
    from estimator.offline.calibration import calibrate_joint_limit  # noqa: F401  (import cost, too)
    from estimator.online.distal import DistalEstimator
    from estimator.sheath import SheathModel
    from slave.simulated import SimulatedRig

    rig = SimulatedRig.from_config(cfg)
    est = DistalEstimator(SheathModel(K=0.5, compliance=1e-4), n_nodes=8)
    for k in range(4):
        rs = rig.step(1e-4 * k, 1.0 / cfg.rig.rate_hz)
        est.step(rs.T_in, rs.x_in, 1e-3 * k)
    rig.set_load(tissue=not cfg.rig.load.tissue)
    rig.close()
