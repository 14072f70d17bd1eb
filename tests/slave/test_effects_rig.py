"""The simulated rig's effect switches against closed forms (relative 1 % unless stated)."""
import math

import numpy as np
import pytest

from estimator.geometry import SheathGeometry
from slave.simulated import SimulatedRig
from slave.simulated_effects import EFFECT_IDS
from study.scenarios import realistic_range, record
from teleop.config.effects import EffectsConfig, EffectSwitch
from teleop.config.schema import LoadConfig, MotorConfig, RunConfig, SensorConfig, SheathConfig, SimulatedRigConfig

L, ANGLE, MU, EA = 1.5, 2.0 * math.pi, 0.1, 15000.0
K = MU * ANGLE
DT = 1e-3
FAST = MotorConfig(bandwidth_hz=1e6, max_speed=10.0)
SPRING = LoadConfig(joint_stiffness=100.0, joint_limit=0.1, tissue_stiffness=2000.0, tissue=True)


def make_rig(fx: EffectsConfig, noise=0.0, motor=FAST, pretension=0.0) -> SimulatedRig:
    g = SheathGeometry.uniform(L, ANGLE)
    sheath = SheathConfig(EA=EA, runs=tuple(RunConfig(r.length, r.radius) for r in g.runs), pretension=pretension)
    return SimulatedRig(sheath, SimulatedRigConfig(n_elements=200, mu=MU, motor=motor, load=SPRING, effects=fx,
                                                     sensors=SensorConfig(load_cell_noise=noise, seed=1)))


def drive(rig, xs):
    states = [rig.step(float(x), DT) for x in xs]
    tr = {k: np.array([getattr(s.truth, k) for s in states]) for k in ("T_in", "T_out", "x_in", "x_out", "elongation")}
    tr["reading"] = np.array([s.T_in for s in states])
    return tr


def ramp(a, b, speed):
    n = max(2, int(abs(b - a) / (speed * DT)) + 1)
    return np.linspace(a, b, n)[1:]


def test_effects_are_off_by_default_and_listed_when_on():
    assert make_rig(EffectsConfig()).effects == ()
    fx = EffectsConfig(stiction=EffectSwitch(enabled=True), sensor_delay=EffectSwitch(enabled=True))
    assert make_rig(fx).effects == ("stiction", "sensor_delay")
    assert EFFECT_IDS == ("velocity_friction", "pretension", "curvature_drift", "tendon_stiffening", "stiction",
                          "friction_offset", "presliding", "distal_backlash", "sensor_offset", "sensor_gain",
                          "sensor_delay", "sensor_drift", "encoder_offset", "friction_step")


def test_bad_effect_magnitude_names_the_key():
    with pytest.raises(ValueError, match=r"rig\.simulated\.effects\.stiction\.static_ratio"):
        make_rig(EffectsConfig(stiction=EffectSwitch(True, static_ratio=-0.1)))
    with pytest.raises(ValueError, match=r"rig\.simulated\.effects\.sensor_delay\.delay"):
        make_rig(EffectsConfig(sensor_delay=EffectSwitch(True, delay=math.nan)))
    for key, setting, bad in (("sensor_gain", "gain", -0.6), ("sensor_drift", "rate", 0.2),
                              ("encoder_offset", "offset", 0.01), ("presliding", "distance", 0.0),
                              ("distal_backlash", "width", -1e-4)):
        with pytest.raises(ValueError, match=rf"rig\.simulated\.effects\.{key}\.{setting} must be"):
            make_rig(EffectsConfig(**{key: EffectSwitch(True, **{setting: bad})}))


@pytest.mark.parametrize("speed", [0.002, 0.02])
def test_velocity_friction_slip_ratio_grows_with_speed(speed):
    c_v = 20.0
    tr = drive(make_rig(EffectsConfig(velocity_friction=EffectSwitch(True, viscous=c_v))), ramp(0, 0.006, speed))
    m = tr["T_in"] > 1.0
    np.testing.assert_allclose(tr["T_out"][m] / tr["T_in"][m], math.exp(-K * (1 + c_v * speed)), rtol=0.01)


