"""The spindle axis on a recorded MRD run: its calibration fitted on a recorded run, saved and reloaded.

A recording cannot execute the spindle's calibration stroke, so the calibration is the one ``teleop analyze
--mrd`` makes on one run: :func:`fit_recorded_model` calls the analysis's own one-run calibration
(:func:`recorded.mrd_calibration.calibrate_on_runs`: the pair model with its extensions selected on the calibration
run, the centre map with the tool file's load gain, and the headline's model choice between them). The
result is saved as the slave's calibration file ``<calibration.dir>/<instrument.id>.yaml`` (the cables'
friction exponents of the pair fit, in the format of every spindle calibration) and, beside it, the full
model ``<instrument.id>.recording.json`` (the pair model's parameters, the centre map's, which of them gives
the torque); the next start reloads both (:meth:`RecordedSpindleAxis.start_loaded`), as every axis reloads
its calibration.

With a model file (``estimator.model``, ``--model``; ``teleop analyze --mrd DIR --tool T --model-out OUTDIR`` writes
one, :mod:`slave.recording.spindle_model`) the model is the file's, not fitted (:func:`file_model`), at power-up and
on a reloaded calibration alike; the stats name it (id, sha256).

Per cycle the axis runs the same models online: :class:`estimator.online.centre_estimator.CentreEstimator`
(the jaw torque, when the calibration chose the centre map) and
:class:`estimator.online.spindle_estimator.SpindleEstimator` with the fitted pair parameters (the jaw
angle, the cables' tensions and phases; the torque too when the pair model was chosen). Everything else
(commands, engage rule, recording columns, Rerun series) is :class:`slave.spindle_axis.SpindleAxis`'s.
"""
from __future__ import annotations

import dataclasses
import datetime as _dt
import json
import logging
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from estimator.errors import CalibrationError, DataError
from estimator.online.centre_estimator import CentreEstimator
from estimator.online.spindle import N_NODES, SpindleParams
from estimator.online.spindle_centre import CentreParams
from estimator.online.spindle_estimator import SpindleEstimator
from slave.axis import SlaveAxis
from slave.calibration_file import InstrumentCalibration, TendonCalibration
from slave.recording.routine import RecordedRoutine, recorded_model_path
from slave.rig import Rig, RigState
from slave.spindle_axis import SpindleAxis
from slave.spindle_calibrate import pull_slip_M_e
from teleop.config.model_file import ModelFile
from teleop.config.schema import Config
from teleop.errors import ConfigError
from teleop.wire.messages import AxisState, TendonState

__all__ = ["CENTRE", "RecordedModel", "calibration_run_path", "fit_recorded_model", "file_model", "save_model",
           "load_model", "model_calibration", "RecordedCalibration", "RecordedSpindleAxis", "full_scale"]

log = logging.getLogger("teleop.slave")

#: The centre map's name among the models (as :data:`recorded.mrd_centre.CENTRE`).
CENTRE = "centre map"
METHOD_RECORDED = "fitted on recorded run {run} (the one-run calibration of teleop analyze --mrd{tool})"


