"""Both-direction joint-limit calibration of the 3-joint instrument, the calibration file and its checks."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from estimator.errors import CalibrationError
from slave.calibration_file import (
    calibration_path,
    from_results,
    load_calibration,
    save_calibration,
    sheath_models,
    user_calibration_dir,
)
from slave.pair_calibrate import PairCalibration
from slave.pair_rig import SimulatedInstrument
from teleop.config.load import config_from_dict, load_config

CONFIG = Path(__file__).resolve().parents[2] / "configs" / "instrument-3dof.yaml"
DT = 1e-3


def run(cfg, inst=None, max_steps=30000):
    inst = inst or SimulatedInstrument.from_config(cfg)
    cal = PairCalibration(cfg, inst)
    st = inst.state
    for _ in range(max_steps):
        if cal.done:
            break
        st = inst.step(cal.command(st, DT), DT)
    return cal, inst


@pytest.fixture(scope="module")
def calibrated():
    cfg = load_config(CONFIG)
    cal, inst = run(cfg)
    return cfg, cal, inst


def test_recovers_K_and_M_e_of_every_tendon_within_5_percent(calibrated):
    cfg, cal, inst = calibrated
    assert cal.done and len(cal.results) == 3
    for i, res in enumerate(cal.results):
        for k, t in enumerate("ab"):
            r = res[t]
            assert r.K == pytest.approx(inst.K[i, k], rel=0.05), (cfg.instrument.joints[i].name, t)
            assert r.M_e == pytest.approx(inst.M_e[i, k], rel=0.05), (cfg.instrument.joints[i].name, t)
            assert r.n_samples > 100 and r.residual_rms < 1e-5
    # the tendons of a pair differ, and the fit tells them apart
    assert abs(cal.results[1]["a"].K - cal.results[1]["b"].K) > 0.03


def test_routine_ends_at_rest_with_the_tissue_back_and_both_tendons_loose(calibrated):
    cfg, cal, inst = calibrated
    tr = inst.state.truth
    assert inst.tissue == (True, True, True)
    assert np.abs(tr.theta).max() < 0.05
    assert np.all((tr.T_in > 0.1) & (tr.T_in < 0.5))
    t, x, T = cal.history[-1]
    assert len(cal.history) > 3000 and T.shape == (3, 2)


def test_file_round_trip_and_models(calibrated, tmp_path):
    cfg, cal, inst = calibrated
    data = from_results(cfg, cal.results, date="2026-01-02T03:04:05+00:00")
    path = save_calibration(data, tmp_path / "cal" / "flex3.yaml")
    raw = yaml.safe_load(path.read_text())
    assert raw["instrument"] == "flex3" and raw["date"] == "2026-01-02T03:04:05+00:00"
    assert [j["name"] for j in raw["joints"]] == ["bend_ud", "bend_lr", "grasp"]
    assert set(raw["joints"][0]["a"]) == {"K", "M_e", "compliance", "knee_x_in", "knee_T_in", "residual_rms",
                                          "n_samples", "tension_noise"}
    back = load_calibration(path, cfg)
    assert back == data
    models = sheath_models(back, cfg)
    assert models[2][1].K == cal.results[2]["b"].K and models[2][1].wrap_shape is not None
    assert calibration_path(cfg).parent == user_calibration_dir()     # the shipped config names no calibration.dir


def _write(tmp_path, calibrated, edit):
    cfg, cal, _ = calibrated
    raw = from_results(cfg, cal.results).as_dict()
    edit(raw)
    p = tmp_path / "bad.yaml"
    p.write_text(yaml.safe_dump(raw))
    return p, cfg


@pytest.mark.parametrize("edit, match", [
    (lambda d: d.update(instrument="other"), r"instrument is 'other'.*another instrument"),
    (lambda d: d["joints"].pop(), r"joints: expected the config's joints \['bend_ud', 'bend_lr', 'grasp'\]"),
    (lambda d: d["joints"][1]["a"].update(M_e=-1.0), r"joints\[1\].a \(bend_lr\).M_e: expected a finite number > 0"),
    (lambda d: d["joints"][0]["b"].pop("K"), r"joints\[0\].b \(bend_ud\).K"),
    (lambda d: d["joints"][2]["b"].update(n_samples=1.5), r"joints\[2\].b \(grasp\).n_samples: expected an integer"),
    (lambda d: d.update(date="yesterday"), r"date: 'yesterday' is not an ISO 8601 date"),
    (lambda d: d.update(extra=1), r"unknown key 'extra'"),
    (lambda d: d.pop("use_route"), r"missing key 'use_route'"),
])
def test_malformed_or_foreign_files_are_rejected_naming_file_and_key(tmp_path, calibrated, edit, match):
    p, cfg = _write(tmp_path, calibrated, edit)
    with pytest.raises(CalibrationError, match=match) as e:
        load_calibration(p, cfg)
    assert str(p) in str(e.value)


def test_missing_and_broken_files(tmp_path, calibrated):
    cfg = calibrated[0]
    with pytest.raises(CalibrationError, match="not found.*teleop calibrate"):
        load_calibration(tmp_path / "none.yaml", cfg)
    (tmp_path / "x.yaml").write_text("joints: [\n")
    with pytest.raises(CalibrationError, match="YAML syntax error"):
        load_calibration(tmp_path / "x.yaml", cfg)


def test_no_joint_limit_within_the_travel_is_an_error_naming_joint_and_tendon():
    cfg = config_from_dict({"instrument": {"joints": [{"name": "wrist", "limits": [-1.2, 9.0]}]},
                            "rig": {"simulated": {"n_elements": 40, "joints": [{"name": "wrist", "stiffness": 0.0}]}},
                            "calibration": {"speed": 0.02}})
    with pytest.raises(CalibrationError, match=r"joint 'wrist', tendon a: pulled 30 mm without reaching"):
        run(cfg)
