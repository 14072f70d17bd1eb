"""The verdict and the rate the model is chosen at. ``unknown`` comes first only when the catalogue missed most of
the structure, after the named effects when they leave some. A long recording is chosen on a series averaged
further (above SELECTION_SAMPLES, not below SELECTION_RATE_MIN) and the chosen model refitted and tested at the
full rate: the same cause, both rates in the settings.

The verdict is checked on stand-ins for fitted models, the selection rate on rig recordings of 45 s at 500 Hz; seeds
are development seeds (the benchmark's final seeds are never used in tests).
"""

import numpy as np
import pytest

from estimator.offline.diagnosis import selection
from estimator.offline.diagnosis import thresholds as th
from estimator.offline.diagnosis.fit import (
    predictions,
)
from estimator.offline.diagnosis.selection import diagnose
from study.scenarios import record
from tests.estimator.diagnosis_support import DUR, RATE, _StubFit, check_named


def test_the_verdict_puts_unknown_first_only_when_the_catalogue_missed_most_of_the_structure():
    from estimator.offline.diagnosis.rules import verdict
    r = th.STRUCTURE_RATIO
    side = _StubFit(("sensor_offset:T_in",), S=0.5)
    # more than twice the threshold left after an effect that explains only part of it: unknown first
    assert verdict(["sensor_offset:T_in"], {"T_out": 2.5 * r}, side, False) == ["unknown", "sensor_offset:T_in"]
    # ... unless it removed nearly all of the base's excess, or a model-free reading named it
    cause = _StubFit(("sensor_offset:T_in",), S=0.5 * th.DOMINANT_SCORE)
    assert verdict(["sensor_offset:T_in"], {"T_out": 2.5 * r}, cause, False) == ["sensor_offset:T_in", "unknown"]
    assert verdict(["sensor_offset:T_in"], {"T_out": 2.5 * r}, side, True) == ["sensor_offset:T_in", "unknown"]
    # structure between the threshold and twice it: unknown after; none left: the effect alone; nothing: none
    assert verdict(["sensor_offset:T_in"], {"T_out": 1.5 * r}, side, False) == ["sensor_offset:T_in", "unknown"]
    assert verdict(["sensor_offset:T_in"], {"T_out": 0.5 * r}, side, False) == ["sensor_offset:T_in"]
    assert verdict([], {"T_out": 0.5 * r}, _StubFit(()), False) == []


def test_a_long_recording_is_chosen_on_a_coarser_series_and_judged_at_the_full_rate(monkeypatch, clean_result):
    """Above SELECTION_SAMPLES the model choice runs on a series averaged further (not below SELECTION_RATE_MIN);
    the chosen model is refitted and tested at the full rate: the cause is the same, the settings say both rates."""
    _, clean = clean_result
    assert clean["settings"]["selection_rate_hz"] == pytest.approx(250.0, rel=1e-3)    # 500 Hz in pairs: below it
    rec = record("velocity_friction", seed=11, duration=DUR, rate_hz=RATE)
    monkeypatch.setattr(selection, "SELECTION_SAMPLES", 3000)        # 45 s at 250 Hz: 11250 samples
    res = diagnose(rec.data)
    assert res["settings"]["selection_rate_hz"] == pytest.approx(100.0, rel=1e-3)   # 66.7 Hz raised to the floor
    assert res["settings"]["target_rate_hz"] == 200.0
    check_named("velocity_friction", rec, res)
    pred = predictions(res, rec.data)               # the model re-runs at the rate it was refitted at
    held = rec.data.time >= res["split"]["time_s"]
    rmse = float(np.sqrt(np.mean((pred["T_out_ext"][held] - rec.data.T_out[held]) ** 2)))
    assert rmse == pytest.approx(res["extended"]["rmse_T_out_N"], rel=1e-6)