def test_curvature_drift_changes_K_with_time():
    rate = 0.02
    rig = make_rig(EffectsConfig(curvature_drift=EffectSwitch(True, rate=rate)))
    drive(rig, np.zeros(10000))                     # 10 s at rest
    tr = drive(rig, ramp(0, 0.006, 0.01))
    t = 10.0 + DT * np.arange(1, tr["T_in"].size + 1)
    m = tr["T_in"] > 1.0
    np.testing.assert_allclose(tr["T_out"][m] / tr["T_in"][m], np.exp(-(K + rate * t[m])), rtol=0.01)


def test_friction_step_changes_K_at_its_instant_and_keeps_it():
    change, at = -0.2, 10.0
    rig = make_rig(EffectsConfig(friction_step=EffectSwitch(True, change=change, time=at)))
    before = drive(rig, ramp(0, 0.006, 0.01))        # pulled before the instant: K
    m = before["T_in"] > 1.0
    np.testing.assert_allclose(before["T_out"][m] / before["T_in"][m], math.exp(-K), rtol=0.01)
    drive(rig, ramp(0.006, 0.0, 0.01))
    drive(rig, np.zeros(10000))                     # past the instant at rest
    after = drive(rig, ramp(0, 0.006, 0.01))
    m = after["T_in"] > 1.0
    np.testing.assert_allclose(after["T_out"][m] / after["T_in"][m], math.exp(-(K + change)), rtol=0.01)


def test_friction_offset_pull_and_release_lines():
    a = 1.0
    rig = make_rig(EffectsConfig(friction_offset=EffectSwitch(True, tension_offset=a)))
    up = drive(rig, ramp(0, 0.007, 0.005))
    m = up["T_out"] > 0.5
    np.testing.assert_allclose(up["T_out"][m], (up["T_in"][m] + a) * math.exp(-K) - a, rtol=0.01)
    T0 = up["T_in"][-1]
    dn = drive(rig, ramp(0.007, 0.003, 0.005))
    m = dn["T_in"] < (T0 + a) * math.exp(-2 * K) - a - 0.2
    assert m.sum() > 100
    np.testing.assert_allclose(dn["T_out"][m], (dn["T_in"][m] + a) * math.exp(K) - a, rtol=0.01)
    # friction that does not vanish with tension: T_in - T_out > (1 - e^-K) T_in on the pull
    p = up["T_out"] > 0.5
    assert np.all(up["T_in"][p] - up["T_out"][p] > (1 - math.exp(-K)) * up["T_in"][p] + 0.5 * a * (1 - math.exp(-K)))


def test_tendon_stiffening_elongation_and_unchanged_T_out():
    beta, Tc = 3.0, 2.0
    tr = drive(make_rig(EffectsConfig(tendon_stiffening=EffectSwitch(True, softening=beta, toe_tension=Tc))),
               ramp(0, 0.006, 0.005))
    base = drive(make_rig(EffectsConfig()), ramp(0, 0.006, 0.005))
    u = np.linspace(0, 1, 2001)
    for k in (200, tr["T_in"].size - 1):
        prof = tr["T_in"][k] * np.exp(-K * u)
        phi = prof + beta * Tc * (1 - np.exp(-prof / Tc))
        assert tr["x_in"][k] - tr["x_out"][k] == pytest.approx(L / EA * np.trapezoid(phi, u), rel=0.01)
    m = tr["T_in"] > 0.5
    np.testing.assert_allclose(tr["T_out"][m] / tr["T_in"][m], math.exp(-K), rtol=1e-6)
    # the soft toe adds at most softening * T_c L/EA of elongation (all of it once T >> T_c everywhere)
    e_base = np.interp(tr["T_in"][-1], base["T_in"], base["x_in"] - base["x_out"])
    extra = (tr["x_in"][-1] - tr["x_out"][-1]) - e_base
    prof = tr["T_in"][-1] * np.exp(-K * u)
    assert extra == pytest.approx(beta * Tc * L / EA * np.trapezoid(1 - np.exp(-prof / Tc), u), rel=0.01)
    assert 0.5 * beta * Tc * L / EA < extra < beta * Tc * L / EA