@dataclass(frozen=True)
class RecordedModel:
    """The fitted model of a recorded spindle axis: ``chosen`` names the torque's model (:data:`CENTRE` or the
    pair model's name), ``pair`` its parameters (SI), ``centre_map`` the centre map's (None when not fitted),
    ``theta_ref`` [rad] the spindle angle the pair model's elastic terms start from, ``run`` the calibration
    run's file, ``tool`` the tool file's name ('' without one), ``band_centre`` [N m] the middle of the
    calibration run's spindle torque band (the batch pair model's initial branch)."""

    chosen: str
    pair_name: str
    pair: SpindleParams
    centre_map: CentreParams | None
    theta_ref: float
    run: str
    tool: str = ""
    band_centre: float = 0.0

    def as_dict(self) -> dict:
        c = self.centre_map
        cmap = None if c is None else {"coef": np.asarray(c.coef).tolist(), "theta_ref": c.theta_ref,
                                       "theta_z": c.theta_z, "window": list(c.window), "half_width": list(c.half_width),
                                       "centre0": c.centre0, "edge_slope": list(c.edge_slope), "notes": c.notes}
        return {"chosen": self.chosen, "pair_name": self.pair_name, "pair": dataclasses.asdict(self.pair),
                "centre_map": cmap, "theta_ref": self.theta_ref, "run": self.run, "tool": self.tool,
                "band_centre": self.band_centre}

    @classmethod
    def from_dict(cls, d: dict) -> RecordedModel:
        """Raises KeyError or TypeError on a malformed record (:func:`load_model` turns them into one line)."""
        c = d["centre_map"]
        cmap = None if c is None else CentreParams(np.asarray(c["coef"], dtype=float), float(c["theta_ref"]),
                                                   float(c["theta_z"]), tuple(c["window"]), tuple(c["half_width"]),
                                                   float(c["centre0"]), tuple(c["edge_slope"]), dict(c["notes"]))
        return cls(str(d["chosen"]), str(d["pair_name"]), SpindleParams(**d["pair"]), cmap, float(d["theta_ref"]),
                   str(d["run"]), str(d.get("tool", "")), float(d.get("band_centre", 0.0)))


def _tool(cfg: Config):
    from teleop.config.tools import load_tool
    return load_tool(cfg.instrument.tool) if cfg.instrument.tool else None


def full_scale(cfg: Config, tau_d: np.ndarray) -> float:
    """Full scale of the jaw torque [N m]: the tool file's measured output-torque range, else the range of
    ``tau_d`` [N m] (the recording's own)."""
    tool = _tool(cfg)
    if tool is not None:
        lo, hi = tool.limits.output_torque
        return float(hi - lo)
    return float(np.ptp(tau_d))


def calibration_run_path(cfg: Config) -> Path:
    """The calibration run's file: ``rig.recording.calibration_run`` (a path, or a run name of the recording's
    folder), else the tool file's ``calibration.runs`` rule (``mid``: the run whose spindle band centre is
    nearest the middle of the folder's, as ``teleop analyze --mrd --calibration mid``), else ``mid``.

    Raises
    ------
    DataError
        No such run in the folder (the message lists the folder's runs).
    """
    from recorded.mrd import load_mrd_dir
    rc = cfg.rig.recording
    folder = Path(str(rc.path)).expanduser().parent
    tool = _tool(cfg)
    name = rc.calibration_run or (tool.calibration.runs if tool is not None else "mid")
    as_path = Path(name).expanduser()
    if as_path.is_file():
        return as_path
    if name == "mid":
        from recorded.mrd_calibration import run_data
        from recorded.mrd_centre import mid_centre_run
        runs, _ = load_mrd_dir(folder)
        name = mid_centre_run([run_data(r) for r in runs])
    for ext in (".TXT", ".txt"):
        if (folder / f"{name}{ext}").is_file():
            return folder / f"{name}{ext}"
    names = sorted(p.stem for p in folder.glob("*.TXT"))
    raise DataError(f"rig.recording.calibration_run: no run {name!r} in {folder} (runs: {', '.join(names) or 'none'})")


def fit_recorded_model(cfg: Config, run_file: Path | None = None) -> RecordedModel:
    """The one-run calibration of ``teleop analyze --mrd`` on ``run_file`` (default
    :func:`calibration_run_path`), with the tool file's load gain (module docstring).

    Raises
    ------
    DataError
        An unreadable calibration run (:func:`recorded.mrd.read_mrd`).
    CalibrationError
        A fit that fails on this run (the message names the run).
    """
    from estimator.offline.spindle.fit import band_centre
    from recorded.mrd import read_mrd
    from recorded.mrd_calibration import calibrate_on_runs
    path = run_file or calibration_run_path(cfg)
    run = read_mrd(path)
    tool = _tool(cfg)
    gain = tool.load_gain.value if tool is not None else None
    spec = None if gain is None else f"gain={gain!r}:{run.name}"
    out: dict[str, Any] = {}
    try:
        _, cmap, cal = calibrate_on_runs([run], "run", run.name, spec, (gain, None), full_scale(cfg, run.tau_d),
                                          lambda _label: None, out)
    except (ValueError, FloatingPointError) as e:
        raise CalibrationError(f"{path}: the one-run calibration fails on this run ({e})") from None
    pair_name = list(out["parameters"])[-1]
    return RecordedModel(chosen=str(out["model_choice"]["chosen"]), pair_name=pair_name,
                         pair=SpindleParams(**out["parameters"][pair_name]), centre_map=cmap,
                         theta_ref=float(np.mean([np.mean(c.theta_p) for c in cal])), run=str(path),
                         tool="" if tool is None else tool.name,
                         band_centre=float(np.mean([band_centre(c.tau_p) for c in cal])))




