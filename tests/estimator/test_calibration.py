"""Joint-limit calibration: knee, M_e by slope, K by Newton on eq. (13)."""
import math

import numpy as np
import pytest

from estimator.errors import CalibrationError
from estimator.geometry import Run, SheathGeometry
from estimator.offline.calibration import calibrate_joint_limit, detect_knee
from estimator.sheath import SheathModel

L, EA = 1.5, 15000.0


def joint_limit_pull(model, k_joint=100.0, limit=0.02, T_max=25.0, noise_T=0.02, q=5e-7, seed=0):
    """Quasi-static pull: distal end on a spring until the limit, then fixed. Profile in full slip."""
    rng = np.random.default_rng(seed)
    T = np.linspace(0.0, T_max, 4000)
    x_out = np.minimum(T * math.exp(-model.K) / k_joint, limit)
    x = x_out + model.M_e * T
    return np.round(x / q) * q, T + rng.normal(0, noise_T, T.size), T


@pytest.mark.parametrize("K_true", [0.2, 0.63, 1.2])
def test_recovers_K_and_M_e_within_one_percent(K_true):
    model = SheathModel(K=K_true, compliance=L / EA)
    x, T, _ = joint_limit_pull(model)
    res = calibrate_joint_limit(x, T, L, EA)
    assert res.K == pytest.approx(K_true, rel=0.01)
    assert res.M_e == pytest.approx(model.M_e, rel=0.01)
    knee_T = 0.02 * 100.0 * math.exp(K_true)
    assert res.knee_T_in == pytest.approx(knee_T, abs=0.1 * knee_T + 0.3)


def test_route_shape_removes_the_constant_curvature_bias():
    g = SheathGeometry([Run(1.0), Run(0.5, 0.5 / (2 * math.pi))])  # all the bend at the distal end
    model = SheathModel.from_geometry(g, 0.1, EA)
    x, T, _ = joint_limit_pull(model)
    with_route = calibrate_joint_limit(x, T, g.length, EA, wrap_shape=model.wrap_shape)
    uniform = calibrate_joint_limit(x, T, g.length, EA)
    assert with_route.K == pytest.approx(model.K, rel=0.01)
    assert abs(uniform.K - model.K) > 0.1 * model.K


def test_no_knee_is_an_error():
    T = np.linspace(0, 20, 500)
    with pytest.raises(CalibrationError, match="knee"):
        calibrate_joint_limit(T * 1e-3, T, L, EA)


def test_too_compliant_says_why():
    model = SheathModel(K=0.5, compliance=L / EA)
    x, T, _ = joint_limit_pull(model)
    with pytest.raises(ValueError, match=r"outside \(0, 1\).*compliant"):
        calibrate_joint_limit(x, T, L, EA * 3)  # claims a much stiffer tendon than measured


def test_too_few_samples():
    with pytest.raises(CalibrationError, match="at least 20"):
        detect_knee(np.arange(5.0), np.arange(5.0))
