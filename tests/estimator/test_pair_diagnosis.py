"""Capstan-joint pair model, pair diagnosis and shared fit: synthetic data made by the models
themselves (parameters recovered, the right cause named). The KAIST results (docs/results/kaist.md)
are checked through the CLI in tests/study/test_analyze.py."""
from __future__ import annotations

import math

import numpy as np
import pytest

from estimator.offline.pair.diagnosis import diagnose_pair
from estimator.offline.pair.diagnosis_fit import figure_bootstrap, fit_model
from estimator.offline.pair.fit import PairParams, play, predict_angle, reversal_dead_zones
from estimator.offline.pair.general import loco_bootstrap
from estimator.offline.pair.models import PAIR_EFFECTS, applicable, parse_model, predict_model
from estimator.offline.pair.shared import SHARED_MODELS, fit_shared, leave_one_out, shared_params
from estimator.pair_kernels import simulate_pair

DT = 0.025                                   # 40 Hz, as the KAIST recordings
N_CYCLE = int(round(2 * math.pi / DT))       # samples per command cycle (period 2 pi s)
TRAIN, TEST = slice(0, N_CYCLE), slice(N_CYCLE, 2 * N_CYCLE)
TRUE = {"G": 1.4, "lam": 0.4, "K_a": 0.9, "K_b": 0.5, "k": 4.0, "theta0": 0.01}


class Rec:
    """A KAIST-like recording: 2 cycles of a 60 deg sine command, 40 Hz."""

    def __init__(self, angle, T, command, config_deg=0):
        self.time = np.arange(angle.size) * DT
        self.command, self.angle, self.config_deg = command, angle, config_deg
        self.T_a, self.T_b = T[:, 0], T[:, 1]


def command(n=2 * N_CYCLE + 20):
    return math.radians(60.0) * np.sin(np.arange(n) * DT)


def capstan_rec(v=TRUE, noise_deg=0.05, seed=0, config_deg=0):
    """The capstan model's own output with tracker noise and 0.02 N load-cell noise."""
    c = command()
    th, T = simulate_pair(c, (5.0, 5.0), v["G"], (v["lam"], v["lam"]), (v["K_a"], v["K_b"]), v["k"])
    rng = np.random.default_rng(seed)
    T = T + 0.02 * rng.standard_normal(T.shape)
    T[0] = 5.0
    return Rec(th + v["theta0"] + math.radians(noise_deg) * rng.standard_normal(c.size), T, c, config_deg)


# ---- the kernel -------------------------------------------------------------------------------

def test_rest_is_an_equilibrium_and_one_step_per_sample_is_enough():
    c = command()
    th, T = simulate_pair(np.zeros(50), (5.0, 4.0), 1.4, (0.4, 0.4), (0.9, 0.5), 4.0)
    assert np.all(th == 0.0) and np.allclose(T, [5.0, 4.0])            # unequal pretensions: still at rest
    a1, T1 = simulate_pair(c, (5.0, 5.0), 1.4, (0.4, 0.4), (0.9, 0.5), 4.0, substeps=1)
    a8, T8 = simulate_pair(c, (5.0, 5.0), 1.4, (0.4, 0.4), (0.9, 0.5), 4.0, substeps=8)
    assert np.max(np.abs(a1 - a8)) < 1e-9 and np.max(np.abs(T1 - T8)) < 1e-7


def test_dead_zone_after_a_reversal_grows_with_K_and_tensions_follow_the_motor():
    c = command()
    zones = []
    for K in (0.2, 0.6, 1.2):
        th, T = simulate_pair(c, (5.0, 5.0), 1.4, (0.4, 0.4), (K, K), 4.0)
        dz = reversal_dead_zones(c, th, T[:, 0], T[:, 1])
        zones.append(np.nanmean([z.command_travel for z in dz]))
        # the released tendon's proximal tension falls by e^{-2K} before the joint moves (Phee eqs. (14)-(21))
        assert np.nanmedian([z.K_release for z in dz]) == pytest.approx(K, rel=0.15)
        assert np.corrcoef(c, T[:, 0] - T[:, 1])[0, 1] > 0.8               # motor pulls a on + command
    assert zones[0] < zones[1] < zones[2] and zones[2] > 2 * zones[0]


