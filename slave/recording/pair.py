"""A KAIST recording played as an antagonistic pair, estimated by the pair axis's online estimator.

The KAIST robot (``sine_config_N.txt`` or a clone's ``N.txt``, :mod:`recorded.kaist`) turns one motor that draws
tendon a in and lets tendon b out: x_in,a = +g c, x_in,b = -g c for the motor command c [rad]; the proximal
load cells give T_a, T_b [N]; an EM tracker measures the distal bending angle, the truth. The pulley radius r,
g and the tendons' compliances are not separately observable from these signals, so the rig speaks in units of
r (r = 1):
x_in = (G c, -G c) with G = g / r, L/EA_j = 2 lam_j [rad/N] (as :func:`estimator.online.pair_batch.predict_pair_angle`).

:class:`RecordedPair` is the rig (:class:`slave.rig.Rig` of one joint, one recorded sample per step).
:func:`kaist_live` calibrates on command cycle 1 (as ``teleop analyze --kaist``), plays every sample through
the rig and the pair axis's :class:`estimator.online.pair.PairEstimator` (the seed pair model with the pair
coupling, J1-J5), and scores the live angle on cycle 2 beside the offline seed pair model
(:func:`estimator.offline.pair.fit.fit_pair`) on the same cycles. The calibration of the live estimator is the same
six parameters fitted with the estimator itself as the model (``fit_pair(..., predict=predict_pair_angle)``).

The offline analysis's headline (the *extended* model its diagnosis chooses, a capstan-joint model,
docs/results/kaist.md) runs live from its model file (``estimator.model``, ``--model``; ``teleop analyze --kaist DIR
--model-out OUTDIR`` writes one per configuration): :class:`RecordedPairAxis` then steps
:class:`estimator.online.pair_model.PairModelEstimator` each cycle, driven by the measured motor position (x_in of
tendon a: the rig's G is 1) and the measured tensions, beside the base estimator. The model's angle is the
estimate; in a cycle where its prediction leaves the physical range (:func:`model_out_of_range`) the base
estimator's stands in, counted (``model.fallbacks`` of the slave's stats) and logged the first time. Without a
model file :func:`kaist_live` reports what leaving the extension out costs in degrees when given the analysis's
figure.
"""
from __future__ import annotations

import dataclasses
import datetime as _dt
import json
import logging
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from estimator.errors import CalibrationError
from estimator.offline.pair.fit import PairParams, fit_pair
from estimator.online.pair import KAIST_PLAY, PairEstimator
from estimator.online.pair_batch import predict_pair_angle
from estimator.sheath import SheathModel
from recorded.kaist import KaistRecording, split
from slave.axis import SlaveAxis
from slave.calibration_file import InstrumentCalibration, TendonCalibration
from slave.estimator_model import configured_model, pair_model_estimator
from slave.pair_axis import PairAxis
from slave.pair_calibrate import set_tension
from slave.pair_control import PairController
from slave.recording.routine import RecordedRoutine, recorded_model_path
from slave.rig import InstrumentTruth, Rig, RigInputError, RigState
from teleop.config.model_file import ModelFile
from teleop.config.schema import Config
from teleop.wire.messages import AxisState

__all__ = ["RecordedPair", "kaist_live", "fit_kaist", "RecordedPairAxis", "model_out_of_range"]

log = logging.getLogger("teleop.slave")

N_NODES = 50          # profile elements per tendon, as the offline pair model


