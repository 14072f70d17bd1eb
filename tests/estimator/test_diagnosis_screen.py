"""The screen of a second cause before its fit: the residual the fits minimise, and the linearised share of it that a
partner removes beside the first model (estimator.offline.diagnosis.screen)."""
from __future__ import annotations

import numpy as np

from estimator.offline.diagnosis import thresholds as th
from estimator.offline.diagnosis.fit import fit_model, fit_residual
from estimator.offline.diagnosis.screen import Linearised
from estimator.offline.effects.catalogue import effect, predict
from estimator.offline.effects.types import Series
from tests.estimator.effects_series import K, series


def _recording(hidden: list[str], values: dict[str, float]) -> Series:
    """30 s at 200 Hz of pulls at two speeds, its distal channels made by the model with ``hidden`` effects."""
    t = np.arange(0.0, 30.0, 0.005)
    x_in = 2e-3 * np.sin(2 * np.pi * t / 4.0) ** 2 + 1e-3 * np.sin(2 * np.pi * t / 1.5) ** 2
    s = series(1.0 + 4e3 * x_in, x_in, dt=0.005)
    truth = predict(hidden, {"K": K, **values}, s, compliance=1e-4)
    return Series(s.time, s.x_in, s.T_in, s.velocity, truth.T_out, truth.x_out, s.u, s.w)


def test_the_residual_is_the_one_the_fit_minimises():
    s = _recording(["sensor_offset:T_out"], {"b_T_out": 0.4})
    mask = slice(0, 4000)
    first = [effect("sensor_offset:T_out")]
    vals, _, cost = fit_model(first, s, [{"K": 0.5, "b_T_out": 0.0}], mask=mask)
    r = fit_residual(first, vals, s, mask)
    assert r.shape == (2 * len(range(0, 4000, 3)),)          # both distal signals, every third sample
    assert abs(0.5 * float(r @ r) - cost) <= 1e-9 * max(cost, 1e-12)


def test_a_partner_the_residual_holds_is_fitted_and_one_it_does_not_is_skipped():
    # velocity friction beside a distal load-cell offset: the offset alone leaves the speed-dependent loop, which
    # velocity friction removes and a drift of K or a distal lag does not
    s = _recording(["sensor_offset:T_out", "velocity_friction"], {"b_T_out": 0.4, "c_v": 25.0})
    mask = slice(0, 4000)
    first = [effect("sensor_offset:T_out")]
    vals, _, _ = fit_model(first, s, [{"K": 0.5, "b_T_out": 0.0}], mask=mask)
    lin = Linearised(first, vals, s, mask)
    assert 0.0 <= lin.left <= lin.cost
    held = {"velocity_form": 0.0}
    rho = lin.share(effect("velocity_friction"), held)
    assert rho is not None and rho > th.PENALTY                  # removes more than its price
    assert not lin.skips(effect("velocity_friction"), held)
    for absent in ("curvature_drift", "sensor_offset:x_out"):
        share = lin.share(effect(absent), {})
        assert share is not None and share < rho / 10, absent
    assert lin.skips(effect("sensor_offset:x_out"), {})
    # a step's instant is not linearised: it is always fitted
    assert lin.share(effect("friction_step"), {}) is None and not lin.skips(effect("friction_step"), {})
