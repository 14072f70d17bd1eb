"""The joint estimator on the KAIST pair (two tensions, one command, the distal angle): it predicts the
distal angle held out (cycle 2) as well as the seed pair model and far better than the linear map.

The data are unlicensed and read in place; without them these tests skip saying so."""
from __future__ import annotations

import math

import numpy as np
import pytest

from estimator.offline.pair.fit import PairParams, fit_linear, fit_pair, predict_angle, rmse
from estimator.online.pair_batch import predict_pair_angle
from recorded.folders import KAIST, skip_reason
from recorded.kaist import cycles, load_all
from recorded.kaist_files import default_kaist_dir, find_configs

KAIST_DIR = default_kaist_dir()
pytestmark = [pytest.mark.kaist, pytest.mark.skipif(not find_configs(KAIST_DIR), reason=skip_reason(KAIST, KAIST_DIR))]


def test_without_friction_the_joint_estimator_is_the_seed_pair_model():
    rng = np.random.default_rng(1)
    n = 400
    c = 1.0 * np.sin(np.linspace(0, 4 * math.pi, n))
    Ta = 5 + 4 * np.maximum(c, -0.3) + rng.normal(0, 0.05, n)
    Tb = 5 - 4 * np.minimum(c, 0.3) + rng.normal(0, 0.05, n)
    p = PairParams(G=1.2, K_a=0.0, K_b=0.0, lam_a=0.1, lam_b=0.08, theta0=0.02)
    assert np.allclose(predict_pair_angle(p, c, Ta, Tb), predict_angle(p, c, Ta, Tb), atol=1e-12)


def test_predicts_the_distal_angle_held_out():
    for rec in load_all(KAIST_DIR):
        c1, c2 = cycles(rec)[:2]
        joint = fit_pair(rec.command, rec.T_a, rec.T_b, rec.angle, c1.stop, predict=predict_pair_angle,
                         name="joint estimator")
        seed = fit_pair(rec.command, rec.T_a, rec.T_b, rec.angle, c1.stop)
        linear = fit_linear(rec.command, rec.angle, c1.stop)
        err = {f.name: math.degrees(rmse(f.prediction[c2] - rec.angle[c2])) for f in (joint, seed, linear)}
        assert err["joint estimator"] < 0.5 * err["linear map"], (rec.config_deg, err)
        assert err["joint estimator"] < 4.0, (rec.config_deg, err)
        assert abs(err["joint estimator"] - err["seed pair model"]) < 0.3, (rec.config_deg, err)