class RecordedPair:
    """A KAIST recording as one joint's tendon pair (module docstring); x_in in units of the pulley radius.

    Parameters
    ----------
    rec : KaistRecording
    G : float
        Motor-to-joint ratio g / r [-] (the calibration's).
    joint_name : str
    """

    def __init__(self, rec: KaistRecording, G: float = 1.0, joint_name: str = "bend", rate: str = "recording"):
        if rate not in ("recording", "slave"):
            raise RigInputError(f"rig.recording.rate must be recording or slave, got {rate!r}")
        self.rec, self.G, self.rate = rec, float(G), rate
        self.joint_names = (joint_name,)
        self.finished = False
        self._i = 0
        self._t = float(rec.time[0])
        self._state = self._read(0, np.zeros((1, 2)))

    @classmethod
    def from_config(cls, cfg: Config, path: Path) -> RecordedPair:
        """The KAIST recording ``path`` for the config's one joint, x_in = the motor command (G = 1: the
        calibration's G = g / r is applied by :class:`RecordedPairAxis`)."""
        from recorded.kaist import read_kaist_recording
        return cls(read_kaist_recording(path), 1.0, cfg.instrument.joints[0].name, cfg.rig.recording.rate)

    @property
    def axis_kind(self) -> Any:
        """The slave's axis kind on this rig: :class:`RecordedPairAxis`."""
        return RecordedPairAxis

    @property
    def state(self) -> RigState:
        return self._state

    def step(self, x_in_cmd: Any, dt: float) -> RigState:
        """The next recorded sample (the command is recorded in the state, the recording's motion is the one that
        happened). Raises RigInputError for ``dt`` not a finite number > 0."""
        if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt > 0):
            raise RigInputError(f"dt must be a finite time step > 0 s, got {dt!r}")
        n, cmd = len(self.rec), np.asarray(x_in_cmd, dtype=float).reshape(1, 2)
        if self.rate == "slave":        # resampled (linear) at the rig's time
            self._t = min(self._t + dt, float(self.rec.time[-1]))
            self.finished = self._t >= float(self.rec.time[-1])
            self._state = self._read(-1, cmd)
            return self._state
        self._i = min(self._i + 1, n - 1)
        self.finished = self._i == n - 1
        self._state = self._read(self._i, cmd)
        return self._state

    def _read(self, k: int, cmd: np.ndarray) -> RigState:
        """Sample ``k`` (>= 0), else the recording interpolated at the rig's time."""
        r = self.rec
        if k >= 0:
            t, c, ta, tb, th = (float(v[k]) for v in (r.time, r.command, r.T_a, r.T_b, r.angle))
        else:
            t = self._t
            c, ta, tb, th = (float(np.interp(t, r.time, v)) for v in (r.command, r.T_a, r.T_b, r.angle))
        x = self.G * c
        none = np.zeros((1, 2))         # distal tensions and stretch are not measured on the KAIST robot
        truth = InstrumentTruth(theta=np.array([th]), torque=np.zeros(1), T_in=none, T_out=none, x_in=none,
                                x_out=none, elongation=none)
        return RigState(t=t, x_in=np.array([[x, -x]]), T_in=np.array([[ta, tb]]), x_in_cmd=cmd, truth=truth)

    def set_load(self, *, tissue: bool | None = None, force: float | None = None) -> None:
        """The recorded load is the one that acted: nothing to switch."""

    def close(self) -> None:
        """Nothing to release; idempotent."""


def kaist_live(rec: KaistRecording, extended_deg: float | None = None) -> dict:
    """Live and offline distal-angle RMSE [deg] on the test cycles of ``rec`` (module docstring); with
    ``extended_deg`` (the offline analysis's extended model on the same cycles) the cost of leaving it out."""
    c1, c2, how = split(rec)
    n_train = c1.stop
    live_fit = fit_pair(rec.command, rec.T_a, rec.T_b, rec.angle, n_train, N_NODES, predict=predict_pair_angle,
                        name="joint estimator")
    seed = fit_pair(rec.command, rec.T_a, rec.T_b, rec.angle, n_train, N_NODES)
    p = PairParams(**live_fit.params)
    rig = RecordedPair(rec, p.G)
    models = [SheathModel(K=K, compliance=max(2.0 * lam, 1e-12)) for K, lam in ((p.K_a, p.lam_a), (p.K_b, p.lam_b))]
    est = PairEstimator(models[0], models[1], 1.0, n_nodes=N_NODES, pretension=(float(rec.T_a[0]), float(rec.T_b[0])),
                         play=KAIST_PLAY)
    offset = p.G * float(rec.command[0]) + p.theta0
    angle = np.empty(len(rec))
    st = rig.state
    for k in range(len(rec)):
        if k:
            st = rig.step(st.x_in, float(rec.time[k] - rec.time[k - 1]))
        s = est.step(float(st.T_in[0, 0]), float(st.x_in[0, 0]), float(st.T_in[0, 1]), float(st.x_in[0, 1]), st.t)
        angle[k] = s.angle + offset

    def deg(e: np.ndarray) -> float:
        return float(math.degrees(np.sqrt(np.mean(e ** 2))))
    live = deg(angle[c2] - rec.angle[c2])
    out: dict[str, Any] = {"config_deg": rec.config_deg, "split": how, "test_samples": int(c2.stop - c2.start),
           "live_rmse_deg": live,
           "live_batch_rmse_deg": deg(live_fit.prediction[c2] - rec.angle[c2]),
           "seed_offline_rmse_deg": deg(seed.prediction[c2] - rec.angle[c2])}
    if extended_deg is not None:
        out["extended_offline_rmse_deg"] = float(extended_deg)
        out["left_out_cost_deg"] = live - float(extended_deg)
    return out


