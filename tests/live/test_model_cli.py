"""Model files on the command line: ``teleop analyze --model-out`` writes files that load and that the slave's check
passes; ``teleop slave --model`` refuses, in one line with exit status 2 and before anything starts, a model for
another axis kind or instrument, an unknown version, a parameter outside its range and a model the per-cycle
estimator cannot run (with the reason). No data needed: the KAIST run is tests/slave/test_recording_model.py."""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from estimator.offline.pair.diagnosis_fit import FitResult
from live.cli import main
from slave.estimator_model import configured_model, with_model
from study.kaist.model_file import kaist_model
from teleop.config.load import load_config
from teleop.config.model_file import ModelExtension, ModelFile, ModelParameter, load_model, save_model

ROOT = Path(__file__).resolve().parents[2]
KAIST_CONFIG = ROOT / "configs" / "recording-kaist.yaml"
CAPSTAN = {"G": 1.4, "lam": 0.4, "K_a": 0.9, "K_b": 0.5, "k": 4.0, "theta0": 0.01}
CAPSTAN_RANGES = {"G": ("-", 0.0, 20.0), "lam": ("rad/N", 1e-4, 10.0), "K_a": ("-", 0.0, 4.0),
                  "K_b": ("-", 0.0, 4.0), "k": ("N/rad", 1e-3, 1e3), "theta0": ("rad", -1.0, 1.0)}


def pair_model(**kw) -> ModelFile:
    """A capstan model with a joint play for the KAIST instrument (configs/recording-kaist.yaml)."""
    m = dict(axis="pair", instrument="kaist-bend", structure="capstan", base=dict(CAPSTAN), base_ranges=CAPSTAN_RANGES,
             extensions=(ModelExtension("joint_backlash", (ModelParameter("b", 0.05, "rad", 0.0, 0.6),)),),
             per_cycle="estimator.online.pair_model.PairModelEstimator capstan+joint_backlash",
             gain={"base": 3.0, "extended": 1.0, "unit": "deg"},
             provenance={"recording": "sine_config_0.txt", "sha256": "ab" * 32, "span_s": [0.0, 6.3],
                         "project_version": "0.0.0", "written": "2026-11-27"})
    m.update(kw)
    return ModelFile(**m)


def slave(tmp_path: Path, model: Path, capsys) -> tuple[int, str]:
    code = main(["slave", "--config", str(KAIST_CONFIG), "--model", str(model), "--run-dir", str(tmp_path / "run"),
                 "--max-duration", "1"])
    return code, capsys.readouterr().err.strip()


@pytest.mark.parametrize("change, message", [
    (dict(axis="spindle", structure="spindle"), "the model is for a spindle axis, the configured instrument is a pair"),
    (dict(instrument="maryland-left"), "the model is for 'maryland-left', the configured instrument is 'kaist-bend'"),
    (dict(extensions=(ModelExtension("joint_backlash", (ModelParameter("b", 0.9, "rad", 0.0, 1.0),)),)),
     r"extensions[0].parameters.b: 0.9 rad is outside the catalogue's range [0, 0.6]"),
    (dict(base_ranges={}, base={**CAPSTAN, "G": 25.0}), "base.G: 25 - is outside the catalogue's range [0, 20]"),
    (dict(extensions=(ModelExtension("sensor_delay", (ModelParameter("tau", -0.02, "s", -0.2, 0.2),)),)),
     "the per-cycle estimator refuses this model: sensor_delay: tau = -0.02 s; a negative delay reads the angle of a "
     "later sample (the future)"),
    (dict(extensions=(ModelExtension("wobble", (ModelParameter("w", 0.1, "-", 0.0, 1.0),)),)),
     "extensions[0].id: 'wobble' is no pair catalogue entry"),
])
def test_the_slave_refuses_a_model_it_cannot_run_in_one_line(tmp_path, capsys, change, message):
    path = save_model(pair_model(**change), tmp_path / "m.model.yaml")
    code, err = slave(tmp_path, path, capsys)
    assert code == 2 and "\n" not in err and err.startswith("teleop: error: ") and str(path) in err
    assert message in err
    assert not (tmp_path / "run").exists()          # refused before the run directory or any session


