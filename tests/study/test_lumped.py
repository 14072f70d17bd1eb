"""The lumped-mass simulator (study.lumped.simulator) against the closed forms of Phee et al. (2009) in the
quasi-static limit and against the estimator's profile memory (estimator.sheath), plus its own
physics switches. Tolerances: capstan ratios 2 %, elongation 3 %, profile memory 1 % of the peak
distal tension (stated per test)."""
import math

import numpy as np
import pytest

from estimator.geometry import SheathGeometry
from estimator.sheath import SheathModel, profile_batch
from study.lumped.simulator import Load, LumpedTendon

L, ANGLE, K, EA = 1.5, 2.0 * math.pi, 0.8, 15000.0
MU = K / ANGLE
RATE = 1000.0
M_E = L * (1.0 - math.exp(-K)) / (EA * K)          # Phee et al. 2009, eq. (12)


def uniform() -> SheathGeometry:
    return SheathGeometry.uniform(L, ANGLE)


def ramp(points, rate=RATE):
    """Piecewise-linear command through (time [s], x [m]) corners, sampled at ``rate``."""
    t, x = np.array(points, dtype=float).T
    return np.interp(np.arange(int(round(t[-1] * rate))) / rate, t, x)


def pull_release(geo=None, T_peak=20.0, **kw):
    """Fixed distal end: slow pull to ~T_peak, hold, slow release to ~0."""
    tl = LumpedTendon(geo or uniform(), MU, EA, Load("fixed"), **kw)
    x_peak = T_peak * SheathModel.from_geometry(geo or uniform(), MU, EA).M_e
    return tl.run(ramp([(0, 0), (0.5, 0), (5.5, x_peak), (6.5, x_peak), (11.5, 0), (12, 0)]), RATE)


def test_slow_pull_and_release_follow_the_capstan_law():
    r = pull_release()
    T_in, T_out = r["T_in"], r["T_out"]
    k_peak = int(np.argmax(T_in))
    pull = np.arange(k_peak)[T_in[:k_peak] > 2.0]
    assert np.max(np.abs(T_out[pull] / T_in[pull] / math.exp(-K) - 1)) < 0.02
    rel = np.arange(k_peak, T_in.size)
    rel = rel[(T_in[rel] < 0.95 * T_in[k_peak] * math.exp(-2 * K)) & (T_in[rel] > 1.0)]
    assert rel.size > 100
    assert np.max(np.abs(T_out[rel] / T_in[rel] / math.exp(K) - 1)) < 0.02


def test_reversal_holds_T_out_over_the_2K_band():
    r = pull_release()
    T_in, T_out = r["T_in"], r["T_out"]
    k_peak = int(np.argmax(T_in))
    band = np.arange(k_peak, T_in.size)
    band = band[(T_in[band] < 0.98 * T_in[k_peak]) & (T_in[band] > 1.02 * T_in[k_peak] * math.exp(-2 * K))]
    assert band.size > 100
    assert np.max(np.abs(T_out[band] / T_out[k_peak] - 1)) < 0.01


def test_elongation_at_full_slip_is_M_e_T_in():
    r = pull_release()
    k = np.arange(int(np.argmax(r["T_in"])))
    k = k[r["T_in"][k] > 5.0]
    elongation = r["x_motor"][k] - r["x_end"][k]
    assert np.max(np.abs(elongation / (M_E * r["T_in"][k]) - 1)) < 0.03


def test_return_point_memory_matches_the_profile_memory():
    # 0 -> 20 -> 15 -> 26 -> 3 -> 12 N equivalents (pull-line displacements): a minor loop inside
    # the 2K band, then a full release and a partial re-pull
    x = [M_E * T for T in (0, 20, 15, 26, 3, 12)]
    cmd = ramp([(0, 0), (0.5, x[0]), (4, x[1]), (5, x[1]), (7, x[2]), (8, x[2]), (12, x[3]), (13, x[3]),
                (17, x[4]), (18, x[4]), (20, x[5]), (21, x[5])])
    r = LumpedTendon(uniform(), MU, EA, Load("fixed")).run(cmd, RATE)
    log_gain, w = SheathModel.from_geometry(uniform(), MU, EA).nodes(400)
    T_out, elong, _ = profile_batch(np.zeros(401), log_gain, w, r["T_in"])
    assert np.max(np.abs(T_out - r["T_out"])) < 0.01 * np.max(r["T_out"])
    assert np.max(np.abs(elong - (r["x_motor"] - r["x_end"]))) < 0.01 * np.max(elong)
    # re-pull (8-12 s): T_out stays put until T_in returns to the previous peak (return-point
    # memory), then follows the pull line; a "last reversal" state machine would wait for T_in_min e^{2K}
    t = np.arange(cmd.size) / RATE
    repull = np.flatnonzero((t > 8) & (t < 12))
    T0, T_min = r["T_out"][repull[0]], r["T_in"][repull[0]]
    assert T0 * math.exp(K) == pytest.approx(np.max(r["T_in"][t < 5]), rel=0.01)
    assert T0 * math.exp(K) < 0.6 * T_min * math.exp(2 * K)
    before = repull[r["T_in"][repull] < 0.97 * T0 * math.exp(K)]
    after = repull[r["T_in"][repull] > 1.03 * T0 * math.exp(K)]
    assert before.size > 100 and after.size > 100
    assert np.ptp(r["T_out"][before]) < 0.01 * T0
    assert np.max(np.abs(r["T_out"][after] / r["T_in"][after] / math.exp(-K) - 1)) < 0.02