def model_out_of_range(s: Any, structure: str) -> str | None:
    """Why a model's step ``s`` (:class:`estimator.online.pair_model.PairModelSample`) leaves the physical range, or
    None: a non-finite angle, or (the capstan structure, which predicts them) a proximal tension that is negative or
    not finite."""
    if not math.isfinite(s.angle):
        return f"angle {s.angle!r}"
    if structure == "capstan" and not (math.isfinite(s.T_a) and math.isfinite(s.T_b) and s.T_a >= 0.0
                                       and s.T_b >= 0.0):
        return f"predicted proximal tensions {s.T_a:.4g}, {s.T_b:.4g} N"
    return None


# ---- the slave's pair axis on a KAIST recording --------------------------------------------------------------



def fit_kaist(cfg: Config) -> dict:
    """The live estimator's calibration on command cycle 1 of ``rig.recording.calibration_run`` (a KAIST file),
    else of the played recording itself, as ``teleop analyze --kaist`` calibrates: the six parameters of the
    seed pair model fitted with the joint estimator as the model. Returns the model record (JSON-ready).

    Raises
    ------
    DataError
        An unreadable calibration recording, or one too short to split.
    """
    from recorded.kaist import read_kaist_recording
    path = Path(cfg.rig.recording.calibration_run or str(cfg.rig.recording.path)).expanduser()
    rec = read_kaist_recording(path)
    c1, _, how = split(rec)
    fit = fit_pair(rec.command, rec.T_a, rec.T_b, rec.angle, c1.stop, N_NODES, predict=predict_pair_angle,
                   name="joint estimator")
    return {"params": {k: float(v) for k, v in fit.params.items()}, "run": str(path), "split": how}


class RecordedPairCalibration:
    """The power-up "routine" on a KAIST recording: :func:`fit_kaist`, made at once; ``done`` from the start."""

    def __init__(self, cfg: Config):
        self.cfg = cfg
        self.model = fit_kaist(cfg)
        self.done = True


def _calibration(cfg: Config, model: dict) -> InstrumentCalibration:
    """The slave's calibration data of ``model``: each tendon's K, compliance 2 lam / G in the rig's units."""
    p = PairParams(**model["params"])
    cables = {}
    for t, K, lam in (("a", p.K_a, p.lam_a), ("b", p.K_b, p.lam_b)):
        c = max(2.0 * lam / max(p.G, 1e-9), 1e-12)
        M_e = c * (1.0 - math.exp(-K)) / K if K > 1e-9 else c
        cables[t] = TendonCalibration(K=float(K), M_e=M_e, compliance=c, knee_x_in=0.0, knee_T_in=0.0,
                                      residual_rms=0.0, n_samples=1)
    date = _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")
    return InstrumentCalibration(instrument=cfg.instrument.id, date=date, target_tension=cfg.calibration.target_tension,
                                 use_route=cfg.calibration.use_route, joints=((cfg.instrument.joints[0].name, cables),),
                                 method=f"fitted on command cycle 1 of recorded {Path(model['run']).name} (the seed "
                                        "pair model with the joint estimator, as teleop analyze --kaist)")


