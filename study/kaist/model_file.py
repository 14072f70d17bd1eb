"""``teleop analyze --kaist DIR --model-out OUTDIR``: the model the pair diagnosis chose for each configuration, as a
model file the live estimator runs (:mod:`teleop.config.model_file`, docs/reference/formats.md, "Model file").

One file per recording, ``OUTDIR/<recording stem>.model.yaml``: axis ``pair``, the instrument id of the recording
rig's config (``configs/recording-kaist.yaml``, ``instrument.id``), the chosen model's structure and effects with
the values the diagnosis fitted (:func:`estimator.offline.pair.diagnosis.diagnose_pair`: its own fit and choice,
the ``/T`` refit with the measured tensions included, nothing refitted here), each parameter with its unit and
the range of the pair catalogue (:mod:`estimator.offline.pair.models`), the per-cycle form
(:class:`estimator.online.pair_model.PairModelEstimator`), the held-out gain (base: the seed pair model, extended:
the chosen one; distal-angle RMSE on the test cycles [deg]) and the provenance (the recording's file name and
SHA-256, the span fitted on [s], the project's version).
"""
from __future__ import annotations

import datetime as _dt
from pathlib import Path

from estimator.offline.pair.models import STRUCTURES, model_params
from estimator.online.pair_model import PER_CYCLE
from recorded.kaist import KaistRecording
from teleop.config.files import shipped_config
from teleop.config.load import load_config
from teleop.config.model_file import (
    ModelExtension,
    ModelFile,
    ModelParameter,
    check_runnable,
    file_sha256,
    project_version,
    save_model,
)
from teleop.errors import ConfigError

__all__ = ["KAIST_CONFIG", "kaist_model", "write_kaist_models"]

#: The recording rig's config of the KAIST recordings: its ``instrument.id`` names the instrument of the model files.
KAIST_CONFIG = "recording-kaist.yaml"


def kaist_model(rec: KaistRecording, summary: dict, fit, instrument: str) -> ModelFile:
    """The model file of one configuration (module docstring), not yet written.

    Parameters
    ----------
    rec : the recording
    summary : its entry of ``analyze_kaist``'s ``configurations`` (``diagnosis``, ``cycle1``)
    fit : the chosen model's :class:`estimator.offline.pair.diagnosis_fit.FitResult`
    instrument : the instrument id
    """
    d = summary["diagnosis"]
    units = {p.name: p for p in model_params(fit.structure, fit.effects)}

    def params(names) -> tuple[ModelParameter, ...]:
        return tuple(ModelParameter(n, float(fit.values[n]), units[n].unit, units[n].lo, units[n].hi) for n in names)

    base = {p.name: float(fit.values[p.name]) for p in STRUCTURES[fit.structure]}
    exts = tuple(ModelExtension(e, params(p.name for p in model_params(fit.structure, (e,))[len(base):]))
                 for e in fit.effects)
    how = "; ".join(f"{e}: {PER_CYCLE[e][1]}" for e in ("capstan_joint", *fit.effects) if e in PER_CYCLE)
    fitted = ("fitted on the angle and the measured proximal tensions (weight "
              f"{fit.tension_weight:g} rad/N)" if fit.tension_weight > 0 else "fitted on the angle")
    model = ModelFile(
        axis="pair", instrument=instrument, structure=fit.structure, base=base, extensions=exts,
        per_cycle=f"estimator.online.pair_model.PairModelEstimator {d['extended']['model']} ({fitted}), driven by "
                  f"the measured motor position: {how}",
        base_ranges={n: (units[n].unit, units[n].lo, units[n].hi) for n in base},
        gain={"base": float(d["seed"]["rmse_test_deg"]), "extended": float(d["extended"]["rmse_test_deg"]),
              "unit": "deg"},
        provenance={"recording": Path(rec.source).name, "sha256": file_sha256(rec.source),
                    "span_s": [float(x) for x in summary["cycle1"]], "project_version": project_version(),
                    "written": _dt.datetime.now(_dt.UTC).date().isoformat()})
    check_runnable(model, {e: None if has else why for e, (has, why) in PER_CYCLE.items()})
    return model


def write_kaist_models(recs: list[KaistRecording], summary: dict, details: list[dict],
                       out_dir: str | Path) -> list[Path]:
    """Write ``<out_dir>/<recording stem>.model.yaml`` for every recording (``summary``, ``details``: what
    :func:`study.analyze.analyze_kaist` returned); returns the paths written.

    Raises
    ------
    ConfigError
        ``out_dir`` cannot be made, or a model that would not read back (:func:`teleop.config.model_file.save_model`).
    """
    instrument = load_config(shipped_config(KAIST_CONFIG)).instrument.id
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise ConfigError(f"--model-out {out_dir}: exists and is not a directory")
    paths = []
    for rec, s, d in zip(recs, summary["configurations"], details, strict=True):
        model = kaist_model(rec, s, d["pair_fits"][d["extended"]], instrument)
        paths.append(save_model(model, out / f"{Path(rec.source).stem}.model.yaml"))
    return paths
