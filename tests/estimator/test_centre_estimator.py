"""The centre map one sample at a time follows the batch centre map (the same equations, a causal spindle rate)."""
from __future__ import annotations

import numpy as np
import pytest

from estimator.offline.spindle.centre_fit import predict_held
from estimator.online.centre_estimator import CentreEstimator
from estimator.online.spindle_centre import CentreParams


def run(seconds: float = 12.0, dt: float = 1e-3):
    """A spindle stroked by a 0.3 Hz sine; its torque a friction band about a load that grows with the angle."""
    t = np.arange(0.0, seconds, dt)
    theta = 0.5 + 0.4 * np.sin(2 * np.pi * 0.3 * t)
    omega = np.gradient(theta, dt)
    tau = 0.02 + 0.01 * theta + 0.004 * np.tanh(omega / 0.05)
    return t, theta, tau


def params(shape_range=None) -> CentreParams:
    coef = np.array([[0.001, 0.01, 0.0], [0.9, 0.1, 0.0], [0.002, 0.0, 0.0], [0.05, 0.0, 0.0]])
    notes = {} if shape_range is None else {"shape_range": shape_range}
    return CentreParams(coef, theta_ref=0.5, theta_z=0.02, window=(0.3, 0.7), half_width=(0.004, 0.0), centre0=0.02,
                        edge_slope=(0.01, 0.01), notes=notes)


@pytest.mark.parametrize("shape_range", [None, [[-0.3, 0.3], [-0.3, 0.3]]])
def test_the_online_centre_map_is_the_batch_one_within_its_rate_delay(shape_range):
    t, theta, tau = run()
    p = params(shape_range)
    est = CentreEstimator(p)
    online = np.array([est.step(a, b, c) for a, b, c in zip(tau, theta, t, strict=False)])
    batch = predict_held(p, tau, theta, 1e-3)
    scale = np.ptp(batch)
    late = t > 4.0                      # both readings hold both band edges
    assert np.sqrt(np.mean((online[late] - batch[late]) ** 2)) < 0.01 * scale
    assert abs(est.centre - 0.02 - 0.005) < 0.002      # the band's middle: 0.02 + 0.01 * mean angle (0.5)


def test_a_bad_coefficient_shape_or_half_width_is_refused():
    p = params()
    with pytest.raises(ValueError, match="coef"):
        CentreEstimator(CentreParams(np.zeros((3, 2)), 0.0, 0.01, (0, 1), (0.0, 0.0), 0.0))
    with pytest.raises(ValueError, match="w1"):
        CentreEstimator(CentreParams(p.coef, 0.0, 0.01, (0, 1), (0.0, 1.5), 0.0))