def test_an_unknown_version_is_refused_before_anything_starts(tmp_path, capsys):
    path = save_model(pair_model(), tmp_path / "m.model.yaml")
    path.write_text(path.read_text().replace("version: 1", "version: 7"))
    code, err = slave(tmp_path, path, capsys)
    assert code == 2 and "\n" not in err and "version: model file version 7 is unknown to this program" in err


def test_a_missing_model_file_is_one_line(tmp_path, capsys):
    code, err = slave(tmp_path, tmp_path / "none.model.yaml", capsys)
    assert code == 2 and "\n" not in err and "none.model.yaml" in err


@pytest.mark.parametrize("extra, message", [
    (["--model-out", "{tmp}"], "the single-tendon model is one file (OUT.yaml) in an existing folder"),
    (["--model-out", "{tmp}/m.yaml", "--route", "{csv}"], "with --route the model runs on the held route's shape"),
    (["--model-out", "{tmp}/m.yaml", "--instrument", "x/y"], "'x/y' is not a valid instrument id"),
    (["--instrument", "tsm0"], "--instrument tsm0: names the instrument of a single-tendon model file"),
])
def test_model_out_for_a_single_tendon_csv_is_checked_before_the_diagnosis(tmp_path, capsys, extra, message):
    csv = tmp_path / "r.csv"
    csv.write_text("time,x_in,T_in,T_out\n0,0,1,1\n0.001,0,1,1\n")     # too short to diagnose: refused before
    assert main(["analyze", str(csv), *(a.format(tmp=tmp_path, csv=csv) for a in extra)]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and message in err


class Rec:
    """A short synthetic recording of the KAIST layout (time, command, T_a, T_b, angle [rad, N, s])."""

    def __init__(self, source: Path):
        self.time = np.arange(400) * 0.025
        self.command = math.radians(60.0) * np.sin(self.time)
        self.T_a = 5.0 + 2.0 * np.maximum(np.sin(self.time), 0.0)
        self.T_b = 5.0 + 2.0 * np.maximum(-np.sin(self.time), 0.0)
        self.angle = 0.9 * self.command
        self.source = str(source)


def test_model_out_writes_the_chosen_fit_as_a_file_that_loads_and_passes_the_check(tmp_path):
    src = tmp_path / "sine_config_60.txt"
    src.write_text("a recording\n")
    rec = Rec(src)
    train, test = slice(0, 250), slice(250, 400)
    fit = FitResult("capstan", ("series_compliance",), {**CAPSTAN, "lam_s": 0.1}, rec, train, test, tension_weight=0.01)
    summary = {"cycle1": [0.0, 6.25], "diagnosis": {"seed": {"rmse_test_deg": 3.1},
                                                    "extended": {"model": fit.id, "rmse_test_deg": 0.9}}}
    path = save_model(kaist_model(rec, summary, fit, "kaist-bend"), tmp_path / "out" / f"{src.stem}.model.yaml")
    m = load_model(path)
    assert m.model_id == "kaist-bend/pair/capstan+series_compliance"
    assert m.values() == {**CAPSTAN, "lam_s": 0.1}
    assert m.base_ranges["k"] == ("N/rad", 1e-3, 1e3)
    assert m.extensions[0].parameters[0].unit == "rad/N"
    assert m.gain == {"base": 3.1, "extended": 0.9, "unit": "deg"}
    assert m.provenance["recording"] == "sine_config_60.txt" and m.provenance["span_s"] == [0.0, 6.25]
    assert len(m.provenance["sha256"]) == 64 and "measured proximal tensions" in m.per_cycle
    cfg = with_model(load_config(KAIST_CONFIG), str(path))
    checked = configured_model(cfg)
    assert checked is not None and checked.sha256 == m.sha256
    assert configured_model(dataclasses.replace(cfg, estimator=dataclasses.replace(cfg.estimator, model=None))) is None