def test_stiction_breakaway_after_a_hold():
    r_s = 0.5
    rig = make_rig(EffectsConfig(stiction=EffectSwitch(True, static_ratio=r_s, slip_time=0.02)),
                   motor=MotorConfig(bandwidth_hz=1e6, max_speed=10.0))
    up = drive(rig, ramp(0, 0.005, 0.005))
    drive(rig, np.full(500, 0.005))                   # hold: the tendon sticks
    T_out0 = rig.state.truth.T_out
    tr = drive(rig, ramp(0.005, 0.008, 0.005))
    k = int(np.argmax(tr["T_out"] > T_out0 * (1 + 1e-6)))   # the distal end first moves here
    assert k > 0
    # breakaway at the static bound: T_in reaches T_out e^{K (1 + r_s)} before the distal end moves
    assert tr["T_in"][k - 1] == pytest.approx(T_out0 * math.exp(K * (1 + r_s)), rel=0.01)
    assert tr["T_in"][k + 5] < tr["T_in"][k - 1]      # then T_in drops (the spike)
    assert tr["T_out"][-1] == pytest.approx(tr["T_in"][-1] * math.exp(-K), rel=0.01)   # kinetic again
    assert up["T_out"][-1] == pytest.approx(up["T_in"][-1] * math.exp(-K), rel=0.01)


def test_pretension_effect_adds_to_the_sheath_pretension():
    rig = make_rig(EffectsConfig(pretension=EffectSwitch(True, tension=2.5)), pretension=1.0)
    np.testing.assert_allclose(rig.state.truth.profile, 3.5)
    assert rig.state.truth.x_out == pytest.approx(3.5 / 2100.0, rel=1e-9)


def test_sensor_offset_and_delay_act_on_the_reading_only():
    fx = EffectsConfig(sensor_offset=EffectSwitch(True, offset=-0.4), sensor_delay=EffectSwitch(True, delay=0.0125))
    rig, ref = make_rig(fx), make_rig(EffectsConfig())
    xs = 0.003 + 0.002 * np.sin(2 * math.pi * 1.0 * DT * np.arange(1, 3001))
    tr, base = drive(rig, xs), drive(ref, xs)
    np.testing.assert_array_equal(tr["T_out"], base["T_out"])
    t = DT * np.arange(1, xs.size + 1)
    expected = np.interp(t - 0.0125, t, tr["T_in"]) - 0.4
    np.testing.assert_allclose(tr["reading"][100:], expected[100:], atol=1e-9)


def test_load_cell_gain_drift_and_encoder_offset_act_on_the_readings_only():
    fx = EffectsConfig(sensor_gain=EffectSwitch(True, gain=0.07), sensor_drift=EffectSwitch(True, rate=-0.01),
                       encoder_offset=EffectSwitch(True, offset=-4e-5))
    rig, ref = make_rig(fx), make_rig(EffectsConfig())
    assert rig.state.x_in == pytest.approx(ref.state.x_in - 4e-5, abs=1e-12)        # the rest reads the offset
    xs = 0.003 + 0.002 * np.sin(2 * math.pi * 1.0 * DT * np.arange(1, 3001))
    states, base = [rig.step(float(x), DT) for x in xs], [ref.step(float(x), DT) for x in xs]
    t = DT * np.arange(1, xs.size + 1)
    T_ref = np.array([s.T_in for s in base])                                         # no noise: the true T_in
    np.testing.assert_allclose([s.T_in for s in states], 1.07 * T_ref - 0.01 * t, atol=1e-9)
    np.testing.assert_allclose([s.x_in for s in states], np.array([s.x_in for s in base]) - 4e-5, atol=1e-12)
    for k in ("T_out", "x_out", "T_in"):
        np.testing.assert_array_equal([getattr(s.truth, k) for s in states], [getattr(s.truth, k) for s in base])