def test_memoised_node_arrays_are_left_unchanged_by_a_run():
    from estimator.pair_kernels import _node_arrays, tendon_arrays
    c = command()
    for kw in ({}, {"toe": 5.0, "toe_tension": 1.0}, {"lam_s": 0.2, "tau_c": 0.2, "shape": 0.5}):
        runs = [simulate_pair(c, (5.0, 4.0), 1.4, (0.4, 0.4), (0.9, 0.5), 4.0, **kw) for _ in range(2)]
        assert all(np.array_equal(x, y) for x, y in zip(*runs, strict=False))
        for K in (0.9, 0.5):                       # the kernels only read the shared node arrays
            lam_s = kw.get("lam_s", 0.0)
            cached, fresh = _node_arrays(K, 0.4, 24, lam_s), tendon_arrays(K, 0.4, 24, lam_s)
            assert all(np.array_equal(x, y) for x, y in zip(cached, fresh, strict=False))


def test_bending_section_friction_stalls_the_joint_at_large_angles_and_is_neutral_when_off():
    c = command()
    base = simulate_pair(c, (5.0, 4.0), 1.4, (0.4, 0.4), (0.9, 0.5), 4.0)
    tiny = simulate_pair(c, (5.0, 4.0), 1.4, (0.4, 0.4), (0.9, 0.5), 4.0, mu_b=1e-12)
    assert np.max(np.abs(tiny[0] - base[0])) < 1e-9 and np.max(np.abs(tiny[1] - base[1])) < 1e-8
    rest, _ = simulate_pair(np.zeros(30), (5.0, 4.0), 1.4, (0.4, 0.4), (0.9, 0.5), 4.0, mu_b=0.5)
    assert np.all(rest == 0.0)                                              # the rest is still an equilibrium
    th, T = simulate_pair(c, (5.0, 4.0), 1.4, (0.4, 0.4), (0.9, 0.5), 4.0, mu_b=0.5)
    assert np.ptp(th) < 0.9 * np.ptp(base[0]) and T[:, 0].max() > base[1][:, 0].max()   # smaller range, more tension
    with pytest.raises(ValueError, match="not combined with toe, tau_c or k2"):
        simulate_pair(c, (5.0, 4.0), 1.4, (0.4, 0.4), (0.9, 0.5), 4.0, mu_b=0.5, tau_c=0.1)
    assert "bending_friction" not in applicable("capstan", ())             # a shared candidate only
    m = SHARED_MODELS["capstan+T, bending-section friction"]
    assert [p.name for p in shared_params(m)] == ["s", "K0_a", "K0_b", "k", "mu_b", "mu"]


def test_kernel_refuses_bad_parameters():
    c = command(10)
    with pytest.raises(ValueError, match="k must be > 0"):
        simulate_pair(c, (5.0, 5.0), 1.0, (0.4, 0.4), (0.5, 0.5), 0.0)
    with pytest.raises(ValueError, match="K_a must be finite and >= 0"):
        simulate_pair(c, (5.0, 5.0), 1.0, (0.4, 0.4), (-0.1, 0.5), 1.0)
    with pytest.raises(ValueError, match="shape must be in"):
        simulate_pair(c, (5.0, 5.0), 1.0, (0.4, 0.4), (0.5, 0.5), 1.0, shape=2.0)
    with pytest.raises(ValueError, match="1-D array of finite"):
        simulate_pair(np.array([0.0, np.nan]), (5.0, 5.0), 1.0, (0.4, 0.4), (0.5, 0.5), 1.0)


def test_catalogue_structures_and_ids():
    assert parse_model("capstan+joint_backlash+sensor_delay") == ("capstan", ("joint_backlash", "sensor_delay"))
    with pytest.raises(ValueError, match="does not apply to the seed"):
        parse_model("seed+joint_friction")
    with pytest.raises(ValueError, match="unknown pair structure"):
        parse_model("spring")
    assert "capstan_joint" not in applicable("capstan", ())
    assert set(applicable("seed", ())) == {"joint_backlash", "sensor_delay", "friction_offset"}
    assert all(e.literature.startswith("E") for e in PAIR_EFFECTS.values())


