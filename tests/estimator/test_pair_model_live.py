"""The pair models per cycle (:class:`estimator.online.pair_model.PairModelEstimator`) give the batch prediction
(:func:`estimator.offline.pair.models.predict_model`) sample by sample: on a synthetic command for every structure
and effect, and on KAIST recordings with the study's fitted parameters (skipped without the data, read in place).

Tolerance: the capstan structure runs the batch model's compiled sample loop one sample per call and the seed
structure the same profile update, so the numbers agree to the last bit; :data:`TOL` allows for a summation order
that a later change might alter: the angle sums ~n_nodes node terms of ~1 rad, each rounded to 2.2e-16 relative,
and the state carries such a rounding from sample to sample over at most ~1e4 samples, 25 * 2.2e-16 * 1e4 ~ 6e-11
rad, well inside 1e-9 rad.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from estimator.offline.pair.diagnosis_fit import CAPSTAN_STARTS, fit_model
from estimator.offline.pair.fit import fit_pair
from estimator.offline.pair.models import PAIR_EFFECTS, STRUCTURES, model_params, predict_model
from estimator.online.pair_model import PER_CYCLE, PairModelEstimator
from estimator.pair_kernels import EFFECT_PARAMS, EFFECT_STRUCTURES, STRUCTURE_PARAMS, simulate_pair
from recorded.folders import KAIST, skip_reason
from recorded.kaist import read_kaist, split
from recorded.kaist_files import default_kaist_dir, find_configs, find_kaist_dir, kaist_path

#: live - batch [rad] (module docstring)
TOL = 1e-9
DT = 0.025                                      # 40 Hz, as the KAIST recordings

CAPSTAN = {"G": 1.4, "lam": 0.4, "K_a": 0.9, "K_b": 0.5, "k": 4.0, "theta0": 0.01}
SEED = {"G": 1.3, "K_a": 0.6, "K_b": 0.3, "lam_a": 0.08, "lam_b": 0.06, "theta0": -0.02}
EXTRA = {"b": 0.03, "tau": 0.04, "a": 0.3, "shape": 0.5, "tau_c": 0.2, "lam_s": 0.1, "k2": 3.0, "theta_c": 0.15,
         "toe": 4.0, "toe_tension": 1.0, "mu_b": 0.1, "lam_d": 0.05}

#: (structure, effects) run on the synthetic command: each effect alone and the combinations the kernels allow
MODELS = [("seed", ()), ("seed", ("joint_backlash",)), ("seed", ("sensor_delay",)), ("seed", ("friction_offset",)),
          ("seed", ("joint_backlash", "sensor_delay", "friction_offset")),
          ("capstan", ())] + [("capstan", (e,)) for e in EFFECT_PARAMS if "capstan" in EFFECT_STRUCTURES[e]] + [
          ("capstan", ("joint_backlash", "sensor_delay")),
          ("capstan", ("friction_offset", "pretension_profile", "series_compliance", "joint_friction",
                       "joint_stiffening", "tendon_toe", "joint_backlash", "sensor_delay")),
          ("capstan", ("series_compliance", "bending_friction", "friction_offset")),
          ("capstan", ("drive_observer", "friction_offset", "series_compliance", "sensor_delay"))]


class Rec:
    """A recording: time [s], command [rad], proximal tensions T_a, T_b [N], angle [rad], shape (n,)."""

    def __init__(self, time, command, T_a, T_b, angle=None):
        self.time, self.command, self.T_a, self.T_b = time, command, T_a, T_b
        self.angle = np.zeros_like(command) if angle is None else angle


def synthetic() -> Rec:
    """A 60 deg sine with reversals, a hold on each branch and a partial reversal; tensions from the capstan model
    with 0.02 N load-cell noise (what the seed structure and the observer read)."""
    t = np.arange(700) * DT
    c = math.radians(60.0) * np.sin(t)
    c[100:140] = c[100]                         # hold on the rising branch
    c[300:330] = c[300]                         # hold on the falling branch
    c[450:470] = c[450] - 0.2 * np.sin(np.linspace(0.0, math.pi, 20))   # a partial reversal
    _, T = simulate_pair(c, (5.0, 4.0), 1.4, (0.4, 0.4), (0.9, 0.5), 4.0)
    T = T + 0.02 * np.random.default_rng(3).standard_normal(T.shape)
    return Rec(t, c, T[:, 0], T[:, 1])


def live(structure, effects, values, rec, **kw) -> tuple[np.ndarray, np.ndarray]:
    """The per-cycle model over a recording: angle [rad] (n,), predicted tensions [N] (n, 2)."""
    est = PairModelEstimator(structure, effects, values, (float(rec.T_a[0]), float(rec.T_b[0])), **kw)
    out = [est.step(float(c), float(a), float(b), float(t)) for c, a, b, t in zip(rec.command, rec.T_a, rec.T_b,
                                                                                  rec.time, strict=True)]
    return np.array([o.angle for o in out]), np.array([(o.T_a, o.T_b) for o in out])


def values_of(structure, effects) -> dict[str, float]:
    base = SEED if structure == "seed" else CAPSTAN
    return {n: base[n] for n in STRUCTURE_PARAMS[structure]} | {n: EXTRA[n] for e in effects for n in EFFECT_PARAMS[e]}


@pytest.mark.parametrize("structure,effects", MODELS, ids=["+".join((s, *e)) for s, e in MODELS])
def test_per_cycle_is_the_batch_model(structure, effects):
    rec = synthetic()
    v = values_of(structure, effects)
    want, T_want = predict_model(structure, effects, v, rec)
    got, T_got = live(structure, effects, v, rec)
    assert np.max(np.abs(got - want)) <= TOL
    if structure == "capstan":
        assert T_want is not None and np.max(np.abs(T_got - T_want)) <= 1e-9 * max(1.0, float(np.max(T_want)))
    else:
        assert np.all(np.isnan(T_got))


def test_substeps_per_cycle_are_the_batch_substeps():
    rec = synthetic()
    v = values_of("capstan", ("tendon_toe",))
    th, T = simulate_pair(rec.command, (rec.T_a[0], rec.T_b[0]), v["G"], (v["lam"], v["lam"]), (v["K_a"], v["K_b"]),
                          v["k"], toe=v["toe"], toe_tension=v["toe_tension"], substeps=3, n_nodes=16)
    got, T_got = live("capstan", ("tendon_toe",), v, rec, substeps=3, n_nodes=16)
    assert np.max(np.abs(got - (th + v["theta0"]))) <= TOL and np.max(np.abs(T_got - T)) <= 1e-9 * np.max(T)


def test_reset_starts_again_from_rest():
    rec = synthetic()
    v = values_of("capstan", ("joint_backlash", "sensor_delay"))
    est = PairModelEstimator("capstan", ("joint_backlash", "sensor_delay"), v, (rec.T_a[0], rec.T_b[0]))
    first = [est.step(c, a, b, t).angle for c, a, b, t in zip(rec.command, rec.T_a, rec.T_b, rec.time, strict=True)]
    est.reset()
    again = [est.step(c, a, b, t).angle for c, a, b, t in zip(rec.command, rec.T_a, rec.T_b, rec.time, strict=True)]
    assert first == again and est.steps == rec.command.size


def test_a_negative_delay_reads_the_future_and_is_refused():
    v = values_of("capstan", ("sensor_delay",)) | {"tau": -0.02}
    with pytest.raises(ValueError, match="future"):
        PairModelEstimator("capstan", ("sensor_delay",), v, (5.0, 4.0))


@pytest.mark.parametrize("structure,effects,values,match", [
    ("lumped", (), {}, "unknown pair structure"),
    ("capstan", ("wobble",), CAPSTAN, "unknown pair effect"),
    ("seed", ("tendon_toe",), SEED, "does not apply"),
    ("capstan", ("capstan_joint",), CAPSTAN, "does not apply"),
    ("capstan", ("joint_friction",), CAPSTAN, "missing"),
    ("capstan", (), CAPSTAN | {"lam_s": 0.1}, "not of the model"),
    ("capstan", ("bending_friction", "joint_friction"), CAPSTAN | {"mu_b": 0.1, "tau_c": 0.1}, "not combined"),
    ("capstan", (), CAPSTAN | {"k": 0.0}, "must be > 0"),
])
def test_refuses_a_model_it_cannot_run(structure, effects, values, match):
    with pytest.raises(ValueError, match=match):
        PairModelEstimator(structure, effects, values, (5.0, 4.0))


def test_the_delay_line_needs_increasing_time_stamps():
    est = PairModelEstimator("capstan", ("sensor_delay",), CAPSTAN | {"tau": 0.02}, (5.0, 4.0))
    est.step(0.0, 5.0, 4.0, 0.0)
    with pytest.raises(ValueError, match="increasing"):
        est.step(0.01, 5.0, 4.0, 0.0)


def test_every_pair_effect_says_whether_it_runs_per_cycle_and_the_core_names_match_the_catalogue():
    assert set(PER_CYCLE) == set(PAIR_EFFECTS) == set(EFFECT_PARAMS)
    assert all(isinstance(has, bool) and why for has, why in PER_CYCLE.values())
    assert {s: tuple(p.name for p in ps) for s, ps in STRUCTURES.items()} == STRUCTURE_PARAMS
    for e, eff in PAIR_EFFECTS.items():
        assert tuple(p.name for p in eff.parameters) == EFFECT_PARAMS[e]
        assert set(eff.structures) <= set(EFFECT_STRUCTURES[e])
    assert [p.name for p in model_params("capstan", ("joint_stiffening",))] == [
        *STRUCTURE_PARAMS["capstan"], *EFFECT_PARAMS["joint_stiffening"]]


# ---- KAIST: the study's fitted models -----------------------------------------------------------------------

KAIST_DIR = default_kaist_dir()


def _kaist(config: int):
    if not find_configs(KAIST_DIR):
        pytest.skip(skip_reason(KAIST, KAIST_DIR))
    return read_kaist(kaist_path(find_kaist_dir(KAIST_DIR), config))


@pytest.mark.kaist
@pytest.mark.parametrize("config,effects", [(0, ()), (120, ("series_compliance",))])
def test_kaist_per_cycle_is_the_fitted_batch_model(config, effects):
    """The model the study chooses for the configuration (docs/results/kaist.md), fitted as ``teleop analyze
    --kaist`` fits it (cycle 1, every capstan start), per cycle over the recording (cycles 1 and 2, ~510 samples)."""
    rec = _kaist(config)
    train, test, _ = split(rec)
    fx = fit_model("capstan", effects, rec, train, test, list(CAPSTAN_STARTS))
    want, T_want = predict_model("capstan", effects, fx.values, rec)
    got, T_got = live("capstan", effects, fx.values, rec)
    assert np.max(np.abs(got - want)) <= TOL and np.max(np.abs(T_got - T_want)) <= 1e-9 * np.max(T_want)
    live_deg = math.degrees(float(np.sqrt(np.mean((got[test] - rec.angle[test]) ** 2))))
    assert live_deg == pytest.approx(math.degrees(fx.rmse_test), abs=1e-6) and live_deg < 1.2


@pytest.mark.kaist
def test_kaist_seed_model_per_cycle_with_play_and_delay():
    rec = _kaist(60)
    train, _, _ = split(rec)
    v = fit_pair(rec.command, rec.T_a, rec.T_b, rec.angle, train.stop).params | {"b": 0.01, "tau": 0.05, "a": 0.2}
    effects = ("friction_offset", "joint_backlash", "sensor_delay")
    want, _ = predict_model("seed", effects, v, rec)
    got, _ = live("seed", effects, v, rec)
    assert np.max(np.abs(got - want)) <= TOL
