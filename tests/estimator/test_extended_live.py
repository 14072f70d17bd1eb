"""The per-cycle form of the extended single-tendon model (estimator/online/extended.py) against the batch model."""
from __future__ import annotations

import math

import numpy as np
import pytest

from estimator.band import NOISE_BAND_SIGMAS
from estimator.offline.effects.catalogue import EFFECT_IDS
from estimator.offline.effects.kernels import backlash_play, run_extended, travel_lag
from estimator.online.distal import smoothed_velocity
from estimator.online.extended import PER_CYCLE, ExtendedEstimator, ExtendedSample
from estimator.sheath import SheathModel

TAU = 0.02
C = 1e-4
SIGMA = 0.02

#: one model per per-cycle form (values in the catalogue's names, SI units)
MODELS = {
    "base": {"K": 0.7},
    "velocity_friction": {"K": 0.7, "c_v": 25.0},
    "pretension": {"K": 0.7, "T0": 2.0},
    "curvature_drift": {"K": 0.7, "K_rate": 0.01},
    "friction_step": {"K": 0.7, "dK": -0.25, "t_s": 3.5},
    "tendon_stiffening": {"K": 0.7, "beta": 2.0, "T_c": 1.5},
    "stiction": {"K": 0.7, "r_s": 0.4},
    "stiction_stribeck": {"K": 0.7, "r_s": 0.4, "v_st": 5e-4},
    "friction_offset": {"K": 0.7, "a": 0.8},
    "presliding": {"K": 0.7, "x_p": 80e-6},
    "distal_backlash": {"K": 0.7, "d_b": 150e-6},
    "sensors": {"K": 0.7, "b_T_in": 0.3, "g_T_in": 0.05, "d_T_in": 0.004, "b_x_in": 30e-6},
    "composed": {"K": 0.6, "c_v": 10.0, "r_s": 0.3, "a": 0.5, "x_p": 60e-6, "d_b": 100e-6, "beta": 1.0, "T0": 1.0},
}


