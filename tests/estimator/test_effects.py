"""The effect catalogue and its kernel: identifiers, closed forms, composability, and a cross-check
against the simulated rig (two implementations of the same physics, driven differently).

Tolerances: closed forms 1e-9 relative unless stated; rig cross-checks in N and m, stated per test.
"""
import math

import numpy as np
import pytest

from estimator.offline.effects import catalogue as effects_module
from estimator.offline.effects.catalogue import (
    CATALOGUE,
    EFFECT_IDS,
    NOISE_BAND,
    PRESLIDING_MIN,
    SPEED_FORM,
    STRIBECK_FORM,
    STRIBECK_SPEED,
    below_resolution,
    effect,
    neutral_values,
    predict,
)
from estimator.offline.effects.kernels import distal_slide, run_extended
from estimator.offline.effects.predict import SLACK_HELD, SLACK_SIGMAS, SLACK_TAUT, SLACK_WINDOW, slack_hold
from estimator.offline.effects.presliding_kernel import NODE_FORM
from estimator.offline.effects.types import (
    ROUTE_FINE,
    ROUTE_FORMS,
    ROUTE_TWELFTHS,
    Series,
    finer_route,
    route_shape,
    route_values,
)
from estimator.online.distal import estimate_batch
from estimator.sheath import SheathGeometry, SheathModel
from slave.simulated import SimulatedRig
from study.scenarios import protocol
from teleop.config.effects import EffectsConfig, EffectSwitch
from teleop.config.schema import LoadConfig, RunConfig, SensorConfig, SheathConfig, SimulatedRigConfig

IDS = ("velocity_friction", "pretension", "curvature_drift", "tendon_stiffening", "stiction", "friction_offset",
       "presliding", "distal_backlash",
       "sensor_offset:T_in", "sensor_offset:T_out", "sensor_gain:T_in", "sensor_gain:T_out", "sensor_lag:T_in",
       "sensor_lag:T_out", "sensor_drift:T_in", "sensor_drift:T_out", "sensor_offset:x_in", "sensor_offset:x_out",
       "sensor_lag:x_in", "sensor_lag:x_out", "friction_step")
K, L, EA = 0.7, 1.5, 15000.0
NODES = 32


def grid(m=NODES):
    shape, weight = SheathModel(K=1.0, compliance=1.0).nodes(m)
    return shape, weight


def series(T_in, x_in=None, dt=1e-3, velocity=None, T_out=None, x_out=None):
    T_in = np.asarray(T_in, dtype=float)
    t = np.arange(1, T_in.size + 1) * dt
    x_in = np.zeros_like(T_in) if x_in is None else np.asarray(x_in, dtype=float)
    v = np.gradient(x_in, t) if velocity is None else np.asarray(velocity, dtype=float)
    u, w = grid()
    return Series(t, x_in, T_in, v, T_out, x_out, u, w)


def test_catalogue_ids_parameters_and_texts():
    assert EFFECT_IDS == IDS
    for eid, e in CATALOGUE.items():
        assert e.id == eid and len(e.cause) > 20 and len(e.signature) > 20 and e.literature.startswith("E")
        assert len(e.extension) > 10 and type(e).__name__ != "Effect"   # one class per effect
        assert e.primary in ("T_out", "x_out") and e.parameters
        for p in e.parameters:
            # the neutral value (off) inside the fitted range, except a pre-sliding travel: 0 is off, and the fit
            # starts at PRESLIDING_MIN (a travel below it is under the floor of x_out)
            inside = p.lower <= p.neutral <= p.upper or (eid == "presliding" and p.neutral == 0.0 < p.lower)
            assert inside and p.unit and p.meaning
            assert all(p.lower <= s <= p.upper for s in p.starts)
        d = e.describe()
        assert d["id"] == eid and all("unit" in q and len(q["bounds"]) == 2 for q in d["parameters"])
    assert effect("stiction") is CATALOGUE["stiction"]
    assert effect("sensor_delay") is CATALOGUE["sensor_lag:T_in"]          # former ids
    for eid in IDS[8:-1]:                                                  # sensor ids name their channel
        e = CATALOGUE[eid]
        assert e.channel == eid.split(":")[1] and e.parameters[0].name.endswith(e.channel)
    with pytest.raises(KeyError, match="known: velocity_friction"):
        effect("backlash")


