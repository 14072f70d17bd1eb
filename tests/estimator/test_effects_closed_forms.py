"""Each effect of the catalogue against its closed form on a pull and a release. The physical effects change the
friction or the tendon: a friction offset shifts the slip exponent's tension, velocity friction raises the exponent
with the proximal (or the mean of both ends') speed, stiction's Stribeck form holds near-static when slow and
kinetic when fast, a drift of K is linear in time (and the memory continuous in it at zero), stiffening changes the
elongation only, a pretension starts from a uniform profile capped by the rest reading of T_out, pre-sliding rounds
a reversal and a backlash holds x_out. The sensor effects correct an input or model a reading.

Tolerances: closed forms 1e-9 relative unless stated.
"""
import math

import numpy as np
import pytest

from estimator.offline.effects.catalogue import (
    CATALOGUE,
    SPEED_FORM,
    STRIBECK_FORM,
    STRIBECK_SPEED,
    predict,
)
from estimator.offline.effects.kernels import run_extended
from tests.estimator.effects_series import K, _pull, grid, series


def test_friction_offset_closed_form_on_pull_and_release():
    a = 1.5
    T_up = np.linspace(0.0, 15.0, 1500)
    T = np.concatenate((T_up, T_up[::-1][1:]))
    x = np.concatenate((np.linspace(0, 0.005, 1500), np.linspace(0.005, 0, 1500)[1:]))
    pr = CATALOGUE["friction_offset"].predict({"K": K, "a": a}, series(T, x), compliance=1e-4)
    up = T_up > (a * math.expm1(K) + 0.1)             # distal end taut on the pull
    np.testing.assert_allclose(pr.T_out[:1500][up], (T_up[up] + a) * math.exp(-K) - a, rtol=1e-9)
    down = T[1500:] < (15.0 + a) * math.exp(-2 * K) - a - 0.1   # past the transition band
    np.testing.assert_allclose(pr.T_out[1500:][down], (T[1500:][down] + a) * math.exp(K) - a, rtol=1e-9)


def test_velocity_friction_raises_the_slip_exponent_with_speed():
    T_in, x_in = _pull()
    c_v = 20.0
    s = series(T_in, x_in, velocity=np.full(T_in.size, 0.005))
    pr = predict(["velocity_friction"], {"K": K, "c_v": c_v}, s, compliance=1e-4)
    m = T_in > 1.0
    np.testing.assert_allclose(pr.T_out[m], T_in[m] * math.exp(-K * (1 + c_v * 0.005)), rtol=1e-9)


def test_a_pull_that_slows_under_velocity_friction_raises_the_distal_tension_as_its_friction_falls():
    """A slide ended mid-pull (T_in turning back by more than 2 sigma, as a noisy reading can) leaves the profile
    written at the pull's friction K (1 + c_v v). As the pull slows to a stop with T_in held, the friction falls to K
    and the distal tension rises to T_in e^{-K}: the stuck rule checks every node when the friction is below the one
    the profile was written with (the proximal node holds within its bound, the distal ones do not). A constant
    friction keeps the memory of the pull instead."""
    u, w = grid()
    c_v, v0, n_pull, n_slow, n_rest = 20.0, 0.005, 2000, 200, 100
    T_hold = 15.0 - 0.05                                 # the turn that ends the slide: 5 sigma
    T_in = np.concatenate((np.linspace(0.0, 15.0, n_pull), np.full(n_slow + n_rest, T_hold)))
    v = np.concatenate((np.full(n_pull, v0), np.linspace(v0, 0.0, n_slow), np.zeros(n_rest)))
    t = np.arange(1, T_in.size + 1) * 1e-3
    T_out, _ = run_extended(T_in, v, t, u, w, K=K, c_v=c_v, sigma=0.01)
    slowing = T_out[n_pull:n_pull + n_slow]
    assert np.all(np.diff(slowing) >= -1e-12)            # rises (or holds) while the speed falls
    np.testing.assert_allclose(T_out[-1], T_hold * math.exp(-K), rtol=1e-9)
    assert T_out[-1] - T_out[n_pull - 1] > 0.9 * 15.0 * (math.exp(-K) - math.exp(-K * (1 + c_v * v0)))
    T_const, _ = run_extended(T_in, v, t, u, w, K=K, sigma=0.01)
    np.testing.assert_allclose(T_const[-1], 15.0 * math.exp(-K), rtol=1e-9)