def _series(n: int = 12_000, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """1 kHz proximal readings of pulls, releases, a minor loop and holds, with load-cell noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 1e-3
    x = 2e-3 * (np.sin(2 * np.pi * 0.4 * t) ** 2 + 0.3 * np.sin(2 * np.pi * 1.7 * t) * (t > 5))
    x = np.round(x / 0.47e-6) * 0.47e-6
    T = 1.0 + 6e3 * np.maximum(x, 0.0) + SIGMA * rng.standard_normal(n)
    return t, x, T


def _batch(values: dict, t: np.ndarray, x: np.ndarray, T: np.ndarray, u: np.ndarray, w: np.ndarray) -> tuple:
    """The batch model's outputs on the inputs the per-cycle form runs on (its corrections and velocity)."""
    g = {k: values.get(k, 0.0) for k in ("b_T_in", "g_T_in", "d_T_in", "b_x_in", "x_p", "d_b")}
    T_true = (T - g["b_T_in"]) / (1.0 + g["g_T_in"]) - g["d_T_in"] * (t - t[0])
    x_true = x - g["b_x_in"]
    v = smoothed_velocity(t, x_true, TAU)
    knobs = {k: values[k] for k in ("T0", "c_v", "K_rate", "beta", "r_s", "a", "v_st") if k in values}
    if "dK" in values:
        knobs["K_step"], knobs["t_step"] = values["dK"], values["t_s"]
    if "T_c" in values:
        knobs["Tc"] = values["T_c"]
    T_out, E1 = run_extended(T_true, v, t, u, w, K=values["K"], sigma=SIGMA, T_min=10 * SIGMA,
                             band=NOISE_BAND_SIGMAS * SIGMA, **knobs)
    if g["x_p"] > 0:
        T_out = T_true - travel_lag(T_true - T_out, x_true, g["x_p"])
    x_out = x_true - C * E1
    if g["d_b"] > 0:
        x_out = backlash_play(x_out, g["d_b"])
    return T_out, C * E1, x_out


@pytest.mark.parametrize("name", sorted(MODELS))
def test_per_cycle_is_the_batch_model_to_the_last_bit(name):
    values = MODELS[name]
    u, w = SheathModel(K=1.0, compliance=1.0).nodes(32)
    t, x, T = _series()
    est = ExtendedEstimator(values, u, w, C, tension_noise=SIGMA, rate_time_constant=TAU)
    live = np.array([est.step(T[k], x[k], t[k])[:3] for k in range(t.size)])
    T_out, elong, x_out = _batch(values, t, x, T, u, w)
    assert np.array_equal(live[:, 0], T_out)
    assert np.array_equal(live[:, 1], elong)
    assert np.array_equal(live[:, 2], x_out)
    assert est.steps == t.size
    est.reset()                                   # from rest again: the same first samples
    again = np.array([est.step(T[k], x[k], t[k])[:3] for k in range(200)])
    assert np.array_equal(again, live[:200])


def test_the_effects_change_the_estimate():
    """Each form moves the estimate away from the base model (so the comparison above tests something)."""
    u, w = SheathModel(K=1.0, compliance=1.0).nodes(32)
    t, x, T = _series(6000)
    base = _batch(MODELS["base"], t, x, T, u, w)
    for name, values in MODELS.items():
        if name != "base":
            ext = _batch(values, t, x, T, u, w)
            moved = max(float(np.max(np.abs(ext[0] - base[0]))), float(np.max(np.abs(ext[2] - base[2]))) / C)
            assert moved > 0.05, name


def test_every_catalogue_entry_says_how_it_runs_per_cycle():
    assert set(PER_CYCLE) == set(EFFECT_IDS)
    assert all(isinstance(has, bool) and len(why) > 20 for has, why in PER_CYCLE.values())
    refused = {e for e, (has, _) in PER_CYCLE.items() if not has}
    assert refused == {"sensor_lag:T_in", "sensor_lag:x_in", "sensor_offset:T_out", "sensor_gain:T_out",
                       "sensor_drift:T_out", "sensor_lag:T_out", "sensor_offset:x_out", "sensor_lag:x_out"}


@pytest.mark.parametrize("values, match", [
    ({"K": 0.5, "tau_T_in": 0.02}, "sensor_lag:T_in: undoing the lag"),
    ({"K": 0.5, "b_T_out": 0.1}, "sensor_offset:T_out: a reading model"),
    ({"K": 0.5, "wobble": 1.0}, "it runs K, T0"),
    ({"T0": 1.0}, "K .* required"),
    ({"K": 0.5, "c_v": -1.0}, "c_v must be >= 0"),
    ({"K": math.nan}, "K must be finite"),
])
def test_refusals_name_the_reason(values, match):
    u, w = SheathModel(K=1.0, compliance=1.0).nodes(8)
    with pytest.raises(ValueError, match=match):
        ExtendedEstimator(values, u, w, C)


def test_out_of_range():
    u, w = SheathModel(K=1.0, compliance=1.0).nodes(8)
    est = ExtendedEstimator({"K": 0.5}, u, w, C, tension_noise=0.01)
    assert est.out_of_range(ExtendedSample(5.0, 0.0, 0.0, 0.5, 6.0)) is None
    assert "< 0" in est.out_of_range(ExtendedSample(-0.1, 0.0, 0.0, 0.5, 6.0))
    assert est.out_of_range(ExtendedSample(6.0 * math.exp(0.5), 0.0, 0.0, 0.5, 6.0)) is None   # on the bound
    assert "above T_in e^K" in est.out_of_range(ExtendedSample(6.2 * math.exp(0.5), 0.0, 0.0, 0.5, 6.0))
    assert "non-finite" in est.out_of_range(ExtendedSample(math.nan, 0.0, 0.0, 0.5, 6.0))
    with pytest.raises(ValueError, match="finite"):
        est.step(math.inf, 0.0, 0.0)
