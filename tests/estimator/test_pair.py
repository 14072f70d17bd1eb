"""Antagonistic-pair angle model: parameter recovery on self-generated data, baselines, dead zones."""
import math

import numpy as np
import pytest

from estimator.offline.pair.fit import (
    PairParams,
    distal_tension,
    fit_force_path,
    fit_linear,
    fit_pair,
    fit_play_map,
    mean_tension,
    play,
    predict_angle,
    reversal_dead_zones,
    rmse,
)

TRUE = PairParams(G=1.1, K_a=0.4, K_b=0.8, lam_a=0.10, lam_b=0.07, theta0=0.02)


def signals(n_cycles=2.05, rate_hz=40.0):
    """KAIST-like: 2 sine cycles of the command (period 2 pi s) with tension minor loops."""
    t = np.arange(0.0, n_cycles * 2 * math.pi, 1.0 / rate_hz)
    command = math.radians(60) * np.sin(t)
    T_a = 5 + 3 * np.sin(t) + 1.0 * np.sin(3.3 * t)
    T_b = 5 - 3 * np.sin(t) + 0.8 * np.sin(2.1 * t + 1.0)
    n_train = int(np.searchsorted(t, 2 * math.pi))
    return t, command, T_a, T_b, n_train


def test_mean_tension_without_friction_is_the_tension_change():
    T = np.array([5.0, 6.0, 3.0, 7.5])
    np.testing.assert_allclose(mean_tension(T, 0.0), T - 5.0, atol=1e-12)
    # K = 1, pull 5 -> 6 N: T(s) = max(5, 6 e^{-s K}), mean - 5 = 6 (1 - 5/6) - 5 ln(6/5)
    E = mean_tension(T, 1.0, n_nodes=400)
    assert E[0] == pytest.approx(0.0, abs=1e-12)
    assert E[1] == pytest.approx(1.0 - 5.0 * math.log(1.2), rel=1e-3)


def test_seed_pair_fit_recovers_parameters_and_predicts_second_cycle():
    t, c, Ta, Tb, n_train = signals()
    y = predict_angle(TRUE, c, Ta, Tb)
    fit = fit_pair(c, Ta, Tb, y, n_train)
    for name, value in TRUE.as_dict().items():
        assert fit.params[name] == pytest.approx(value, rel=0.02, abs=1e-4), name
    assert rmse(fit.prediction[n_train:] - y[n_train:]) < math.radians(0.01)


def test_seed_pair_fit_with_noise_stays_close():
    t, c, Ta, Tb, n_train = signals()
    y = predict_angle(TRUE, c, Ta, Tb) + np.random.default_rng(0).normal(0, math.radians(0.2), t.size)
    fit = fit_pair(c, Ta, Tb, y, n_train)
    assert fit.params["G"] == pytest.approx(TRUE.G, rel=0.05)
    assert rmse(fit.prediction[n_train:] - y[n_train:]) < math.radians(0.25)   # noise level


def test_linear_map_is_exact_on_linear_data_and_bad_on_the_pair():
    t, c, Ta, Tb, n_train = signals()
    lin = fit_linear(c, 0.7 * c - 0.01, n_train)
    assert lin.params == pytest.approx({"a": 0.7, "b": -0.01})
    y = predict_angle(TRUE, c, Ta, Tb)
    assert rmse(fit_linear(c, y, n_train).prediction[n_train:] - y[n_train:]) > math.radians(2)


def test_play_operator_and_its_fit():
    u = np.array([0.0, 1.0, 2.0, 1.5, 0.5, -1.0, 0.0])
    np.testing.assert_allclose(play(u, 0.5), [0.0, 0.5, 1.5, 1.5, 1.0, -0.5, -0.5])
    t, c, _, _, n_train = signals()
    y = play(0.8 * c + 0.01, 0.3)
    fit = fit_play_map(c, y, n_train)
    assert fit.params["a"] == pytest.approx(0.8, rel=0.02)
    assert fit.params["w"] == pytest.approx(0.3, rel=0.02)
    assert rmse(fit.prediction[n_train:] - y[n_train:]) < 1e-3


def test_dead_zones_of_a_backlash_are_its_width():
    t, c, Ta, Tb, _ = signals()
    a, w = 0.8, 0.3
    y = play(a * c, w)
    zones = reversal_dead_zones(c, y, Ta, Tb, threshold=1e-3)
    assert len(zones) == 4                          # two maxima, two minima of the command
    for z in zones[:-1]:
        assert z.command_travel == pytest.approx(2 * w / a, abs=0.03)   # 40 Hz sampling
    top = zones[0]                                  # at a maximum: A released, B pulled
    k = top.index + int(np.argmax(np.abs(y[top.index:] - y[top.index]) > 1e-3))
    assert top.K_release == pytest.approx(0.5 * math.log(Ta[top.index] / Ta[k]))
    assert top.K_pull == pytest.approx(0.5 * math.log(Tb[k] / Tb[top.index]))


def test_dead_zones_with_a_tension_read_at_or_below_zero_have_no_capstan_ratio():
    """A load cell with an offset reads a released tendon below zero (the long KAIST recordings): the
    dead zone is still measured, its log ratio is nan instead of a math domain error."""
    t, c, Ta, Tb, _ = signals()
    y = play(0.8 * c, 0.3)
    zones = reversal_dead_zones(c, y, Ta - Ta.max(), Tb, threshold=1e-3)    # A never positive
    assert len(zones) == 4 and all(math.isfinite(z.command_travel) for z in zones[:-1])
    assert all(math.isnan(z.K_release) for z in zones if c[z.index] > 0)  # A released at a maximum
    assert all(math.isnan(z.K_pull) for z in zones if c[z.index] < 0)     # A pulled at a minimum
    assert all(math.isfinite(z.K_pull) for z in zones[:-1] if c[z.index] > 0)


def test_fit_pair_rejects_bad_input():
    with pytest.raises(ValueError, match="equal length"):
        fit_pair(np.zeros(10), np.zeros(10), np.zeros(9), np.zeros(10), 8)
    with pytest.raises(ValueError, match="n_train"):
        fit_pair(np.zeros(10), np.ones(10), np.ones(10), np.zeros(10), 4)


def test_force_path_fit_recovers_K_and_beta():
    t, c, Ta, Tb, n_train = signals()
    K, beta, th0 = 0.6, 0.12, -0.03
    y = beta * (distal_tension(Ta, K) - distal_tension(Tb, K)) + th0
    fit = fit_force_path(Ta, Tb, y, n_train)
    assert fit.params == pytest.approx({"K": K, "beta": beta, "theta0": th0}, rel=0.02)
    assert rmse(fit.prediction[n_train:] - y[n_train:]) < math.radians(0.01)
    # the distal tension holds after a reversal until T_in has crossed the 2K band (Phee eq. (14))
    T = np.array([1.0, 8.0, 7.0, 8.0 * math.exp(-2 * K) + 0.01, 8.0 * math.exp(-2 * K) - 0.2])
    T_out = distal_tension(T, K, n_nodes=200)
    assert T_out[1] == pytest.approx(8.0 * math.exp(-K))
    assert T_out[2] == T_out[3] == T_out[1]
    assert T_out[4] == pytest.approx((8.0 * math.exp(-2 * K) - 0.2) * math.exp(K))
