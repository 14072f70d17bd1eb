"""A recorded spindle model written as a model file reads back as the same model: the spindle pair model's
parameters with their ranges, and the centre map when the calibration chose it (no data needed)."""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from estimator.online.spindle import SpindleParams
from estimator.online.spindle_centre import CentreParams
from slave.recording.spindle import CENTRE, RecordedModel
from slave.recording.spindle_model import recorded_model_dict, spindle_model_file
from teleop.config.model_file import load_model, save_model
from teleop.errors import ConfigError

GAIN = {"base": 0.03, "extended": 0.015, "unit": "FS"}


def recorded(tmp_path: Path, centre: bool) -> RecordedModel:
    run = tmp_path / "31.TXT"
    run.write_text("a run\n")
    cmap = CentreParams(np.arange(20.0).reshape(4, 5) / 10.0, 0.1, 0.02, (-0.3, 0.4), (0.05, 0.1), 0.01,
                        (0.2, -0.1), {"shape_range": [[-0.2, 0.3], [-0.25, 0.35]], "degree": 4})
    return RecordedModel(chosen=CENTRE if centre else "pair+k_p", pair_name="pair+k_p",
                         pair=SpindleParams(rho=0.9, Q=0.4, K_a=0.02, K_b=0.015, k_p=0.01, n_k=0.91, lam=0.002),
                         centre_map=cmap, theta_ref=0.05, run=str(run), tool="davinci-maryland-left", band_centre=0.003)


@pytest.mark.parametrize("centre", [True, False])
def test_a_spindle_model_reads_back_as_the_same_model(tmp_path, centre):
    model = recorded(tmp_path, centre)
    path = save_model(spindle_model_file(model, "maryland-left", GAIN, [0.0, 30.0]), tmp_path / "m.model.yaml")
    mf = load_model(path)
    assert mf.axis == "spindle" and mf.instrument == "maryland-left" and mf.gain == GAIN
    assert mf.base_ranges["K_a"] == ("-", 0.0, 3.0) and mf.base_ranges["lam"][0] == "rad/(N m)"
    assert [e.id for e in mf.extensions] == (["centre_map"] if centre else [])
    back = RecordedModel.from_dict(recorded_model_dict(mf, tmp_path, model.tool))
    assert back.pair == model.pair and back.theta_ref == model.theta_ref and back.band_centre == model.band_centre
    assert back.run == model.run and back.tool == model.tool
    if centre:
        assert back.chosen == CENTRE and back.centre_map is not None
        c, d = back.centre_map, model.centre_map
        assert np.array_equal(c.coef, d.coef) and c.window == d.window and c.edge_slope == d.edge_slope
        assert c.notes["shape_range"] == d.notes["shape_range"]
    else:
        assert back.chosen != CENTRE and back.centre_map is None


def test_a_spindle_parameter_outside_the_fit_bounds_is_not_written(tmp_path):
    model = dataclasses.replace(recorded(tmp_path, False), pair=SpindleParams(K_a=3.5))
    with pytest.raises(ConfigError, match=r"base\.K_a\.value: 3.5 - is outside its range \[0, 3\]"):
        save_model(spindle_model_file(model, "maryland-left", GAIN, [0.0, 30.0]), tmp_path / "m.model.yaml")
