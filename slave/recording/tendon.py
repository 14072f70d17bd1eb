"""A measured-data CSV (one tendon) played as the single-tendon axis's hardware.

The project's measured-data CSV (docs/reference/formats.md: time [s], x_in [m], T_in [N] and the distal T_out [N]
and/or x_out [m]; :func:`teleop.recording.measured_csv.read_measured_csv`, the reader of ``teleop analyze FILE``) gives
the proximal signals each cycle (x_in, T_in) and its distal channels as the truth. :class:`RecordedTendon` is the rig
(one recorded sample per step, or resampled at the rig's time); :class:`RecordedTendonAxis` the single-tendon axis on
it: its calibration is the profile-memory estimator's K and L/EA fitted on the first 60 % of the calibration recording
(``rig.recording.calibration_run``, else the played one) by :func:`estimator.offline.fit.fit_single`, the fit of
``examples/estimate_csv.py``, saved as the calibration file and ``<instrument.id>.recording.json`` and reloaded. The
estimate is :class:`estimator.online.distal.DistalEstimator`, the axis's own.
"""
from __future__ import annotations

import datetime as _dt
import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from estimator.data import MeasuredData
from estimator.errors import CalibrationError
from estimator.sheath import SheathModel
from recorded.detect import read_tendon_csv
from slave.axis import SlaveAxis
from slave.calibration_file import InstrumentCalibration, TendonCalibration
from slave.recording.routine import RecordedRoutine, recorded_model_path
from slave.rig import Rig, RigInputError, RigState, RigTruth
from slave.tendon_axis import TendonAxis
from teleop.config.schema import Config

__all__ = ["RecordedTendon", "fit_tendon", "RecordedTendonAxis"]


class RecordedTendon:
    """A measured-data CSV as one tendon (module docstring), a :class:`slave.rig.Rig` of tendon shape ``()``."""

    def __init__(self, data: MeasuredData, rate: str = "recording"):
        if rate not in ("recording", "slave"):
            raise RigInputError(f"rig.recording.rate must be recording or slave, got {rate!r}")
        self.data, self.rate = data, rate
        self.finished = False
        self._i = 0
        self._t = float(data.time[0])
        self._state = self._read(0, 0.0)

    @classmethod
    def from_config(cls, cfg: Config, path: Path) -> RecordedTendon:
        return cls(read_tendon_csv(path), cfg.rig.recording.rate)

    @property
    def axis_kind(self) -> Any:
        """The slave's axis kind on this rig: :class:`RecordedTendonAxis`."""
        return RecordedTendonAxis

    @property
    def state(self) -> RigState:
        return self._state

    def step(self, x_in_cmd: Any, dt: float) -> RigState:
        """The next recorded sample (``rate: slave``: the recording at the rig's time); the command is recorded in
        the state only. Raises RigInputError for ``dt`` not a finite number > 0."""
        if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt > 0):
            raise RigInputError(f"dt must be a finite time step > 0 s, got {dt!r}")
        d, cmd = self.data, float(x_in_cmd)
        if self.rate == "slave":
            self._t = min(self._t + dt, float(d.time[-1]))
            self.finished = self._t >= float(d.time[-1])
            self._state = self._read(-1, cmd)
        else:
            self._i = min(self._i + 1, len(d.time) - 1)
            self.finished = self._i == len(d.time) - 1
            self._state = self._read(self._i, cmd)
        return self._state

    def _read(self, k: int, cmd: float) -> RigState:
        d = self.data

        def at(v: np.ndarray | None) -> float:
            if v is None:
                return 0.0              # a distal channel the recording does not have
            return float(v[k]) if k >= 0 else float(np.interp(self._t, d.time, v))
        t = float(d.time[k]) if k >= 0 else self._t
        x_in, T_in, x_out, T_out = at(d.x_in), at(d.T_in), at(d.x_out), at(d.T_out)
        truth = RigTruth(T_in=T_in, T_out=T_out, x_in=x_in, x_out=x_out,
                         elongation=x_in - x_out if d.x_out is not None else 0.0, profile=np.zeros(1))
        return RigState(t=t, x_in=x_in, T_in=T_in, x_in_cmd=cmd, truth=truth)

    def set_load(self, *, tissue: bool | None = None, force: float | None = None) -> None:
        """The recorded load is the one that acted: nothing to switch."""

    def close(self) -> None:
        """Nothing to release; idempotent."""


