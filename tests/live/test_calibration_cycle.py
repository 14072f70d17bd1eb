"""The calibration life cycle of every instrument, as `teleop slave` runs it: reload the file when it is
there, calibrate at power-up (None) when it is missing or on --recalibrate, refuse another kind's file."""
from __future__ import annotations

import dataclasses

import pytest

from estimator.errors import CalibrationError
from live.sides import load_or_recalibrate
from slave.calibration_file import InstrumentCalibration, TendonCalibration, save_calibration
from teleop.config.schema import Config, InstrumentConfig

TENDON = TendonCalibration(K=0.6, M_e=8e-5, compliance=1e-4, knee_x_in=0.006, knee_T_in=4.0, residual_rms=3e-7,
                           n_samples=1500)


def _cfg(tmp_path, ident="cyc1") -> Config:
    c = Config()
    return dataclasses.replace(c, instrument=InstrumentConfig(id=ident),
                               calibration=dataclasses.replace(c.calibration, dir=str(tmp_path / "calibration")))


def test_missing_file_means_calibrate_then_save_there(tmp_path):
    cfg = _cfg(tmp_path)
    cal, path = load_or_recalibrate(cfg, recalibrate=False)
    assert cal is None and path == tmp_path / "calibration" / "cyc1.yaml" and not path.exists()


def test_a_saved_single_tendon_calibration_is_reloaded_unless_recalibrating(tmp_path):
    cfg = _cfg(tmp_path)
    data = InstrumentCalibration(instrument="cyc1", date="2026-01-01T00:00:00+00:00", target_tension=20.0,
                                 use_route=True, tendon=TENDON)
    save_calibration(data, tmp_path / "calibration" / "cyc1.yaml")
    cal, _ = load_or_recalibrate(cfg, recalibrate=False)
    assert cal is not None and cal.tendon == TENDON and cal.joints == ()
    again, path = load_or_recalibrate(cfg, recalibrate=True)
    assert again is None and path.exists()                  # the file stays until the new fit replaces it


def test_a_file_of_another_instrument_or_kind_is_refused_naming_it(tmp_path):
    cfg = _cfg(tmp_path)
    path = tmp_path / "calibration" / "cyc1.yaml"
    path.parent.mkdir()
    path.write_text("instrument: cyc1\ndate: 2026-01-01T00:00:00+00:00\nmethod: x\ntarget_tension: 20.0\n"
                    "use_route: true\njoints: []\n")
    with pytest.raises(CalibrationError, match=r"cyc1.yaml: joints: this is the calibration of a joint instrument"):
        load_or_recalibrate(cfg, recalibrate=False)
