"""A prediction wanted on the first samples only (``predict(..., stop=k)``) is the same as the whole prediction there.

The model runs forward in time; the few steps that read later samples (undoing a lag, the slack rule's held
tension, the distal speed) are covered by :func:`estimator.offline.effects.predict.lookahead`, and the per-node
pre-sliding estimates L/EA on the whole series either way. The diagnosis's forward fold relies on it: its fits run
the model no further than their fit block needs, and their answers must not change.
"""
import numpy as np
import pytest

from estimator.offline.diagnosis.fit import prepare
from estimator.offline.effects.catalogue import PRESLIDING_MIN, SPEED_FORM, STRIBECK_FORM, predict
from estimator.offline.effects.presliding_kernel import NODE_FORM
from study.lumped import scenarios as lumped_scenarios

#: effect ids and values, each a different part of the model: the kernel's knobs, every lag (the steps that read
#: later samples), the per-node pre-sliding with its L/EA estimated on the whole series, the backlash's L/EA refits
MODELS = [
    ([], {"K": 0.7}),
    (["velocity_friction"], {"K": 0.7, "c_v": 20.0, SPEED_FORM: 1.0}),
    (["stiction"], {"K": 0.7, "r_s": 0.3, STRIBECK_FORM: 1.0}),
    (["pretension", "tendon_stiffening"], {"K": 0.7, "T0": 1.0, "beta": 2.0, "T_c": 1.0}),
    (["sensor_lag:T_in", "sensor_lag:x_in", "sensor_lag:x_out", "sensor_lag:T_out"],
     {"K": 0.7, "tau_T_in": 0.2, "tau_x_in": 0.15, "tau_x_out": 0.2, "tau_T_out": 0.05}),
    (["presliding"], {"K": 0.7, "x_p": 3 * PRESLIDING_MIN, NODE_FORM: 1.0}),
    (["presliding"], {"K": 0.7, "x_p": 3 * PRESLIDING_MIN, NODE_FORM: 0.0}),
    (["distal_backlash", "sensor_offset:x_out"], {"K": 0.7, "d_b": 1e-4, "b_x_out": 2e-5}),
]


@pytest.fixture(scope="module")
def series():
    rec = lumped_scenarios.record(None, seed=501, duration=20.0, rate_hz=200.0)
    return prepare(rec.data)


@pytest.mark.parametrize("effects, values", MODELS, ids=["+".join(m[0]) or "base" for m in MODELS])
def test_a_prediction_cut_at_stop_equals_the_whole_one_there(series, effects, values):
    for stop in range(200, len(series) - 50, 37):       # stops in holds, moves and reversals
        mask = slice(0, stop)
        whole = predict(effects, values, series, fit_mask=mask)
        cut = predict(effects, values, series, fit_mask=mask, stop=stop)
        assert cut.T_out.shape == cut.x_out.shape == (stop,)
        assert cut.compliance == whole.compliance, stop
        np.testing.assert_array_equal(cut.T_out, whole.T_out[:stop], err_msg=f"stop {stop}")
        np.testing.assert_array_equal(cut.x_out, whole.x_out[:stop], err_msg=f"stop {stop}")


def test_the_series_is_cut_short_of_its_end_only_by_what_the_lags_read(series):
    from estimator.offline.effects.predict import SLACK_HELD, lookahead

    n, stop = len(series), len(series) // 2
    dt = float(series.time[1] - series.time[0])
    plain = lookahead(series, {}, stop)
    lagged = lookahead(series, {"sensor_lag:T_in": 0.2}, stop)
    assert stop + SLACK_HELD <= plain < stop + SLACK_HELD + 5
    assert lagged - plain == pytest.approx(0.2 / dt, abs=2)
    assert lookahead(series, {}, n - 3) == n