def save_model(model: RecordedModel, path: str | Path) -> Path:
    """Write ``model`` as JSON to ``path`` (directories created); returns the path."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(json.dumps(model.as_dict(), indent=1), encoding="utf-8")
    return p


def load_model(path: str | Path) -> RecordedModel:
    """Read a model written by :func:`save_model`.

    Raises
    ------
    CalibrationError
        Missing, unreadable or malformed file (one line naming it).
    """
    p = Path(path)
    try:
        return RecordedModel.from_dict(json.loads(p.read_text(encoding="utf-8")))
    except FileNotFoundError:
        raise CalibrationError(f"{p}: the recorded axis's model file is missing (start the slave with "
                               "--recalibrate to fit it again)") from None
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise CalibrationError(f"{p}: not a recorded axis's model file ({type(e).__name__}: {e})") from None


def model_calibration(cfg: Config, model: RecordedModel, date: str | None = None) -> InstrumentCalibration:
    """The slave's calibration data of ``model``: each cable's K of the pair fit, M_e from it and the route."""
    date = date or _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")
    joint = cfg.instrument.joints[0]
    cables = {}
    for t, K in (("a", model.pair.K_a), ("b", model.pair.K_b)):
        tendon = getattr(joint.tendons, t)
        cables[t] = TendonCalibration(K=float(K), M_e=pull_slip_M_e(joint, t, float(K)),
                                      compliance=tendon.geometry().length / tendon.EA, knee_x_in=0.0, knee_T_in=0.0,
                                      residual_rms=0.0, n_samples=1)
    tool = f", tool {model.tool}" if model.tool else ""
    c = cfg.calibration
    return InstrumentCalibration(instrument=cfg.instrument.id, date=date, target_tension=c.target_tension,
                                 use_route=c.use_route, joints=((joint.name, cables),),
                                 method=METHOD_RECORDED.format(run=Path(model.run).name, tool=tool))


class RecordedCalibration:
    """The power-up "routine" of a recorded axis: the fit of :func:`fit_recorded_model`, made at once (the
    recording is not played meanwhile). ``done`` is True from the start."""

    def __init__(self, cfg: Config):
        self.cfg = cfg
        self.model = file_model(cfg) or fit_recorded_model(cfg)
        self.done = True


def file_model(cfg: Config) -> RecordedModel | None:
    """The recorded model of the model file ``estimator.model`` (checked,
    :func:`slave.estimator_model.configured_model`; its calibration run in the played run's folder), or None without
    one: the model is then fitted."""
    from slave.estimator_model import configured_model
    from slave.recording.spindle_model import recorded_model_dict
    mf = configured_model(cfg)
    if mf is None:
        return None
    folder = Path(str(cfg.rig.recording.path)).expanduser().parent
    tool = _tool(cfg)
    return RecordedModel.from_dict(recorded_model_dict(mf, folder, "" if tool is None else tool.name))


class RecordedSpindleAxis(RecordedRoutine, SpindleAxis):
    """The spindle axis on a recorded run (module docstring)."""

    centre: CentreEstimator | None = None
    model_file: ModelFile | None = None       # the model file it runs (estimator.model), or None: fitted at power-up
    routine_class = RecordedCalibration
    model_calibration = staticmethod(model_calibration)

    def start_model(self, model: RecordedModel, state: RigState) -> None:
        """The online estimators of ``model``, at rest at the rig's current sample."""
        from slave.estimator_model import configured_model
        mf = self.model_file = configured_model(self.cfg)
        if mf is not None:
            log.info("%s: estimator model %s (sha256 %s...) from %s: torque from the %s", self.name, mf.model_id,
                     mf.sha256[:12], mf.path, model.chosen if model.chosen == CENTRE else "spindle pair model")
        j, i = self.joint, self.index
        self.rest = self.phi_cmd = float(np.asarray(state.x_in)[i])
        c = tuple(t.geometry().length / t.EA for t in (j.tendons.a, j.tendons.b))
        self.estimator = SpindleEstimator(model.pair, self.r_p, (c[0], c[1]), theta_ref=model.theta_ref,
                                          n_nodes=N_NODES, rate_time_constant=self.cfg.estimator.rate_time_constant,
                                          hold_rate=self.cfg.estimator.hold_rate)
        self.centre = CentreEstimator(model.centre_map) if model.chosen == CENTRE and model.centre_map else None
        self.sample = self.estimator.step(float(np.asarray(state.T_in)[i]), self.rest, state.t)
        if self.centre is not None:
            self.sample = dataclasses.replace(self.sample, torque=self.centre.step(
                float(np.asarray(state.T_in)[i]), self.rest, state.t))

    @classmethod
    def finish_routine(cls, axes: Sequence[SlaveAxis], routine: Any, state: RigState) -> tuple[Any, dict]:
        cfg, model = routine.cfg, routine.model
        save_model(model, recorded_model_path(cfg))
        for ax in axes:
            assert isinstance(ax, RecordedSpindleAxis)
            ax.start_model(model, state)
        log.info("calibrated %s on recorded run %s: torque from the %s", cfg.instrument.joints[0].name,
                 Path(model.run).name, model.chosen)
        calibration = model_calibration(cfg, model)
        return calibration, {**calibration.as_dict(), "recorded_model": model.as_dict()}

    @classmethod
    def start_loaded(cls, axes: Sequence[SlaveAxis], calibration: InstrumentCalibration, state: RigState) -> dict:
        cfg = axes[0].cfg if axes else None
        if cfg is None:
            raise ConfigError("a recorded spindle instrument needs one joint")
        model = file_model(cfg) or load_model(recorded_model_path(cfg))
        for ax in axes:
            assert isinstance(ax, RecordedSpindleAxis)
            ax.start_model(model, state)
        return {**calibration.as_dict(), "recorded_model": model.as_dict()}

    @classmethod
    def recording(cls, cfg: Config, rig: Rig) -> tuple[str, tuple[str, ...], dict[str, str]]:
        """``slave_joints.csv`` in the joint instrument's columns; the truth is the recording's."""
        name, cols, meta = super().recording(cfg, rig)
        src = cfg.rig.recording.path or ""
        return name, cols, {**meta, "rig": f"recording {src}",
                            "truth": "torque, angle: the recording's measured jaw torque and angle; the cables' "
                                     "T_out and elongation are not measured (0)"}

    @classmethod
    def stats(cls, axes: Sequence[SlaveAxis]) -> dict[str, Any]:
        """The axis's entries and ``model``: the model file's id, sha256 and path (None without one)."""
        mf = next((ax.model_file for ax in axes if isinstance(ax, RecordedSpindleAxis)), None)
        return {"joints": [a.name for a in axes], "drive": "spindle", "rig": "recording",
                "model": None if mf is None else {"id": mf.model_id, "sha256": mf.sha256, "path": mf.path}}

    def observe(self, state: RigState) -> tuple[AxisState, tuple[float, ...]]:
        assert self.estimator is not None
        i = self.index
        phi, tau = float(state.x_in[i]), float(state.T_in[i])
        s = self.estimator.step(tau, phi, state.t)
        if self.centre is not None:
            s = dataclasses.replace(s, torque=self.centre.step(tau, phi, state.t))
        self.sample = s
        x = self.r_p * (phi - self.rest)
        return AxisState(s.torque, s.angle, (TendonState(s.T_in[0], x, s.T_out[0], s.elongation[0], s.phase[0]),
                                             TendonState(s.T_in[1], -x, s.T_out[1], s.elongation[1], s.phase[1]))), ()