# ---- fitting and diagnosis on the models' own output ---------------------------------------------

def test_capstan_model_recovers_its_parameters():
    rec = capstan_rec()
    f = fit_model("capstan", (), rec, TRAIN, TEST, [{"G": 2.0, "lam": 0.3, "K_a": 0.3, "K_b": 0.3, "k": 2.0}])
    for name, want in TRUE.items():
        assert f.values[name] == pytest.approx(want, rel=0.06, abs=0.002), name
    assert math.degrees(f.rmse_test) < 0.06                            # the tracker noise, 0.05 deg
    assert f.rmse_T_in < 0.15                      # it predicts the load cells too (range 2-10 N, noise 0.02 N)
    u = figure_bootstrap(f, rec, TRAIN, TEST, n_draws=5)               # training blocks redrawn and refitted
    assert u["n_draws"] == 5 and 0.0 < u["std_deg"] < 0.01 and 0.04 < u["ci95_deg"][0] <= u["ci95_deg"][1] < 0.07
    with pytest.raises(ValueError, match="n_draws"):
        figure_bootstrap(f, rec, TRAIN, TEST, n_draws=4)


def test_diagnosis_names_the_capstan_joint_on_its_own_data():
    rec = capstan_rec(seed=1)
    s, fits = diagnose_pair(rec, TRAIN, TEST)
    assert s["causes"] == ["capstan_joint"]                            # nothing left above the noise
    assert s["extended"]["model"] == "capstan"
    assert s["extended"]["rmse_test_deg"] < 0.06 < 0.2 < s["seed"]["rmse_test_deg"]
    assert s["candidates"]["capstan"]["accepted"] and s["gain"] > 0.7
    assert s["extended"]["params"]["K_a"]["value"] == pytest.approx(0.9, rel=0.06)


def test_diagnosis_names_joint_backlash_when_the_seed_model_has_one():
    base = capstan_rec(seed=2, noise_deg=0.0)
    p = PairParams(1.3, 0.2, 0.2, 0.1, 0.1, 0.0)
    th = play(predict_angle(p, base.command, base.T_a, base.T_b), math.radians(8.0), 0.0)
    rec = Rec(th + math.radians(0.05) * np.random.default_rng(3).standard_normal(th.size),
              np.column_stack([base.T_a, base.T_b]), base.command)
    s, _ = diagnose_pair(rec, TRAIN, TEST)
    assert s["cause"] == "joint_backlash" and s["extended"]["model"].startswith("seed+joint_backlash")
    assert math.degrees(s["extended"]["params"]["b"]["value"]) == pytest.approx(8.0, rel=0.1)
    assert s["extended"]["rmse_test_deg"] < 0.1


def test_shared_fit_recovers_mu_and_predicts_a_left_out_configuration():
    v0 = {"G": 1.4, "lam": 0.4, "k": 4.0, "K0_a": 0.6, "K0_b": 0.3, "mu": 0.15}
    bends = [math.radians(n) for n in (0, 90, 180, 240)]
    recs = [capstan_rec({**v0, "K_a": v0["K0_a"] + v0["mu"] * b, "K_b": v0["K0_b"] + v0["mu"] * b, "theta0": 0.0},
                        seed=10 + i) for i, b in enumerate(bends)]
    m = SHARED_MODELS["capstan"]
    assert [p.name for p in shared_params(m)] == ["G", "lam", "K0_a", "K0_b", "k", "mu"]
    v = fit_shared(m, recs, bends, [TRAIN] * 4)
    for name, want in v0.items():
        assert v[name] == pytest.approx(want, rel=0.08), name
    loo = leave_one_out(m, recs, bends, [slice(0, TEST.stop)] * 4, [TEST] * 4, v)
    assert max(r["rmse_test_deg"] for r in loo) < 0.15                  # 3x the noise, from N alone
    # the figure's bootstrap: noise-free shapes, started at the truth, are predicted exactly from every draw
    exact = [capstan_rec({**v0, "K_a": v0["K0_a"] + v0["mu"] * b, "K_b": v0["K0_b"] + v0["mu"] * b, "theta0": 0.0},
                         noise_deg=0.0) for b in bends[:3]]
    u = loco_bootstrap(m, exact, bends[:3], [[TRAIN, TEST]] * 3, [TEST] * 3, [{"params": v0}] * 3, n_draws=5)
    assert len(u) == 3 and all(x["n_draws"] == 5 and x["ci95_deg"][1] < 1e-3 for x in u)
    with pytest.raises(ValueError, match="n_draws"):
        loco_bootstrap(m, exact, bends[:3], [[TRAIN]] * 3, [TEST] * 3, [{"params": v0}] * 3, n_draws=4)
    with pytest.raises(ValueError, match="equal length"):
        fit_shared(m, recs, bends[:2], [TRAIN] * 4)