def test_velocity_friction_distal_speed_form_uses_the_mean_of_both_ends():
    """The second form (velocity_form 1, needs x_out): the sliding speed is the mean of |dx_in/dt| and
    |dx_out/dt| (per-segment friction on each segment's own speed, between the two ends' speeds)."""
    T_in, x_in = _pull()
    c_v = 20.0
    t = np.arange(1, T_in.size + 1) * 1e-3
    s = series(T_in, x_in, velocity=np.full(T_in.size, 0.005), x_out=0.001 * t)     # distal end at 1 mm/s
    pr = predict(["velocity_friction"], {"K": K, "c_v": c_v, SPEED_FORM: 1.0}, s, compliance=1e-4)
    m = T_in > 1.0
    np.testing.assert_allclose(pr.T_out[m], T_in[m] * math.exp(-K * (1 + c_v * 0.003)), rtol=1e-9)
    assert CATALOGUE["velocity_friction"].variant_ok({SPEED_FORM: 1.0}, ["T_out"]) is False


def test_stiction_stribeck_form_static_when_slow_kinetic_when_fast_and_base_at_zero():
    """Stiction's second form (stiction_form 1): each node's friction K (1 + r_s e^-(v/v_st)^2) by its own
    speed. A slide below v_st (above V_STOP) has the Stribeck bound of its speed, far above v_st the kinetic
    one; on the release after the pull T_out holds until T_in is below it by the proximal nodes' bound:
    near-static when they slip slowly, kinetic when fast. At r_s = 0 it is the base model exactly."""
    u, w = grid()
    r_s, T0, n = 0.4, 4.0, 400
    t = np.arange(2 * n) * 1e-3
    T_in = np.concatenate([np.linspace(0.0, T0, n), T0 * np.exp(-np.linspace(0.0, 3.0 * K, n))])
    out = {}
    for name, speed in (("slow", 0.6 * STRIBECK_SPEED), ("fast", 20 * STRIBECK_SPEED)):
        v = np.concatenate([np.full(n, speed), np.full(n, -speed)])
        out[name] = run_extended(T_in, v, t, u, w, K=K, r_s=r_s, v_st=STRIBECK_SPEED)[0]
        base = run_extended(T_in, v, t, u, w, K=K)
        np.testing.assert_array_equal(run_extended(T_in, v, t, u, w, K=K, r_s=0.0, v_st=STRIBECK_SPEED)[0], base[0])
        # release: at T_in = T_out,top e^-1.15K the slow proximal nodes (bound >= 1.28 K) still hold
        top = out[name][n - 1]
        k = n + int(np.searchsorted(-T_in[n:], -top * math.exp(-1.15 * K)))
        if name == "slow":
            assert out[name][k] == pytest.approx(top, rel=1e-9)
        else:
            assert out[name][k] < top * math.exp(-0.1 * K)
    up = slice(n // 2, n)
    np.testing.assert_allclose(out["slow"][up], T_in[up] * math.exp(-K * (1 + r_s * math.exp(-0.36))), rtol=1e-9)
    np.testing.assert_allclose(out["fast"][up], T_in[up] * math.exp(-K), rtol=1e-9)
    assert CATALOGUE["stiction"].variants[1] == {STRIBECK_FORM: 1.0}
    s = series(T_in, velocity=np.concatenate([np.full(n, 0.6 * STRIBECK_SPEED), np.full(n, -0.6 * STRIBECK_SPEED)]))
    pr = predict(["stiction"], {"K": K, "r_s": r_s, STRIBECK_FORM: 1.0}, s, compliance=1e-4)
    np.testing.assert_allclose(pr.T_out, out["slow"], rtol=1e-9)


def test_curvature_drift_changes_K_linearly_in_time():
    T_in, x_in = _pull()
    s = series(T_in, x_in)
    rate = 0.1
    pr = predict(["curvature_drift"], {"K": K, "K_rate": rate}, s, compliance=1e-4)
    m = T_in > 1.0
    np.testing.assert_allclose(pr.T_out[m], T_in[m] * np.exp(-(K + rate * (s.time[m] - s.time[0]))), rtol=1e-9)


def test_the_memory_is_continuous_in_a_drift_or_step_of_K_at_zero():
    """A node latched on its bound sits there to rounding; the bound computed from a drifting K must not let an ulp
    decide that the slip reached the distal end (NODE_ROUNDING). On this recording it did: K_rate = 0 and 1e-12 gave
    distal tensions 8 mN apart, and the drift's fit started at 0 saw no gradient."""
    from estimator.offline.diagnosis.fit import prepare
    from study.lumped.scenarios import record
    s = prepare(record(("pretension", "curvature_drift"), seed=5860000, level=0.2, duration=60.0).data)
    kw = dict(K=0.7345, slide=s.slide, sigma=s.sigma_T_in, T_min=s.T_min, band=0.01)
    T0, E0 = run_extended(s.T_in, s.velocity, s.time, s.u, s.w, **kw)
    for near in (dict(K_rate=1e-12), dict(K_step=1e-12, t_step=30.0)):
        T1, E1 = run_extended(s.T_in, s.velocity, s.time, s.u, s.w, **kw, **near)
        assert np.max(np.abs(T1 - T0)) < 1e-8 * np.ptp(T0), near
        assert np.max(np.abs(E1 - E0)) < 1e-8 * np.ptp(E0), near


def test_tendon_stiffening_elongation_closed_form_and_T_out_unchanged():
    T_in, x_in = _pull()
    beta, Tc = 3.0, 2.0
    s = series(T_in, x_in)
    pr = predict(["tendon_stiffening"], {"K": K, "beta": beta, "T_c": Tc}, s, compliance=1e-4)
    base = predict([], {"K": K}, s, compliance=1e-4)
    np.testing.assert_array_equal(pr.T_out, base.T_out)
    u = np.linspace(0, 1, 4001)
    for k in (500, 1999):        # e/(L/EA) = int_0^1 phi(T_in e^{-K u}) du, phi(T) = T + beta Tc (1 - e^{-T/Tc})
        prof = T_in[k] * np.exp(-K * u)
        phi = prof + beta * Tc * (1 - np.exp(-prof / Tc))
        expected = np.trapezoid(phi, u)
        assert (x_in[k] - pr.x_out[k]) / 1e-4 == pytest.approx(expected, rel=2e-3)


def test_pretension_starts_from_a_uniform_profile_and_zeroed_positions():
    T0 = 3.0
    T_in = np.concatenate((np.full(200, T0), np.linspace(T0, 12.0, 1000)))
    x_in = np.concatenate((np.zeros(200), np.linspace(0, 0.003, 1000)))
    pr = predict(["pretension"], {"K": K, "T0": T0}, series(T_in, x_in), compliance=1e-4)
    base = predict([], {"K": K}, series(T_in, x_in), compliance=1e-4)
    np.testing.assert_allclose(pr.T_out[:200], T0)          # at rest the distal end carries T0
    np.testing.assert_allclose(pr.x_out[:200], 0.0, atol=1e-15)
    assert base.T_out[0] == pytest.approx(T0 * math.exp(-K)) and base.x_out[0] < -1e-5
    # the first pull moves the distal end only once T_in exceeds T0 e^K
    still = T_in[200:] < T0 * math.exp(K) * 0.999
    np.testing.assert_allclose(pr.T_out[200:][still], T0)


def test_pretension_rest_profile_is_capped_by_the_rest_reading_of_T_out():
    # a load that holds less than the preload: T_out reads 2 N at rest while T_in reads 3 N; the rest profile
    # is T0 capped by the friction band above the distal reading, the distal end carries what the load holds
    T0, T_d = 3.0, 2.0
    T_in = np.concatenate((np.full(200, T0), np.linspace(T0, 12.0, 1000)))
    x_in = np.concatenate((np.zeros(200), np.linspace(0, 0.003, 1000)))
    capped = predict(["pretension"], {"K": K, "T0": T0}, series(T_in, x_in, T_out=np.full(T_in.size, T_d)),
                     compliance=1e-4)
    np.testing.assert_allclose(capped.T_out[:200], T_d)
    np.testing.assert_allclose(capped.x_out[:200], 0.0, atol=1e-15)      # positions zeroed at that rest
    # the first pull reaches the distal end at T_d e^K (not T0 e^K) and moves it less than a uniform T0 would
    uniform = predict(["pretension"], {"K": K, "T0": T0}, series(T_in, x_in), compliance=1e-4)
    moved = capped.T_out[200:] > T_d * 1.001
    assert T_in[200:][moved][0] == pytest.approx(T_d * math.exp(K), rel=0.02)
    assert capped.x_out[-1] != pytest.approx(uniform.x_out[-1], rel=1e-3)
    # a rest reading at or above the preload leaves the uniform profile
    for reading in (T0, 1.5 * T0):
        same = predict(["pretension"], {"K": K, "T0": T0}, series(T_in, x_in, T_out=np.full(T_in.size, reading)),
                       compliance=1e-4)
        np.testing.assert_allclose(same.x_out, uniform.x_out, atol=1e-12)
    # a T_out load cell reading 0.4 N high, fitted with it: the cap uses the true distal tension, not the reading
    offset = predict(["pretension", "sensor_offset:T_out"], {"K": K, "T0": T0, "b_T_out": 0.4},
                     series(T_in, x_in, T_out=np.full(T_in.size, T_d + 0.4)), compliance=1e-4)
    np.testing.assert_allclose(offset.T_out, capped.T_out + 0.4, atol=1e-12)
    np.testing.assert_allclose(offset.x_out, capped.x_out, atol=1e-15)


def test_presliding_rounds_the_reversal_and_backlash_holds_x_out():
    T = np.concatenate((np.linspace(0, 15, 1500), np.linspace(15, 2, 1300)))
    x = np.concatenate((np.linspace(0, 0.005, 1500), np.linspace(0.005, 0.001, 1300)))
    s = series(T, x)
    ref = predict([], {"K": K}, s, compliance=1e-4)
    pr = predict(["presliding"], {"K": K, "x_p": 1e-4}, s, compliance=1e-4)
    flat = slice(1510, 1560)                           # just after the reversal the base T_out stays put
    assert np.ptp(ref.T_out[flat]) < 1e-9 and np.all(np.diff(pr.T_out[flat]) < 0)   # rounded: it already falls
    # far from the corner the friction lags by x_p dF/dx at most: (1 - e^-K) (15 N / 5 mm) x_p
    lag = (1 - math.exp(-K)) * 15.0 / 0.005 * 1e-4
    assert np.max(np.abs(pr.T_out[1000:1400] - ref.T_out[1000:1400])) <= lag * 1.01
    d_b = 2e-4
    bl = predict(["distal_backlash"], {"K": K, "d_b": d_b}, s, compliance=1e-4)
    np.testing.assert_array_equal(bl.T_out, ref.T_out)
    assert np.max(np.abs(bl.x_out - ref.x_out)) <= 0.5 * d_b + 1e-15
    turn = int(np.argmax(ref.x_out))                   # after the tendon end turns, the joint waits for d_b
    still = (ref.x_out[turn:] > ref.x_out[turn] - d_b * 0.999)
    np.testing.assert_allclose(bl.x_out[turn:][still], bl.x_out[turn])


def test_sensor_effects_are_input_corrections():
    T_in, x_in = _pull()
    s = series(T_in + 0.7, x_in)
    shifted = predict(["sensor_offset"], {"K": K, "b_T_in": 0.7}, s, compliance=1e-4)
    np.testing.assert_allclose(shifted.T_out, predict([], {"K": K}, series(T_in, x_in), compliance=1e-4).T_out,
                               rtol=1e-12, atol=1e-12)
    lagged = series(np.interp(np.arange(T_in.size) - 20.0, np.arange(T_in.size), T_in), x_in)  # 20 ms late
    fixed = predict(["sensor_lag:T_in"], {"K": K, "tau_T_in": 0.020}, lagged, compliance=1e-4)
    ref = predict([], {"K": K}, series(T_in, x_in), compliance=1e-4)
    np.testing.assert_allclose(fixed.T_out[30:-30], ref.T_out[30:-30], rtol=1e-9, atol=1e-9)


def test_distal_sensor_effects_are_reading_models():
    T = np.concatenate((np.linspace(0, 15, 1500), np.linspace(15, 2, 1300)))
    x = np.concatenate((np.linspace(0, 0.005, 1500), np.linspace(0.005, 0.001, 1300)))
    s = series(T, x)
    ref = predict([], {"K": K}, s, compliance=1e-4)
    t = s.time
    cases = {"sensor_offset:T_out": (0.3, ref.T_out + 0.3, ref.x_out),
             "sensor_gain:T_out": (0.05, 1.05 * ref.T_out, ref.x_out),
             "sensor_drift:T_out": (0.01, ref.T_out + 0.01 * (t - t[0]), ref.x_out),
             "sensor_lag:T_out": (0.02, np.interp(t - 0.02, t, ref.T_out), ref.x_out),
             "sensor_offset:x_out": (4e-5, ref.T_out, ref.x_out + 4e-5),
             "sensor_lag:x_out": (0.02, ref.T_out, np.interp(t - 0.02, t, ref.x_out)),
             "sensor_offset:x_in": (4e-5, ref.T_out, ref.x_out - 4e-5)}
    for eid, (v, T_exp, x_exp) in cases.items():
        pr = predict([eid], {"K": K, CATALOGUE[eid].parameters[0].name: v}, s, compliance=1e-4)
        np.testing.assert_allclose(pr.T_out, T_exp, rtol=1e-12, atol=1e-12, err_msg=eid)
        np.testing.assert_allclose(pr.x_out, x_exp, rtol=0, atol=1e-12, err_msg=eid)
    # a gain on T_in is a gain 1/(1 + g) - 1 on T_out (the memory is homogeneous), L/EA absorbs it in x_out
    s2 = series(1.05 * T, x, x_out=ref.x_out)
    a = predict(["sensor_gain:T_in"], {"K": K, "g_T_in": 0.05}, s2)
    b = predict(["sensor_gain:T_out"], {"K": K, "g_T_out": 1 / 1.05 - 1}, s2)
    np.testing.assert_allclose(a.T_out, b.T_out, rtol=1e-9)
    np.testing.assert_allclose(a.x_out, b.x_out, atol=1e-12)