def _history(n=6000, seed=0):
    rng = np.random.default_rng(seed)
    knots = np.concatenate(([0.0], rng.uniform(0.5, 20.0, 30)))
    return np.interp(np.linspace(0, knots.size - 1, n), np.arange(knots.size), knots)


def test_base_kernel_is_the_profile_memory_estimator():
    T_in = _history()
    T_out, E1 = run_extended(T_in, np.zeros_like(T_in), np.arange(T_in.size) * 1e-3, *grid(100), K=K)
    ref = estimate_batch(T_in, np.zeros_like(T_in), SheathModel(K=K, compliance=1.0), n_nodes=100)
    np.testing.assert_allclose(T_out, ref.T_out, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(E1, ref.elongation, rtol=1e-9, atol=1e-12)


def test_noise_band_keeps_the_memory_from_latching_the_noise_extremes():
    """A pull to 10 N then a 10 s hold read with 50 mN of white noise: the memory rule latches the noise's
    largest excursion (T_out biased by about 3 sigma e^-K), the noise band h takes h e^-K of it off."""
    u, w = grid()
    true = np.concatenate([np.linspace(1.0, 10.0, 400), np.full(2000, 10.0)])
    t = np.arange(true.size) * 5e-3
    sigma, hold = 0.05, slice(600, None)
    noisy = true + sigma * np.random.default_rng(0).standard_normal(true.size)
    ref = run_extended(true, np.zeros_like(true), t, u, w, K=K)[0]
    scale = sigma * math.exp(-K)
    bias = {b: float(np.mean(run_extended(noisy, np.zeros_like(true), t, u, w, K=K, band=b * sigma)[0][hold]
                             - ref[hold])) / scale for b in (0.0, NOISE_BAND)}
    assert bias[0.0] > 2.0, bias
    assert bias[NOISE_BAND] == pytest.approx(bias[0.0] - NOISE_BAND, abs=0.05), bias
    # and on exact data the band is a dead zone: the hold sits h e^-K below the exact memory
    exact = run_extended(true, np.zeros_like(true), t, u, w, K=K, band=NOISE_BAND * sigma)[0]
    np.testing.assert_allclose(exact[hold], ref[hold] - NOISE_BAND * scale, rtol=1e-9)
    with pytest.raises(ValueError, match="band"):
        run_extended(true, np.zeros_like(true), t, u, w, K=K, band=-0.01)


def test_distal_slide_reads_motion_beyond_the_resolution_only():
    rng = np.random.default_rng(3)
    x = np.concatenate([np.zeros(200), np.linspace(0.0, 1e-3, 300), np.full(200, 1e-3), np.linspace(1e-3, 0.0, 300)])
    d = distal_slide(x + 2e-7 * rng.standard_normal(x.size), 2e-6, 5)
    assert not d[:200].any() and not d[505:700].any()          # rest and hold: noise (0.2 um) under 2 um
    assert (d[220:500] == 1).mean() > 0.9 and (d[720:1000] == -1).mean() > 0.9
    assert not (d[:500] == -1).any() and not (d[700:] == 1).any()
    with pytest.raises(ValueError, match="travel"):
        distal_slide(x, 0.0)
    with pytest.raises(ValueError, match="window"):
        distal_slide(x, 1e-6, 0)


def test_a_distal_end_seen_moving_makes_the_whole_tendon_slide():
    """A constant-force load F: the true release sits at T_in = F e^-K, on the
    edge of the band. With a K that is too large (here 0.9 for a true 0.7) the memory alone holds the pulled
    T_out there (T_in stays inside its band) and matches the constant F whatever K is; the measured distal end
    moving with the proximal one says the tendon slides, and the model's T_out is then T_in e^{K} - wrong for a
    wrong K, which is what lets the fit find K from the release too."""
    u, w = grid()
    F, K_true, K_fit = 5.0, 0.7, 0.9
    T_in = np.concatenate([np.linspace(0.5, F * math.exp(K_true), 300), np.full(500, F * math.exp(K_true)),
                           np.linspace(F * math.exp(K_true), F * math.exp(-K_true), 100),
                           np.full(500, F * math.exp(-K_true))])
    x_in = np.concatenate([np.linspace(0.0, 1e-3, 300), np.linspace(1e-3, 6e-3, 500), np.full(100, 6e-3),
                           np.linspace(6e-3, 1e-3, 500)])
    t = np.arange(T_in.size) * 5e-3
    v = np.gradient(x_in, t)
    slide = np.sign(v).astype(np.int8)           # the distal end moves with the proximal one
    slide[800:900] = 0                           # and holds while the proximal tension falls through the band
    held = run_extended(T_in, v, t, u, w, K=K_fit)[0]
    seen = run_extended(T_in, v, t, u, w, K=K_fit, slide=slide)[0]
    release = slice(950, None)
    np.testing.assert_allclose(held[release], F * math.exp(K_true - K_fit), rtol=1e-9)    # the pulled T_out held
    np.testing.assert_allclose(seen[release], F * math.exp(K_fit - K_true), rtol=1e-9)    # full slip at T_in e^K
    # with the right K both agree with the load: the reading of x_out changes nothing there
    np.testing.assert_allclose(run_extended(T_in, v, t, u, w, K=K_true, slide=slide)[0][release], F, rtol=1e-9)
    # a T_in that turns back while the distal end is still seen moving (the averaged T_in turns before the distal
    # end stops at a reversal) ends the slide and starts none: T_out held at the pulled value, as without x_out
    # (a slide restarted there as a breakaway would put T_out low through the reversal)
    turn = np.concatenate([np.linspace(0.5, 10.0, 300), np.linspace(10.0, 8.0, 20)])
    xt = np.linspace(0.0, 2e-3, turn.size)                                   # the proximal end still pulling
    tt = np.arange(turn.size) * 5e-3
    vt = np.gradient(xt, tt)
    up = np.ones(turn.size, dtype=np.int8)
    for r_s in (0.0, 0.3):
        alone = run_extended(turn, vt, tt, u, w, K=K_fit, r_s=r_s, sigma=0.01)[0]
        seen_t = run_extended(turn, vt, tt, u, w, K=K_fit, r_s=r_s, sigma=0.01, slide=up)[0]
        np.testing.assert_array_equal(seen_t[300:], alone[300:])
        assert np.ptp(seen_t[301:]) == 0.0                                   # held through the turn
    # no motion seen, or motion against the proximal end's: the memory alone
    np.testing.assert_array_equal(run_extended(T_in, v, t, u, w, K=K_fit, slide=np.zeros_like(slide))[0], held)
    np.testing.assert_array_equal(run_extended(T_in, v, t, u, w, K=K_fit, slide=-slide)[0], held)


@pytest.mark.parametrize("eid", IDS)
def test_every_extension_at_its_neutral_values_is_the_base(eid):
    s = series(_history(3000, 1), x_in=np.linspace(0, 0.004, 3000))
    base = predict([], {"K": K}, s, compliance=1e-4)
    ext = predict([eid], {"K": K, **neutral_values([effect(eid)])}, s, compliance=1e-4)
    np.testing.assert_allclose(ext.T_out, base.T_out, rtol=0, atol=1e-12)
    np.testing.assert_allclose(ext.x_out, base.x_out, rtol=0, atol=1e-15)


def _pull(T_max=15.0, n=2000):
    """A monotone pull from 0 with the proximal end moving at a constant 5 mm/s."""
    T_in = np.linspace(0.0, T_max, n)
    x_in = np.linspace(0.0, 0.005 * n * 1e-3, n)
    return T_in, x_in


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


def test_a_slack_tendon_holds_the_distal_end_while_the_proximal_end_moves_on(monkeypatch):
    # exact tensions: no noise band (NOISE_BAND, a dead zone of 3 sigma on a reading), only the slack rule's sigma
    monkeypatch.setattr(effects_module, "NOISE_BAND", 0.0)
    # pull, release to zero tension while the proximal end goes on back (the tendon goes slack), pull again
    T = np.concatenate((np.linspace(0, 10, 1000), np.linspace(10, 0, 1000), np.zeros(500), np.linspace(0, 10, 1000)))
    x = np.concatenate((np.linspace(0, 3e-3, 1000), np.linspace(3e-3, 1e-3, 1000), np.linspace(1e-3, -1e-3, 500),
                        np.linspace(-1e-3, 2e-3, 1000)))
    sigma = 0.01
    s = series(T, x)
    s = Series(s.time, s.x_in, s.T_in, s.velocity, None, None, s.u, s.w, 0.0, sigma)
    pr = predict([], {"K": K}, s, compliance=1e-4)
    taut = T >= SLACK_SIGMAS * sigma
    last = int(np.flatnonzero(taut[:2500])[-1])
    np.testing.assert_allclose(pr.x_out[last:2500], pr.x_out[last])       # held where the tendon went slack
    assert abs(pr.x_out[last] - x[last]) < 1e-5 < np.ptp(x[last:2500])      # while the proximal end moved 2 mm
    # taut again (the tension held for SLACK_WINDOW samples: this pull rises before the proximal end is back
    # where it went slack): x_out = x_in - (L/EA) E1 as without slack; noiseless data (sigma 0) are never held
    free = predict([], {"K": K}, series(T, x), compliance=1e-4)
    again = 2500 + int(np.flatnonzero(taut[2500:])[0])
    np.testing.assert_allclose(pr.x_out[again - 1:again + 1], pr.x_out[last])
    settled = taut.copy()
    settled[again:again + SLACK_WINDOW - 1] = False
    np.testing.assert_allclose(pr.x_out[settled], free.x_out[settled], atol=1e-15)
    assert np.ptp(free.x_out[last:2500]) > 1e-3
    np.testing.assert_array_equal(slack_hold(T, 0.0), np.arange(T.size))
    np.testing.assert_array_equal(slack_hold(T, 0.0, x), np.arange(T.size))


def test_a_noise_sample_does_not_end_a_slack_phase_a_held_tension_does():
    # in a slack phase (T_in at zero) one sample of noise above the threshold does not put the distal end back on
    # x_in: the slack ends when the proximal end is back where it went slack, when the tension is held above the
    # threshold, or at SLACK_TAUT x the threshold
    thr = 0.03
    n = 400
    T = np.concatenate((np.full(100, 1.0), np.zeros(n)))
    x = np.concatenate((np.full(100, 2e-3), np.linspace(2e-3, 0.0, n)))      # the proximal end pays out
    blip = T.copy()
    blip[300] = 1.2 * thr
    idx = slack_hold(blip, thr, x)
    assert np.all(idx[100:] == 99)                                           # held through the blip
    assert slack_hold(blip, thr)[300] == 300                                 # (by T_in alone it was not)
    strong = T.copy()
    strong[300] = 1.01 * SLACK_TAUT * thr
    assert slack_hold(strong, thr, x)[300] == 300                            # a tension the noise cannot give
    held = T.copy()
    held[300:] = 1.5 * thr                                                   # a taut tendon at low tension
    idx = slack_hold(held, thr, x)
    assert idx[300] == 99 and idx[300 + SLACK_WINDOW - 1] == 300 + SLACK_WINDOW - 1
    back = np.concatenate((T, np.full(50, 0.5 * thr), np.full(10, 1.2 * thr)))
    xb = np.concatenate((x, np.linspace(0.0, 2.5e-3, 50), np.full(10, 2.5e-3)))   # proximal end back past 2 mm
    assert slack_hold(back, thr, xb)[550] == 550


def test_a_tendon_released_against_a_weak_load_stays_taut_under_the_threshold():
    # a 125 N/m joint released at K 1.4 pulls the tendon back at T_in = T_out e^-K, 1-3 sigma of the reading; by
    # the sample alone every sample under the 3 sigma threshold would be slack. Held above zero on both sides, it
    # is taut; a drop to zero is slack at once
    rng = np.random.default_rng(3)
    thr = 0.03                                                               # SLACK_SIGMAS sigma
    sigma = thr / SLACK_SIGMAS
    low = 0.8 * thr + sigma * rng.standard_normal(300)                       # taut, mostly below thr
    assert np.mean(low < thr) > 0.6
    T = np.concatenate((np.full(100, 1.0), low, sigma * rng.standard_normal(300)))
    x = np.concatenate((np.full(100, 3e-3), np.linspace(3e-3, 1e-3, 300), np.linspace(1e-3, 0.0, 300)))
    idx = slack_hold(T, thr, x)
    k = np.arange(100, 400 - SLACK_HELD)
    np.testing.assert_array_equal(idx[k], k)                                 # taut through the release
    assert 400 - SLACK_HELD <= idx[400] < 400 and np.all(idx[400:] == idx[400])   # slack from the drop on
    old = np.flatnonzero(low < thr)[0] + 100                                 # by the sample alone: slack at the
    assert slack_hold(T, thr)[old] < old                                     # first dip


def test_a_tendon_whose_distal_end_is_carried_along_is_taut_at_any_tension():
    # a 97 N/m joint released to 0.85 mm keeps the tendon taut at T_out 0.08 N, so T_in = T_out e^-1.43 = 0.012 N,
    # 0.4 sigma of its load cell: no rule on T_in tells that from a slack tendon. The distal end moving the way the
    # proximal end does says the tendon carries the motion: taut
    thr = 0.03
    n = 300
    T = np.concatenate((np.full(100, 1.0), np.full(n, 0.13 * thr)))          # 0.4 sigma
    x = np.concatenate((np.full(100, 2e-3), np.linspace(2e-3, 1e-3, n)))
    assert np.all(slack_hold(T, thr, x)[100:] == 99)                          # held slack by T_in alone
    moving = np.zeros(T.size, dtype=bool)
    moving[100:] = True
    k = np.arange(100, 100 + n)
    np.testing.assert_array_equal(slack_hold(T, thr, x, moving)[k], k)       # taut while carried along
    moving[250:] = False                                                     # the distal end stops: slack again
    idx = slack_hold(T, thr, x, moving)
    assert idx[249] == 249 and np.all(idx[250:] == 249)


def test_compliance_is_fitted_by_linear_least_squares():
    T_in, x_in = _pull()
    s = series(T_in, x_in)
    truth = predict([], {"K": K}, s, compliance=1.234e-4)
    s2 = Series(s.time, s.x_in, s.T_in, s.velocity, None, truth.x_out, s.u, s.w)
    assert predict([], {"K": K}, s2).compliance == pytest.approx(1.234e-4, rel=1e-9)


# ---- cross-check: the rig's physics (driven by x_in) against the kernel (driven by the rig's T_in) --

RIG_CASES = {   # rig switch, kernel values, rms tolerance on T_out [N] and on x_out [m]
    "velocity_friction": (EffectSwitch(True, viscous=20.0), {"c_v": 20.0}, 0.02, 6e-6),
    "curvature_drift": (EffectSwitch(True, rate=0.01), {"K_rate": 0.01}, 1e-4, 1e-7),
    "tendon_stiffening": (EffectSwitch(True, softening=2.0, toe_tension=2.0), {"beta": 2.0, "T_c": 2.0}, 1e-9, 1e-7),
    "stiction": (EffectSwitch(True, static_ratio=0.4), {"r_s": 0.4}, 1e-6, 1e-7),
    "friction_offset": (EffectSwitch(True, tension_offset=1.0), {"a": 1.0}, 1e-6, 1e-7),
    # the rig solves the pre-sliding lag exactly over a step with the memory's friction linear in it, the kernel
    # holds it at the step's end: they differ by about half a step's change of the friction, ~10 mN
    "presliding": (EffectSwitch(True, distance=1e-4), {"x_p": 1e-4}, 0.02, 1e-7),
    "distal_backlash": (EffectSwitch(True, width=2e-4), {"d_b": 2e-4}, 1e-6, 1e-7),
}


@pytest.mark.parametrize("eid", sorted(RIG_CASES))
def test_extension_reproduces_the_rig_with_the_same_effect(eid, monkeypatch):
    """The rig (displacement-driven, 100 elements) and the kernel (driven by the rig's T_in, 32 nodes)
    agree to round-off for the rate-independent effects; viscous friction differs by the speed the
    kernel sees (the differenced encoder instead of the motor's step) - a few mN and um. The rig's
    tensions are exact: no noise band (NOISE_BAND is for a noisy reading; sigma_T_in is the breakaway's)."""
    monkeypatch.setattr(effects_module, "NOISE_BAND", 0.0)
    sub, values, tol_T, tol_x = RIG_CASES[eid]
    geo = SheathGeometry.uniform(L, 2 * math.pi)
    sheath = SheathConfig(EA=EA, runs=tuple(RunConfig(r.length, r.radius) for r in geo.runs))
    rig = SimulatedRig(sheath, SimulatedRigConfig(n_elements=100, mu=K / (2 * math.pi),
                                                    effects=EffectsConfig(**{eid: sub}),
                                                    sensors=SensorConfig(load_cell_noise=0.0),
                                                    load=LoadConfig(joint_limit=0.05, tissue_stiffness=2000.0)))
    rest = 0.0012 if eid == "friction_offset" else 0.0002        # taut at rest
    cmd = rig.state.truth.x_in + protocol(20.0, 1000.0, 0.006, np.random.default_rng(3), rest)
    tr = [rig.step(float(x), 1e-3).truth for x in cmd]
    T_in = np.array([t.T_in for t in tr])
    x_in = np.array([t.x_in for t in tr]) - tr[0].x_in
    x_out = np.array([t.x_out for t in tr]) - tr[0].x_out
    T_out = np.array([t.T_out for t in tr])
    v = np.diff(np.concatenate(([0.0], x_in))) / 1e-3
    s = series(T_in, x_in, velocity=v)
    s = Series(s.time, s.x_in, s.T_in, s.velocity, None, None, s.u, s.w, T_min=0.0, sigma_T_in=1e-3)
    ext = predict([eid], {"K": K, **values}, s, compliance=L / EA)
    base = predict([], {"K": K}, s, compliance=L / EA)
    rms = lambda e: float(np.sqrt(np.mean(e ** 2)))  # noqa: E731
    off = ext.x_out[0] - x_out[0]
    assert rms(ext.T_out - T_out) < tol_T
    assert rms(ext.x_out - off - x_out) < tol_x
    if eid not in ("tendon_stiffening", "distal_backlash"):   # they leave T_out alone
        assert rms(base.T_out - T_out) > 5 * rms(ext.T_out - T_out)
    else:
        assert rms(base.x_out - x_out) > 20 * rms(ext.x_out - off - x_out)


def test_presliding_fit_keeps_a_travel_the_sensors_resolve():
    # a base-model recording (no pre-sliding) with x_out: the per-node form, started at 1 um, may not go below
    # PRESLIDING_MIN, where it would differ from the base model only by driving the distal end on the measured x_out
    from estimator.offline.diagnosis.fit import fit_model
    T = np.concatenate((np.linspace(0, 15, 600), np.linspace(15, 2, 500), np.linspace(2, 12, 500)))
    x = np.concatenate((np.linspace(0, 0.005, 600), np.linspace(0.005, 0.001, 500), np.linspace(0.001, 0.004, 500)))
    s0 = series(T, x)
    ref = predict([], {"K": K}, s0, compliance=1e-4)
    s = series(T, x, T_out=ref.T_out, x_out=ref.x_out)
    assert 0.0 < PRESLIDING_MIN <= 0.5 * CATALOGUE["presliding"].knob.ranges[0][1]
    vals, _, _ = fit_model([CATALOGUE["presliding"]], s, [{"K": K, "x_p": 1e-6, NODE_FORM: 1.0}], max_starts=1)
    assert PRESLIDING_MIN <= vals["x_p"] < 1e-3 and vals[NODE_FORM] == 1.0


def test_a_fit_at_the_smallest_resolvable_magnitude_is_below_resolution():
    # pre-sliding at PRESLIDING_MIN (the fit's lower bound, above the neutral 0) does not count as pre-sliding;
    # a travel in its realistic range does, and effects whose range starts at their neutral value never are
    pre = [CATALOGUE["presliding"]]
    assert below_resolution(pre, {"x_p": PRESLIDING_MIN}) and below_resolution(pre, {"x_p": 1.02 * PRESLIDING_MIN})
    assert not below_resolution(pre, {"x_p": 40e-6}) and not below_resolution(pre, {})
    assert not below_resolution([CATALOGUE["velocity_friction"], CATALOGUE["stiction"]], {"c_v": 0.0, "r_s": 0.0})


def test_the_finer_route_holds_the_thirds_as_a_special_case():
    # sixths from thirds (each third's share split over its two sixths) give the same wrap shape
    for r1, r2 in ((1 / 3, 0.5), (0.05, 0.95), (0.7, 0.0), (0.0, 0.0)):
        fine = finer_route({"r_1": r1, "r_2": r2})
        assert set(fine) == {p.name for p in ROUTE_FINE} and all(0.0 <= v <= 1.0 for v in fine.values())
        coarse = route_shape(61, r1, r2)
        sixths = route_shape(61, *(fine[p.name] for p in ROUTE_FINE))
        np.testing.assert_allclose(sixths, coarse, atol=1e-12)
    # the neutral sixths are the uniform route; a share of 1 puts the whole wrap in that sixth
    np.testing.assert_allclose(route_shape(13, *(p.neutral for p in ROUTE_FINE)), np.linspace(0, 1, 13), atol=1e-12)
    u = route_shape(61, 0.0, 0.0, 1.0, 0.5, 0.5)
    assert u[20] == pytest.approx(0.0) and u[30] == pytest.approx(1.0) and u[-1] == pytest.approx(1.0)


def test_the_twelfths_hold_the_sixths_and_the_thirds_as_special_cases():
    # each sixth's share split over its two twelfths (and the thirds through them) gives the same wrap shape
    for sixths in ((0.0, 0.247, 0.2, 0.253, 1.0), (1 / 6, 0.2, 0.25, 1 / 3, 0.5), (0.9, 0.0, 0.5, 0.0, 0.3)):
        fine = finer_route(dict(zip(("r_1", "r_2", "r_3", "r_4", "r_5"), sixths, strict=False)), ROUTE_TWELFTHS)
        assert list(fine) == [p.name for p in ROUTE_TWELFTHS] and all(0.0 <= v <= 1.0 for v in fine.values())
        np.testing.assert_allclose(route_shape(121, *route_values(fine)), route_shape(121, *sixths), atol=1e-12)
    thirds = {"r_1": 0.05, "r_2": 0.95}
    np.testing.assert_allclose(route_shape(121, *route_values(finer_route(thirds, ROUTE_TWELFTHS))),
                               route_shape(121, 0.05, 0.95), atol=1e-12)
    np.testing.assert_allclose(route_shape(25, *(p.neutral for p in ROUTE_TWELFTHS)), np.linspace(0, 1, 25), atol=1e-12)
    # route_values reads the shares in order; r_2 is neutral when only r_1 is given; none without a route
    assert route_values({"K": 1.0, "r_2": 0.4, "r_1": 0.2}) == (0.2, 0.4)
    assert route_values({"r_1": 0.2}) == (0.2, 0.5) and route_values({"K": 1.0}) == ()
    assert set(ROUTE_FORMS) == {"thirds", "fine", "twelfths"} and len(ROUTE_FORMS["twelfths"]) == 11