def test_predict_model_applies_delay_and_backlash():
    rec = capstan_rec(noise_deg=0.0)
    v = {**TRUE, "tau": 2 * DT, "b": 0.0}
    th, T = predict_model("capstan", ("sensor_delay",), v, rec)
    th0, _ = predict_model("capstan", (), TRUE, rec)
    assert np.allclose(th[10:], th0[8:-2]) and T.shape == (th.size, 2)
    thb, _ = predict_model("capstan", ("joint_backlash",), {**TRUE, "b": 0.05}, rec)
    assert np.max(np.abs(thb - th0)) == pytest.approx(0.05, abs=1e-3)


def test_toe_tendon_is_neutral_when_off_converges_and_keeps_the_released_tendon_taut():
    c = command()
    base = simulate_pair(c, (5.0, 5.0), 1.4, (0.4, 0.4), (0.9, 0.5), 4.0)
    off = simulate_pair(c, (5.0, 5.0), 1.4, (0.4, 0.4), (0.9, 0.5), 4.0, toe=0.0, toe_tension=0.3)
    assert all(np.array_equal(x, y) for x, y in zip(base, off, strict=False))              # bit for bit when off
    tiny = simulate_pair(c, (5.0, 5.0), 1.4, (0.4, 0.4), (0.9, 0.5), 4.0, toe=1e-9)
    assert np.max(np.abs(tiny[0] - base[0])) < 1e-9                           # the toe path is the same model
    a1, T1 = simulate_pair(c, (5.0, 5.0), 1.4, (0.4, 0.4), (0.9, 0.5), 4.0, toe=5.0, toe_tension=1.0)
    a8, T8 = simulate_pair(c, (5.0, 5.0), 1.4, (0.4, 0.4), (0.9, 0.5), 4.0, toe=5.0, toe_tension=1.0, substeps=8)
    assert np.max(np.abs(a1 - a8)) < math.radians(0.05) and np.max(np.abs(T1 - T8)) < 0.02
    # soft at low tension: the released tendon keeps more tension, and the joint leaves a plateau later
    assert T1.min() > base[1].min() + 0.1
    assert np.max(np.abs(a1 - base[0])) > math.radians(0.5)
    with pytest.raises(ValueError, match="toe_tension finite and > 0"):
        simulate_pair(c, (5.0, 5.0), 1.4, (0.4, 0.4), (0.9, 0.5), 4.0, toe=1.0, toe_tension=0.0)


def test_fits_run_the_causal_models_only_up_to_the_fitted_samples():
    from estimator.offline.pair.models import LOOKAHEAD_S, head
    rec = capstan_rec()
    part = head(rec, TRAIN)
    assert N_CYCLE < len(part.angle) <= N_CYCLE + LOOKAHEAD_S / DT + 2 and head(rec, slice(N_CYCLE, None)) is rec
    assert len(head(rec, np.array([3, 40, 7])).angle) < N_CYCLE
    v = {**TRUE, "tau": -0.2, "b": 0.05}
    for effects in ((), ("sensor_delay",), ("joint_backlash", "sensor_delay")):   # the delay reads ahead
        full, _ = predict_model("capstan", effects, v, rec)
        short, _ = predict_model("capstan", effects, v, part)
        assert np.array_equal(full[TRAIN], short[TRAIN])


