"""Sheath geometry and the profile-memory kernels."""
import math

import numpy as np
import pytest

from estimator.geometry import Run, SheathGeometry
from estimator.sheath import SheathModel, profile_batch, profile_update, pull_elongation_factor


def test_total_angle_and_K_from_runs():
    g = SheathGeometry([Run(0.3), Run(0.6, 0.2), (0.4, 0.1)])
    assert g.length == pytest.approx(1.3)
    assert g.total_angle == pytest.approx(0.6 / 0.2 + 0.4 / 0.1)
    m = SheathModel.from_geometry(g, mu=0.12, EA=1.0e4)
    assert m.K == pytest.approx(0.12 * g.total_angle)
    assert m.compliance == pytest.approx(1.3 / 1.0e4)


def test_wrap_angle_is_piecewise_integral_of_curvature():
    g = SheathGeometry([Run(0.5), Run(0.5, 0.25)])
    s = np.linspace(0, 1.0, 1001)
    kappa = g.curvature(s)
    numeric = np.concatenate(([0], np.cumsum(0.5 * (kappa[1:] + kappa[:-1]) * np.diff(s))))
    assert np.allclose(g.wrap_angle(s), numeric, atol=5e-3)
    assert g.wrap_angle(0.5) == pytest.approx(0.0)
    assert g.wrap_angle(1.0) == pytest.approx(2.0)


@pytest.mark.parametrize("bad", [dict(length=-1.0), dict(length=0.0), dict(length=1.0, radius=-0.1),
                                 dict(length=float("nan"))])
def test_bad_runs_raise_naming_the_field(bad):
    with pytest.raises(ValueError, match="length|radius"):
        Run(**bad)


def test_model_rejects_bad_values():
    with pytest.raises(ValueError, match="K"):
        SheathModel(K=-0.1, compliance=1e-4)
    with pytest.raises(ValueError, match="compliance"):
        SheathModel(K=0.1, compliance=0.0)
    with pytest.raises(ValueError, match="EA"):
        SheathModel.from_geometry(SheathGeometry.uniform(1.0, 1.0), mu=0.1, EA=-5.0)


def test_M_e_general_form_matches_constant_curvature_closed_form():
    K, L, EA = 0.7, 1.5, 15000.0
    uniform = SheathModel.from_geometry(SheathGeometry.uniform(L, K / 0.1), 0.1, EA)
    assert uniform.M_e == pytest.approx(L * (1 - math.exp(-K)) / (EA * K), rel=1e-4)
    # a bend concentrated at the distal end leaves more of the tendon at full tension
    distal_bend = SheathModel.from_geometry(SheathGeometry([Run(L - 0.2), Run(0.2, 0.2 / (K / 0.1))]), 0.1, EA)
    assert distal_bend.K == pytest.approx(K)
    assert distal_bend.M_e > uniform.M_e * 1.1
    assert pull_elongation_factor(0.0) == 1.0


def test_reversal_compliance_is_the_elongation_change_across_the_release_band():
    K, L, EA = 0.7, 1.5, 15000.0
    uniform = SheathModel.from_geometry(SheathGeometry.uniform(L, K / 0.1), 0.1, EA)
    assert uniform.reversal_compliance == pytest.approx(uniform.M_e * (1 - math.exp(-K)), rel=1e-4)
    # from the profiles themselves: T0 e^-K(s) before the band, T0 e^-2K e^+K(s) after, distal end held
    T0 = 10.0
    K_s, w = uniform.nodes(400)
    before, after = T0 * np.exp(-K_s), T0 * math.exp(-2 * K) * np.exp(K_s)
    assert after[-1] == pytest.approx(before[-1])                     # the distal tension holds
    assert float(np.sum(w * (before - after))) == pytest.approx(uniform.reversal_compliance * T0, rel=1e-3)
    assert SheathModel(K=0.0, compliance=1e-4).reversal_compliance == 0.0


def test_profile_update_is_the_play_operator_at_the_distal_node():
    K = 0.5
    log_gain = np.linspace(0, K, 51)
    T = np.zeros(51)
    T_out = 0.0
    rng = np.random.default_rng(3)
    for T_in in rng.uniform(0, 30, 300):
        expected = min(max(T_out, T_in * math.exp(-K)), T_in * math.exp(K))
        T_out = profile_update(T, log_gain, T_in)
        assert T_out == pytest.approx(expected, rel=1e-12)
        # log-tension stays mu-Lipschitz in theta: the friction bound is never violated
        assert np.all(np.abs(np.diff(np.log(np.maximum(T, 1e-300)))) <= np.diff(log_gain) + 1e-9) or T_in == 0


def test_batch_equals_repeated_online_updates():
    m = SheathModel(K=0.8, compliance=1e-4)
    lg, w = m.nodes(40)
    T_in = np.abs(np.cumsum(np.random.default_rng(0).normal(0, 1, 500)))
    T_out_b, e_b, T_fin = profile_batch(np.full(41, 2.0), lg, w, T_in)
    T = np.full(41, 2.0)
    for k, t in enumerate(T_in):
        assert profile_update(T, lg, t) == pytest.approx(T_out_b[k])
        assert w @ T == pytest.approx(e_b[k])
    assert np.allclose(T, T_fin)


def test_negative_tension_reads_as_slack():
    m = SheathModel(K=0.3, compliance=1e-4)
    lg, _ = m.nodes(10)
    T = np.full(11, 5.0)
    assert profile_update(T, lg, -3.0) == pytest.approx(0.0)
    assert np.all(T == 0.0)