class RecordedPairAxis(RecordedRoutine, PairAxis):
    """The pair axis on a KAIST recording: x_in is the motor command [rad] on both tendons, the estimator
    runs in units of the pulley radius with r = 1 / G (so that G c is the kinematic angle) and adds the
    angle offset G c_0 + theta_0 (:func:`estimator.online.pair_batch.predict_pair_angle`); the torque it
    reports is r (T_out,a - T_out,b) with the config's pulley radius r (the master renders T_out,a - T_out,b)."""

    offset = 0.0
    torque_scale = 1.0
    routine_class = RecordedPairCalibration
    model_calibration = staticmethod(_calibration)
    model_file: ModelFile | None = None     # the model file it runs (estimator.model), or None: the base estimator
    pair_model: Any = None                  # its PairModelEstimator
    model_cycles = 0                        # cycles the model was stepped
    fallbacks = 0                           # of them, cycles the base estimator's angle stood in

    def start_model(self, model: dict, state: RigState) -> None:
        """The joint estimator of ``model`` at the rig's current sample (its tensions: the pretension)."""
        p = PairParams(**model["params"])
        i, G = self.index, max(p.G, 1e-9)
        pc = self.cfg.pair_control
        self.controller = PairController(self.r, set_tension(self.cfg, self.joint), pc.tension_gain, pc.switch_band,
                                         self.cfg.slave.relax_speed, tuple(state.x_in_cmd[i]),
                                         feedforward=pc.feedforward)
        models = [SheathModel(K=K, compliance=max(2.0 * lam / G, 1e-12))
                  for K, lam in ((p.K_a, p.lam_a), (p.K_b, p.lam_b))]
        T0 = (float(state.T_in[i, 0]), float(state.T_in[i, 1]))
        self.estimator = PairEstimator(models[0], models[1], 1.0 / G, n_nodes=N_NODES, pretension=T0,
                                        play=KAIST_PLAY / G)
        self.offset = G * float(state.x_in[i, 0]) + p.theta0
        self.torque_scale = self.r * G      # r (T_out,a - T_out,b) with the config's pulley radius r [m]
        s = self.estimator.step(T0[0], float(state.x_in[i, 0]), T0[1], float(state.x_in[i, 1]), state.t)
        self.sample = s._replace(angle=s.angle + self.offset, torque=s.torque * self.torque_scale)
        mf = configured_model(self.cfg)
        if mf is not None:
            self.start_pair_model(mf, state, T0)

    def start_pair_model(self, mf: ModelFile, state: RigState, T0: tuple[float, float]) -> None:
        """Run the model file ``mf`` from the rig's current sample (its proximal tensions ``T0`` [N]: the
        pretension): its angle replaces the base estimator's, except in the cycles where its prediction leaves the
        physical range (:func:`model_out_of_range`)."""
        self.model_file, self.model_cycles, self.fallbacks = mf, 0, 0
        self.pair_model = pair_model_estimator(mf, T0)
        log.info("%s: estimator model %s (sha256 %s...) from %s, driven by the measured motor position; held-out "
                 "%.2f %s where it was fitted (base %.2f)", self.name, mf.model_id, mf.sha256[:12], mf.path,
                 mf.gain["extended"], mf.gain["unit"], mf.gain["base"])
        self.sample = self.sample._replace(angle=self.model_angle(state, self.sample.angle))

    def model_angle(self, state: RigState, base_angle: float) -> float:
        """One step of the model file's estimator on the rig's sample: its distal angle [rad], or ``base_angle`` [rad]
        (the base estimator's) when its prediction leaves the physical range; counted, and logged the first time."""
        i = self.index
        Ta, Tb = state.T_in[i].tolist()
        self.model_cycles += 1
        try:
            s = self.pair_model.step(float(state.x_in[i, 0]), Ta, Tb, state.t)
            why = model_out_of_range(s, self.pair_model.structure)
        except ValueError as e:         # an input the model cannot read (non-finite, time not increasing)
            why = str(e)
        if why is None:
            return s.angle
        self.fallbacks += 1
        if self.fallbacks == 1:
            log.warning("%s: the model's prediction leaves the physical range at t = %.3f s (%s): the base estimator's "
                        "angle stands in for every such cycle (counted as model.fallbacks in slave_stats.json)",
                        self.name, state.t, why)
        return base_angle

    def model_stats(self) -> dict | None:
        """The model file's entry of the slave's stats: id, sha256, path, cycles run, fallbacks; None without one."""
        mf = self.model_file
        if mf is None:
            return None
        return {"id": mf.model_id, "sha256": mf.sha256, "path": mf.path, "cycles": self.model_cycles,
                "fallbacks": self.fallbacks, "gain": dict(mf.gain)}

    @classmethod
    def finish_routine(cls, axes: Sequence[SlaveAxis], routine: Any, state: RigState) -> tuple[Any, dict]:
        cfg, model = routine.cfg, routine.model
        path = recorded_model_path(cfg)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(model, indent=1), encoding="utf-8")
        for ax in axes:
            assert isinstance(ax, RecordedPairAxis)
            ax.start_model(model, state)
        calibration = _calibration(cfg, model)
        return calibration, {**calibration.as_dict(), "recorded_model": model}

    @classmethod
    def start_loaded(cls, axes: Sequence[SlaveAxis], calibration: Any, state: RigState) -> dict:
        path = recorded_model_path(axes[0].cfg)
        try:
            model = json.loads(path.read_text(encoding="utf-8"))
            PairParams(**model["params"])
        except FileNotFoundError:
            raise CalibrationError(f"{path}: the recorded axis's model file is missing (start the slave with "
                                   "--recalibrate to fit it again)") from None
        except (OSError, ValueError, KeyError, TypeError) as e:
            raise CalibrationError(f"{path}: not a recorded pair's model file ({type(e).__name__}: {e})") from None
        for ax in axes:
            assert isinstance(ax, RecordedPairAxis)
            ax.start_model(model, state)
        return {**calibration.as_dict(), "recorded_model": model}

    @classmethod
    def recording(cls, cfg: Config, rig: Rig) -> tuple[str, tuple[str, ...], dict[str, str]]:
        name, cols, meta = super().recording(cfg, rig)
        return name, cols, {**meta, "rig": f"recording {cfg.rig.recording.path}",
                            "drive": "x_in: the KAIST motor command [rad] on both tendons (+a, -b)",
                            "truth": "angle: the recording's measured distal angle; torque, T_out, elongation are "
                                     "not measured (0)"}

    @classmethod
    def observe_all(cls, axes: Sequence[SlaveAxis], state: RigState) -> list[tuple[AxisState, tuple[float, ...]]]:
        """Every joint's estimate with its angle offset (module docstring)."""
        out = []
        for ax in axes:
            assert isinstance(ax, RecordedPairAxis)
            a, extra = ax.observe(state)
            angle = ax.sample.angle + ax.offset
            if ax.pair_model is not None:
                angle = ax.model_angle(state, angle)
            ax.sample = ax.sample._replace(angle=angle, torque=ax.sample.torque * ax.torque_scale)
            out.append((dataclasses.replace(a, position_hat=angle, effort_hat=a.effort_hat * ax.torque_scale), extra))
        return out

    @classmethod
    def stats(cls, axes: Sequence[SlaveAxis]) -> dict[str, Any]:
        """The pair axis's counters and ``model``: the model file's entry (:meth:`model_stats`), None without one."""
        models = [ax.model_stats() for ax in axes if isinstance(ax, RecordedPairAxis)]
        return {**super().stats(axes), "model": models[0] if models else None}

    @classmethod
    def warm_up(cls, cfg: Config) -> None:
        m = SheathModel(K=0.5, compliance=1e-4)
        est = PairEstimator(m, m, 1.0, n_nodes=4)
        est.step(1.0, 0.0, 0.5, 0.0, 0.0)
        est.step(1.1, 0.0, 0.5, 0.0, 1e-3)