# ---- the stiffening joint, the cross-validation folds, the exported shared set -------------------

def test_stiffening_joint_caps_the_angle_and_folds_split_the_training_block():
    from estimator.offline.pair.diagnosis_fit import folds
    c = command()
    th0, _ = simulate_pair(c, (5.0, 5.0), 1.4, (0.4, 0.4), (0.5, 0.5), 4.0)
    th1, _ = simulate_pair(c, (5.0, 5.0), 1.4, (0.4, 0.4), (0.5, 0.5), 4.0, k2=40.0, theta_c=0.1)
    assert np.max(np.abs(th0)) > 0.5 and np.max(np.abs(th1)) < 0.2           # stiff beyond 0.1 rad
    first = np.argmax(np.abs(th0) > 0.1)
    np.testing.assert_allclose(th1[:first], th0[:first], atol=1e-12)          # the same below theta_c
    (f1, s1), (f2, s2) = folds(slice(0, 100), 120)
    assert np.array_equal(f1, s2) and np.array_equal(f2, s1) and not set(f1) & set(f2)
    assert sorted(np.concatenate([f1, f2])) == list(range(100)) and f1[0] == 0 and 12 <= f2[0] <= 13


def test_exported_shared_set_predicts_without_refit():
    from estimator.offline.pair.general import export_params, predict_shared
    m = SHARED_MODELS["capstan+T"]
    v = {"s": 12.5, "k": 4.0, "K0_a": 0.6, "K0_b": 0.3, "mu": 0.15}                 # G held at 5: lam = 5 / 12.5
    b = math.radians(150)
    rec = capstan_rec({"G": 5.0, "lam": 0.4, "k": 4.0, "K_a": 0.6 + 0.15 * b, "K_b": 0.3 + 0.15 * b, "theta0": 0.0},
                      noise_deg=0.0)
    p = export_params(m, v, "test")
    assert p["values"]["s"]["unit"] == "N/rad" and "lam = G / s" in p["model"]["laws"] and "G" not in p["values"]
    th, used = predict_shared(p, rec, b)
    assert used["lam"] == pytest.approx(0.4) and used["K_a"] == pytest.approx(0.6 + 0.15 * b)
    assert np.max(np.abs(th - rec.angle)) < 1e-9
    with pytest.raises(ValueError, match="missing mu"):
        predict_shared({**p, "values": {k: x for k, x in p["values"].items() if k != "mu"}}, rec, b)


def test_tension_weighted_fit_recovers_a_series_compliance_and_predicts_the_load_cells():
    from estimator.offline.pair.diagnosis_fit import cross_validate
    true = {"G": 1.4, "lam": 0.1, "K_a": 0.9, "K_b": 0.5, "k": 6.0, "lam_s": 0.25}
    c = command()
    th, T = simulate_pair(c, (5.0, 5.0), true["G"], (true["lam"],) * 2, (true["K_a"], true["K_b"]), true["k"],
                          lam_s=true["lam_s"])
    rng = np.random.default_rng(7)
    T = T + 0.02 * rng.standard_normal(T.shape)
    T[0] = 5.0
    rec = Rec(th + math.radians(0.05) * rng.standard_normal(c.size), T, c)
    start = [{"G": 2.5, "lam": 0.3, "K_a": 0.6, "K_b": 0.3, "k": 4.0, "lam_s": 0.1}]
    f = fit_model("capstan", ("series_compliance",), rec, TRAIN, TEST, start, tension_weight=0.01)
    for name in ("G", "lam_s", "K_a", "K_b", "k"):
        assert f.values[name] == pytest.approx(true[name], rel=0.1), name
    assert f.rmse_T_train < 0.05 and f.rmse_T_in < 0.05 and math.degrees(f.rmse_test) < 0.1
    assert 0.0 < cross_validate(f, rec, TRAIN, tension_weight=0.01) < math.radians(0.2)
    plain = fit_model("capstan", (), rec, TRAIN, TEST, [{"G": 2.0, "lam": 0.3, "K_a": 0.3, "K_b": 0.3, "k": 2.0}],
                      max_nfev=8)
    zero = fit_model("capstan", (), rec, TRAIN, TEST, [{"G": 2.0, "lam": 0.3, "K_a": 0.3, "K_b": 0.3, "k": 2.0}],
                     max_nfev=8, tension_weight=0.0)
    assert plain.values == zero.values                                  # weight 0: the angle-only fit, unchanged
    with pytest.raises(ValueError, match="tension_weight must be finite and >= 0"):
        fit_model("capstan", (), rec, TRAIN, TEST, [TRUE], tension_weight=-1.0)


