"""``teleop analyze --mrd DIR --tool T --model-out OUTDIR``: the spindle model the recording rig runs on DIR's runs, as
a model file (``OUTDIR/<folder name>.model.yaml``; :mod:`slave.recording.spindle_model`, docs/reference/formats.md,
"Model file").

The model is the one-run calibration the recording rig makes at power-up with the tool file today
(:func:`slave.recording.spindle.fit_recorded_model`: the calibration run by the tool's rule, or ``--calibration RUN``,
the tool's load gain; the spindle pair model with its selected extensions, the centre map, the choice between
them), for the instrument of the recording rig's config (``configs/recording-mrd.yaml``, ``instrument.id``). Its
held-out gain is the analysis's: the median jaw-torque RMSE over the scored runs [FS] of the base spindle pair model
(no extension) and of the chosen model.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path

from recorded.mrd import MrdRun
from slave.recording.spindle import fit_recorded_model
from slave.recording.spindle_model import spindle_model_file
from teleop.config.files import shipped_config
from teleop.config.load import load_config
from teleop.config.model_file import save_model
from teleop.errors import ConfigError

__all__ = ["MRD_CONFIG", "check_model_out", "write_mrd_model"]

#: The recording rig's config of the MRD runs: its ``instrument.id`` names the instrument of the model file.
MRD_CONFIG = "recording-mrd.yaml"


def check_model_out(args) -> None:
    """Refuse ``--model-out`` where the recording rig's calibration is not the analysis's: without ``--tool``, or with
    a ``--calibration`` other than one run (ConfigError, one line)."""
    out = getattr(args, "model_out", None)
    if out is None:
        return
    if not getattr(args, "tool", None):
        raise ConfigError(f"--model-out {out}: the MRD model file is the recording rig's one-run calibration with a "
                          "tool file's load gain: give --tool T")
    cal = getattr(args, "calibration", None)
    if cal and (":" in cal or "," in cal or cal.startswith("gain=")):
        raise ConfigError(f"--model-out {out}: --calibration {cal}: the recording rig calibrates on one run (a run "
                          "name or mid)")


def write_mrd_model(args, runs: list[MrdRun], summary: dict) -> Path:
    """Write ``<args.model_out>/<folder name>.model.yaml`` (module docstring) and return its path.

    Raises
    ------
    ConfigError
        ``--model-out`` exists and is not a directory, or a model that would not read back.
    CalibrationError, DataError
        The one-run calibration fails (:func:`slave.recording.spindle.fit_recorded_model`).
    """
    out = Path(args.model_out)
    if out.exists() and not out.is_dir():
        raise ConfigError(f"--model-out {args.model_out}: exists and is not a directory")
    cfg = load_config(shipped_config(MRD_CONFIG))
    folder = Path(runs[0].source).parent
    rec = dataclasses.replace(cfg.rig.recording, path=str(runs[0].source), calibration_run=args.calibration or None)
    cfg = dataclasses.replace(cfg, instrument=dataclasses.replace(cfg.instrument, tool=args.tool),
                              rig=dataclasses.replace(cfg.rig, recording=rec))
    model = fit_recorded_model(cfg)
    s = summary["summary"]
    base_name = min(s["models"], key=len)           # the spindle pair model without an extension
    gain = {"base": float(s["models"][base_name]["median_torque_rmse_fs"]),
            "extended": float(s["model"]["median_torque_rmse_fs"]),
            "unit": "FS (jaw torque RMSE over the full scale, median of the scored runs)"}
    cal = next((r for r in runs if r.name == Path(model.run).stem), None)
    span = [0.0, float(cal.time[-1])] if cal is not None else [0.0, 0.0]
    mf = spindle_model_file(model, cfg.instrument.id, gain, span)
    return save_model(mf, out / f"{folder.name}.model.yaml")