def test_distal_backlash_holds_the_distal_position_across_the_gap():
    width = 2e-4
    rig, ref = make_rig(EffectsConfig(distal_backlash=EffectSwitch(True, width=width))), make_rig(EffectsConfig())
    pull, release = ramp(0.0, 0.006, 0.005), ramp(0.006, 0.002, 0.005)
    xs = np.concatenate([pull, release, ramp(0.002, 0.006, 0.005)])
    tr, base = drive(rig, xs), drive(ref, xs)
    np.testing.assert_array_equal(tr["T_out"], base["T_out"])                      # the tendon end carries the load
    gap = tr["x_out"] - base["x_out"]
    assert np.all(np.abs(gap) <= 0.5 * width + 1e-15)
    up, down = pull.size - 1, pull.size + release.size - 1                           # the ends of pull and release
    assert gap[up] == pytest.approx(-0.5 * width, rel=1e-9)                          # the play trails the end
    turn = np.argmax(base["x_out"][up:] < base["x_out"][up] - 0.9 * width) + up       # the end crossed 0.9 of it
    assert np.ptp(tr["x_out"][up:turn + 1]) == 0.0                                    # the distal position stayed
    assert gap[down] == pytest.approx(0.5 * width, rel=1e-9)                         # then leads it on release


def test_presliding_lags_the_friction_in_proximal_travel():
    x_p = 1e-4
    rig, ref = make_rig(EffectsConfig(presliding=EffectSwitch(True, distance=x_p))), make_rig(EffectsConfig())
    xs = np.concatenate([ramp(0.0, 0.006, 0.002), ramp(0.006, 0.004, 0.002)])
    tr, base = drive(rig, xs), drive(ref, xs)
    np.testing.assert_array_equal(tr["x_out"], base["x_out"])
    np.testing.assert_array_equal(tr["T_in"], base["T_in"])
    F, M = tr["T_in"] - tr["T_out"], base["T_in"] - base["T_out"]                  # friction: lagged, memory's
    ds = np.abs(np.diff(xs, prepend=0.0))[1:]
    # dF/ds = (M - F) / x_p, step by step (midpoint of each step: the rig solves it exactly over the step)
    rhs = 0.5 * (M[1:] + M[:-1] - F[1:] - F[:-1]) / x_p
    np.testing.assert_allclose(np.diff(F) / ds, rhs, rtol=0, atol=1e-3 * np.max(np.abs(rhs)))
    up = np.argmax(xs)                                                               # end of the pull
    slope = (M[up] - M[up - 100]) / (xs[up] - xs[up - 100])
    assert M[up] - F[up] == pytest.approx(x_p * slope, rel=0.02)                     # a steady lag of x_p dM/ds
    back = np.searchsorted(-xs[up:], -(xs[up] - 0.5 * x_p)) + up                     # half x_p into the release
    assert F[back] - M[back] > 0.5 * (M[up] - M[back])         # the lagged friction keeps over half the memory's drop
    slope = (M[-1] - M[-101]) / abs(xs[-1] - xs[-101])                               # per unit of travel
    assert M[-1] - F[-1] == pytest.approx(x_p * slope, rel=0.02)                     # and trails it again