# ---- tension plausibility of the choice, the drive-side observer ---------------------------------------

def test_tension_check_refuses_a_capstan_fit_whose_tension_peaks_are_off_and_refits_it_with_the_tensions():
    rec = capstan_rec(seed=4)
    f = fit_model("capstan", (), rec, TRAIN, TEST, [dict(TRUE)])
    assert f.tension_peak_ratio(rec, TRAIN) == pytest.approx([1.0, 1.0], abs=0.02)
    T = np.column_stack([rec.T_a, rec.T_b])
    T[1:] = 5.0 + 3.0 * (T[1:] - 5.0)            # load cells that read the motion 3x: the fit's peaks 0.5x
    odd = Rec(rec.angle, T, rec.command)
    s, fits = diagnose_pair(odd, TRAIN, TEST, max_effects=1)
    assert s["candidates"]["capstan"]["refused"] and not s["candidates"]["capstan"]["accepted"]
    assert s["extended"]["model"] == "capstan/T" and "tensions" in s["extended"]["fit_inputs"]
    assert all(1 / 1.5 <= x <= 1.5 for x in s["candidates"]["capstan/T"]["tension_peak_ratio"])
    assert s["tension_check"]["ratio"] == 1.5
    s0, _ = diagnose_pair(odd, TRAIN, TEST, max_effects=1, tension_ratio=None)   # the check off
    assert s0["extended"]["model"] == "capstan" and s0["tension_check"] is None
    with pytest.raises(ValueError, match="tension_ratio"):
        diagnose_pair(odd, TRAIN, TEST, tension_ratio=0.9)


def test_drive_observer_is_the_command_model_when_off_and_reads_the_measured_tensions():
    rec = capstan_rec(seed=5)
    args = (rec.command, (5.0, 5.0), TRUE["G"], (TRUE["lam"],) * 2, (TRUE["K_a"], TRUE["K_b"]), TRUE["k"])
    base = simulate_pair(*args)
    off = simulate_pair(*args, observed=(rec.T_a, rec.T_b), lam_d=0.0)
    assert all(np.array_equal(x, y) for x, y in zip(base, off, strict=False))
    on = simulate_pair(*args, observed=(rec.T_a, rec.T_b), lam_d=0.05)
    assert np.ptp(on[0]) < np.ptp(base[0])         # the entry gives way as the measured tension rises
    flat = simulate_pair(*args, observed=(np.full_like(rec.T_a, 5.0), np.full_like(rec.T_b, 5.0)), lam_d=0.5)
    assert np.array_equal(flat[0], base[0])        # no measured change: no correction
    th, _ = predict_model("capstan", ("drive_observer",), {**TRUE, "lam_d": 0.05}, rec)
    assert np.allclose(th - TRUE["theta0"], on[0])
    with pytest.raises(ValueError, match="observed"):
        simulate_pair(*args, observed=(rec.T_a[:-1], rec.T_b), lam_d=0.1)
    with pytest.raises(ValueError, match="observer"):
        simulate_pair(*args, observed=(rec.T_a, rec.T_b), lam_d=0.1, tau_c=0.1)
    assert "drive_observer" not in applicable("capstan", ())         # not offered by default