def fit_tendon(cfg: Config) -> dict:
    """K [-] and L/EA [m/N] of the profile-memory estimator fitted on the first 60 % of the calibration recording
    (module docstring); the model record (JSON-ready). Raises DataError for an unreadable recording."""
    from estimator.offline.fit import fit_single
    path = Path(cfg.rig.recording.calibration_run or str(cfg.rig.recording.path)).expanduser()
    d = read_tendon_csv(path)
    fit = fit_single(d.time, d.T_in, d.x_in, T_out=d.T_out, x_out=d.x_out, n_nodes=cfg.estimator.n_nodes,
                     pretension=cfg.sheath.pretension)
    f = fit.fits["profile"]
    # with T_out alone L/EA is not identifiable and does not change T_out: any positive value will do
    return {"K": float(f.K), "compliance": float(f.compliance) if f.compliance is not None else 1e-4,
            "run": str(path), "split_time_s": float(fit.split_time)}


class RecordedTendonCalibration:
    """The power-up "routine" on a recorded tendon: :func:`fit_tendon`, made at once; ``done`` from the start."""

    def __init__(self, cfg: Config):
        self.cfg = cfg
        self.model = fit_tendon(cfg)
        self.done = True


def _calibration(cfg: Config, model: dict) -> InstrumentCalibration:
    K, c = model["K"], model["compliance"]
    date = _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")
    tendon = TendonCalibration(K=K, M_e=c * (1.0 - math.exp(-K)) / K if K > 1e-9 else c, compliance=c, knee_x_in=0.0,
                               knee_T_in=0.0, residual_rms=0.0, n_samples=1)
    return InstrumentCalibration(instrument=cfg.instrument.id, date=date, target_tension=cfg.calibration.target_tension,
                                 use_route=cfg.calibration.use_route, tendon=tendon,
                                 method=f"K and L/EA fitted on the first 60 % of recorded {Path(model['run']).name} "
                                        "(the profile-memory estimator, estimator.offline.fit.fit_single)")




class RecordedTendonAxis(RecordedRoutine, TendonAxis):
    """The single-tendon axis on a recorded tendon (module docstring)."""

    routine_class = RecordedTendonCalibration
    model_calibration = staticmethod(_calibration)

    @classmethod
    def finish_routine(cls, axes: Sequence[SlaveAxis], routine: Any, state: RigState) -> tuple[Any, dict]:
        cfg, model = routine.cfg, routine.model
        path = recorded_model_path(cfg)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(model, indent=1), encoding="utf-8")
        ax = axes[0]
        assert isinstance(ax, TendonAxis)
        ax.start(SheathModel(K=model["K"], compliance=model["compliance"]), state)
        calibration = _calibration(cfg, model)
        return calibration, {**calibration.as_dict(), "recorded_model": model}

    @classmethod
    def start_loaded(cls, axes: Sequence[SlaveAxis], calibration: Any, state: RigState) -> dict:
        ax = axes[0]
        assert isinstance(ax, TendonAxis)
        path = recorded_model_path(ax.cfg)
        try:
            model = json.loads(path.read_text(encoding="utf-8"))
            sheath = SheathModel(K=float(model["K"]), compliance=float(model["compliance"]))
        except FileNotFoundError:
            raise CalibrationError(f"{path}: the recorded axis's model file is missing (start the slave with "
                                   "--recalibrate to fit it again)") from None
        except (OSError, ValueError, KeyError, TypeError) as e:
            raise CalibrationError(f"{path}: not a recorded tendon's model file ({type(e).__name__}: {e})") from None
        ax.start(sheath, state)
        return {**calibration.as_dict(), "recorded_model": model}

    @classmethod
    def recording(cls, cfg: Config, rig: Rig) -> tuple[str, tuple[str, ...], dict[str, str]]:
        name, cols, meta = super().recording(cfg, rig)
        return name, cols, {**meta, "rig": f"recording {cfg.rig.recording.path}",
                            "truth": "x_out, T_out: the recording's measured distal channels (0 where it has none)"}