def test_general_solver_keeps_the_taut_invariant():
    fx = EffectsConfig(friction_offset=EffectSwitch(True, tension_offset=0.5),
                         tendon_stiffening=EffectSwitch(True, softening=2.0, toe_tension=1.5),
                         velocity_friction=EffectSwitch(True, viscous=10.0),
                         stiction=EffectSwitch(True, static_ratio=0.3))
    rig = make_rig(fx, motor=MotorConfig())
    rng = np.random.default_rng(4)
    cmd = np.clip(0.004 + np.cumsum(rng.normal(0, 3e-5, 4000)), 0.002, 0.009)
    for x in cmd:
        t = rig.step(float(x), DT).truth
        assert np.all(t.profile >= 0.0)
        if t.profile.min() > 1e-6:  # (a slide that slowed leaves a steeper part; the front crossing it
            # is blended linearly in T, not in strain: nanometres)
            assert t.x_in - t.x_out == pytest.approx(t.elongation, rel=1e-4, abs=1e-12)


def test_scenario_recordings_look_like_a_bench():
    rec = record("sensor_offset", seed=3, duration=30.0, rate_hz=500.0)
    d = rec.data
    assert len(d) == 15000 and d.x_out is not None and d.T_out is not None
    assert d.x_in[0] == 0.0 and abs(d.x_out[0]) <= 4e-6                         # zeroed encoders
    q = 2 * math.pi * 0.005 / 67000
    np.testing.assert_allclose(d.x_in / q, np.round(d.x_in / q), atol=1e-6)          # quantised encoder
    assert np.std(d.T_out - rec.truth["signals"]["T_out"]) == pytest.approx(rec.truth["noise_T_out"], rel=0.05)
    lo, hi = realistic_range("sensor_offset")["offset"]
    assert lo <= abs(rec.truth["parameters"]["offset"]) <= hi
    again = record("sensor_offset", seed=3, duration=30.0, rate_hz=500.0)
    np.testing.assert_array_equal(again.data.T_in, d.T_in)
    clean = record(None, seed=3, duration=30.0, rate_hz=500.0)      # same rig and protocol, no effect
    np.testing.assert_array_equal(clean.data.x_in, d.x_in)
    assert "offset" not in str(d.metadata)
    with pytest.raises(ValueError, match="unknown effect"):
        record("backlash")


@pytest.mark.parametrize("key", ["sensor_gain", "sensor_drift", "encoder_offset", "presliding", "distal_backlash"])
def test_scenario_records_each_switch_at_its_level(key):
    rec = record(key, seed=5, level=0.5, duration=10.0, rate_hz=500.0)
    clean = record(None, seed=5, level=0.5, duration=10.0, rate_hz=500.0)     # same rig, protocol and noise
    (name, (lo, hi)), = realistic_range(key).items()
    m = rec.truth["parameters"][name]
    assert abs(m) == pytest.approx(lo + 0.5 * (hi - lo), rel=1e-12)
    d, c, tr, tc = rec.data, clean.data, rec.truth["signals"], clean.truth["signals"]
    np.testing.assert_array_equal(tr["x_in"], tc["x_in"])
    if key == "sensor_gain":
        np.testing.assert_allclose(d.T_in - c.T_in, m * c.T_in, atol=6 * abs(m) * rec.truth["noise_T_in"])
    elif key == "sensor_drift":
        np.testing.assert_allclose(d.T_in - c.T_in, m * d.time, atol=1e-9)
    elif key == "encoder_offset":
        np.testing.assert_allclose(d.x_in - c.x_in, m, atol=1e-12)
    elif key == "presliding":
        np.testing.assert_array_equal(tr["x_out"], tc["x_out"])
        assert np.max(np.abs(tr["T_out"] - tc["T_out"])) > 0.1                     # rounded corners on T_out
    else:
        np.testing.assert_array_equal(tr["T_out"], tc["T_out"])
        gap = tr["x_out"] - tc["x_out"]
        assert np.max(gap) == pytest.approx(0.5 * m, rel=1e-6) and np.min(gap) == pytest.approx(-0.5 * m, rel=1e-6)