def test_velocity_friction_creeps_to_the_rest_friction_after_a_fast_pull_stops():
    # a pull at 25 mm/s under c_v = 30 s/m writes a profile 1.75 x steeper than friction at rest holds. The motor
    # stops at once; the tendon slides on: T_in falls and T_out rises until T_out = e^-K T_in, within 0.2 s
    # (docs/concepts/model.md, the simulators: the quasi-static rig holds the steep profile instead)
    tl = LumpedTendon(uniform(), MU, EA, Load("spring", stiffness=2000.0), speed_coefficient=30.0, pretension=2.0,
                      motor_bandwidth_hz=2000.0, motor_max_speed=1.0)
    r = tl.run(ramp([(0, 0), (0.3, 0), (3.3, 6e-3), (3.4, 8.5e-3), (4.4, 8.5e-3)]), RATE)
    T_in, T_out = r["T_in"], r["T_out"]
    stop, end = int(3.4 * RATE) - 1, int(3.6 * RATE)
    ratio = T_out[stop:] / T_in[stop:] / math.exp(-K)
    assert ratio[0] < 0.8                               # the fast pull's profile, steeper than rest friction
    assert np.all(np.abs(ratio[end - stop:] - 1.0) < 0.01)     # crept to the rest friction and held there
    assert T_in[end] < 0.75 * T_in[stop] and T_out[end] > 1.05 * T_out[stop]


def test_route_shape_changes_the_elongation_not_the_capstan_ratio():
    # the same total wrap 2 pi, concentrated near the proximal or near the distal end
    near = SheathGeometry([(0.4, 0.4 / ANGLE), (1.1, math.inf)])
    far = SheathGeometry([(1.1, math.inf), (0.4, 0.4 / ANGLE)])
    M = {}
    for name, geo in (("near", near), ("far", far)):
        r = pull_release(geo)
        k = np.arange(int(np.argmax(r["T_in"])))
        k = k[r["T_in"][k] > 5.0]
        assert np.max(np.abs(r["T_out"][k] / r["T_in"][k] / math.exp(-K) - 1)) < 0.02
        M[name] = float(np.median((r["x_motor"][k] - r["x_end"][k]) / r["T_in"][k]))
        M_e = SheathModel.from_geometry(geo, MU, EA).M_e      # (1/EA) int exp(-mu theta(s)) ds
        assert M[name] == pytest.approx(M_e, rel=0.03)
    assert M["far"] > 1.3 * M["near"]


def test_default_substep_is_converged_on_a_fast_pull():
    geo = SheathGeometry([(0.3, math.inf), (0.4, 0.2), (0.5, math.inf), (0.3, 0.3 / (ANGLE - 2.0))])
    cmd = ramp([(0, 0), (0.05, 0), (0.1, 0.002), (0.2, 0.002)])
    out = [LumpedTendon(geo, MU, EA, Load("constant", preload=2.7), substep_hz=f).run(cmd, RATE)["T_in"]
           for f in (5000.0, 40000.0)]
    assert np.max(out[0]) > 0.95 * 2.7 * math.exp(K)          # the load slides: T_in = P e^K
    # backward Euler is first order: the 40 mm/s start-up transient differs by < 1.5 % of the peak
    assert np.max(np.abs(out[0] - out[1])) < 0.015 * np.max(out[1])


def test_sheath_spring_adds_T_in_over_k_s():
    k_s = 2e5
    r = pull_release(sheath_stiffness=k_s)
    k = r["T_in"] > 1.0
    np.testing.assert_allclose(r["x_motor"][k] - r["x_p"][k], r["T_in"][k] / k_s, rtol=1e-3, atol=1e-9)


def test_loads_hold_their_laws_at_rest():
    x = ramp([(0, 0), (3, 0.004), (4, 0.004)])
    pre = LumpedTendon(uniform(), MU, EA, Load("preloaded", stiffness=1000.0, preload=3.0)).run(x, RATE)
    lifted = pre["T_out"] > 3.2
    assert np.all(pre["x_end"][pre["T_out"] < 2.8] < 1e-5)            # on its stop below the preload
    np.testing.assert_allclose(pre["T_out"][lifted][-1], 3.0 + 1000.0 * pre["x_end"][lifted][-1], rtol=0.01)
    joint = LumpedTendon(uniform(), MU, EA, Load("joint", stiffness=200.0, limit=0.001, stop=5e5)).run(x, RATE)
    assert joint["T_out"][-1] > 1.0
    assert joint["x_end"][-1] == pytest.approx(0.001 + (joint["T_out"][-1] - 0.2) / 5e5, rel=0.01)


def test_bad_arguments_name_the_argument():
    with pytest.raises(ValueError, match="mu"):
        LumpedTendon(uniform(), -0.1, EA)
    with pytest.raises(ValueError, match="EA"):
        LumpedTendon(uniform(), MU, 0.0)
    with pytest.raises(ValueError, match="n_nodes"):
        LumpedTendon(uniform(), MU, EA, n_nodes=2)
    with pytest.raises(ValueError, match="presliding"):
        LumpedTendon(uniform(), MU, EA, presliding=0.0)
    with pytest.raises(ValueError, match="route"):
        LumpedTendon([(1.0, -1.0)], MU, EA)
    with pytest.raises(ValueError, match="load.kind"):
        Load("rubber")
    with pytest.raises(ValueError, match="load.stiffness"):
        Load("spring")
    with pytest.raises(ValueError, match="x_cmd"):
        LumpedTendon(uniform(), MU, EA).run(np.array([0.0, np.nan]), RATE)
    with pytest.raises(ValueError, match="rate_hz"):
        LumpedTendon(uniform(), MU, EA).run(np.zeros(3), 0.0)
