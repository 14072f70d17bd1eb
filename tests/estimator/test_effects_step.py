"""The friction step (a reshaped sheath): the kernel's step of K at its instant, the instant fitted by a profile,
the fold that judges a step, and the diagnosis telling a step from a drift."""
from __future__ import annotations

import numpy as np
import pytest

from estimator.offline.diagnosis.fit import fit_model
from estimator.offline.diagnosis.folds import Folds, step_fold
from estimator.offline.diagnosis.instant import PROFILE_MARGIN
from estimator.offline.diagnosis.selection import diagnose
from estimator.offline.effects.catalogue import effect, predict
from estimator.offline.effects.types import Series
from study import scenarios
from study.report import format_summary
from tests.estimator.effects_series import K, _pull, series


def test_friction_step_changes_K_at_its_instant_only():
    T_in, x_in = _pull()
    s = series(T_in, x_in)
    t_s = 0.4 * float(s.time[-1] - s.time[0])
    pr = predict(["friction_step"], {"K": K, "dK": -0.3, "t_s": t_s}, s, compliance=1e-4)
    base = predict([], {"K": K}, s, compliance=1e-4)
    after = s.time - s.time[0] >= t_s
    m = T_in > 1.0
    np.testing.assert_array_equal(pr.T_out[~after], base.T_out[~after])
    # a sliding pull follows the lower friction at once
    np.testing.assert_allclose(pr.T_out[m & after], T_in[m & after] * np.exp(-(K - 0.3)), rtol=1e-9)


def test_friction_step_instant_is_profiled_not_a_gradient():
    # a pull-release series whose friction steps at 13 s: the fit finds the instant by its profile and both levels
    t = np.arange(0.0, 30.0, 0.005)
    x_in = 2e-3 * np.sin(2 * np.pi * t / 4.0) ** 2
    T_in = 1.0 + 5e3 * x_in
    s = series(T_in, x_in, dt=0.005)
    truth = predict(["friction_step"], {"K": K, "dK": -0.2, "t_s": 13.0}, s, compliance=1e-4)
    s = Series(s.time, s.x_in, s.T_in, s.velocity, truth.T_out, truth.x_out, s.u, s.w)
    vals, _, _ = fit_model([effect("friction_step")], s, [{"K": 0.5, "dK": 0.0}])
    assert abs(vals["t_s"] - 13.0) < 1.0          # the pulls are 2 s apart: the instant lies between two of them
    assert abs(vals["dK"] + 0.2) < 0.01 and abs(vals["K"] - K) < 0.01


def test_a_step_is_judged_by_the_fold_whose_fit_block_holds_both_sides():
    t = np.arange(0.0, 100.0, 0.01)
    s = series(np.ones_like(t), dt=0.01)
    folds = Folds(s, kb=3000, kv=6000, kt=9000)     # forward fit [0, 60 s), backward fit [30, 90 s)
    assert step_fold(folds, [20.0, 70.0]) == 1      # after the forward fit block: only the backward fold saw it
    assert step_fold(folds, [10.0, 40.0]) == 0      # before the backward fit block: only the forward fold saw it
    assert step_fold(folds, [45.0, 45.0]) is None   # inside both: the worse fold counts
    assert step_fold(folds, [45.0, 60.0 - 0.5 * PROFILE_MARGIN]) == 1
    # each fold's instant beyond the other's fit block: the fold whose step explains its validation block judges
    assert step_fold(folds, [10.0, 70.0], [0.05, 0.97]) == 0
    assert step_fold(folds, [10.0, 70.0], [0.98, 0.04]) == 1


@pytest.mark.parametrize("hidden", ["friction_step", "curvature_drift"])
def test_a_step_is_named_a_step_and_a_ramp_a_drift(hidden):
    # the same rig with K stepping at one instant or drifting: the residual of a steady K is a step or a ramp
    rec = scenarios.record(hidden, seed=3, level=0.8, duration=40.0, rate_hz=200.0)
    d = diagnose(rec.data)
    assert d["cause"] == hidden
    if hidden == "friction_step":
        fitted = d["parameters"]["t_s"]["value"] + float(rec.data.time[0])
        assert abs(fitted - rec.truth["parameters"]["t_s"]) < 2.0
        assert abs(d["parameters"]["dK"]["value"] - rec.truth["parameters"]["dK"]) < 0.2 * abs(
            rec.truth["parameters"]["dK"])


@pytest.mark.parametrize("pair", [("pretension", "curvature_drift"), ("velocity_friction", "sensor_offset:T_out")])
def test_two_causes_at_once_are_both_named(pair):
    rec = scenarios.record(pair, seed=3, level=0.8, duration=40.0, rate_hz=200.0)
    causes = diagnose(rec.data)["causes"]
    assert set(pair) <= set(causes[:2])


@pytest.mark.parametrize("hidden", [("velocity_friction", "sensor_offset:T_out"), ("sensor_offset:T_out",)])
def test_velocity_friction_beside_an_offset_shows_once_the_offset_is_taken_off(hidden):
    # the independent simulator's per-node velocity friction at its low level beside a T_out offset, on a joint: the
    # offset bends every other single fit; the speed term shows in the reading once the fitted offset is taken off
    from study.lumped import scenarios as lumped
    rec = lumped.record(hidden, seed=5762003, level=0.2, duration=60.0)
    d = diagnose(rec.data)
    assert d["causes"][0] == "sensor_offset:T_out"
    assert d["parameters"]["b_T_out"]["value"] == pytest.approx(rec.truth["parameters"]["offset"], abs=0.05)
    assert ("velocity_friction" in d["causes"]) == ("velocity_friction" in hidden)


def test_an_offset_beside_the_physical_effect_chosen_first_is_fitted_with_the_route_free():
    # the independent simulator's velocity friction beside a T_out offset on a constant-force load: velocity friction
    # is chosen first and, on the route the offset bent, leaves the distal elongation structured; neither effect's
    # single is strong enough for the pairs' pool. Beside the offset with the route free, both are named: the single
    # takes the proximal-speed form (S 0.807, the mean of both ends' speeds 0.808), the pair in that form leaves the
    # distal elongation at 7 floors, the pair in the mean-speed form from the uniform route at 1.8
    from study.lumped import scenarios as lumped
    rec = lumped.record(("velocity_friction", "sensor_offset:T_out"), seed=5862000, level=0.2, duration=60.0)
    d = diagnose(rec.data)
    assert set(d["causes"]) == {"velocity_friction", "sensor_offset:T_out"}
    assert d["parameters"]["velocity_form"]["value"] == 1.0
    assert d["parameters"]["b_T_out"]["value"] == pytest.approx(rec.truth["parameters"]["offset"], abs=0.05)
    assert d["parameters"]["c_v"]["value"] == pytest.approx(rec.truth["parameters"]["viscous"], rel=0.2)
    assert d["settings"]["pair_rule"] == "offset_beside_physical"
    assert "named by the step offset_beside_physical" in format_summary(d)
