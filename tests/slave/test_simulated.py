"""SimulatedRig against the closed forms of Phee et al. (2009) and the load, motor and sensor models.

Every expected value is computed from a formula; tolerances are relative 1 % unless stated.
"""
import math

import numpy as np
import pytest
from scipy.optimize import brentq

from estimator.geometry import SheathGeometry
from slave.rig import Rig, RigState
from slave.simulated import SimulatedRig
from teleop.config.schema import (
    Config,
    LoadConfig,
    MotorConfig,
    RunConfig,
    SensorConfig,
    SheathConfig,
    SimulatedRigConfig,
)

L, ANGLE, MU, EA = 1.5, 2.0 * math.pi, 0.1, 15000.0
K = MU * ANGLE
M_E = L * (1.0 - math.exp(-K)) / (EA * K)          # Phee et al. 2009, eq. (12): pull branch
M_REL = L * (math.exp(K) - 1.0) / (EA * K)         # release branch, profile T_in e^{+mu theta}
DT = 1e-3
FAST = MotorConfig(bandwidth_hz=1e6, max_speed=10.0)   # motor follows the command within one step

FREE = LoadConfig(joint_stiffness=100.0, joint_limit=0.1, tissue=False, force=0.0)
SPRING = LoadConfig(joint_stiffness=100.0, joint_limit=0.1, tissue_stiffness=2000.0, tissue_contact=0.0,
                    tissue=True, force=0.0)
ACTUATOR = LoadConfig(joint_stiffness=100.0, joint_limit=0.1, tissue=False, force=5.0)


def uniform_sheath(**kw) -> SheathConfig:
    g = SheathGeometry.uniform(L, ANGLE)
    return SheathConfig(EA=EA, runs=tuple(RunConfig(r.length, r.radius) for r in g.runs), **kw)


def make_rig(load=SPRING, sheath=None, motor=FAST, noise=0.0, seed=0, n=200) -> SimulatedRig:
    rig = SimulatedRigConfig(n_elements=n, mu=MU, motor=motor, load=load,
                             sensors=SensorConfig(load_cell_noise=noise, seed=seed))
    return SimulatedRig(sheath or uniform_sheath(), rig)


def drive(rig, xs):
    """Step through commands ``xs``; truth arrays T_in, T_out, x_in, x_out, elongation."""
    out = [rig.step(x, DT).truth for x in xs]
    return {k: np.array([getattr(t, k) for t in out]) for k in ("T_in", "T_out", "x_in", "x_out", "elongation")}


def ramp(a, b, step=1e-6):
    n = max(2, int(abs(b - a) / step) + 1)
    return np.linspace(a, b, n)[1:]


def test_protocol_and_initial_state():
    rig = make_rig()
    assert isinstance(rig, Rig)
    s = rig.state
    assert isinstance(s, RigState) and s.t == 0.0 and s.truth.profile.shape == (201,)
    s1 = rig.step(1e-4, DT)
    assert s1 is rig.state and s1.t == pytest.approx(DT) and s1.x_in_cmd == 1e-4
    assert rig.K == pytest.approx(K, rel=1e-12)
    assert rig.M_e == pytest.approx(M_E, rel=1e-4)


@pytest.mark.parametrize("load", [ACTUATOR, SPRING], ids=["force-actuator", "spring"])
def test_pull_full_slip_ratio_and_load_law(load):
    rig = make_rig(load)
    tr = drive(rig, ramp(0.0, 0.006))
    m = tr["T_in"] > 0.1
    np.testing.assert_allclose(tr["T_out"][m] / tr["T_in"][m], math.exp(-K), rtol=0.01)
    moving = tr["x_out"] > 1e-4
    assert moving.sum() > 100
    k = load.joint_stiffness + (load.tissue_stiffness if load.tissue else 0.0)
    np.testing.assert_allclose(tr["T_out"][moving], load.force + k * tr["x_out"][moving], rtol=0.01)
    if load.force > 0:  # against the stop while the tendon pulls less than the set force
        assert np.all(tr["x_out"][tr["T_out"] < load.force * 0.999] == 0.0)


def test_release_full_slip_ratio_and_elongation():
    rig = make_rig()
    up = drive(rig, ramp(0.0, 0.006))
    T0 = up["T_in"][-1]
    dn = drive(rig, ramp(0.006, 0.0005))
    m = (dn["T_in"] < T0 * math.exp(-2 * K) * 0.999) & (dn["T_in"] > 0.1)
    assert m.sum() > 100
    np.testing.assert_allclose(dn["T_out"][m] / dn["T_in"][m], math.exp(K), rtol=0.01)
    np.testing.assert_allclose(dn["x_in"][m] - dn["x_out"][m], M_REL * dn["T_in"][m], rtol=0.01)


def test_pull_elongation_law_from_zero():
    rig = make_rig(ACTUATOR)
    tr = drive(rig, ramp(0.0, 0.005))
    m = tr["T_in"] > 0.5
    np.testing.assert_allclose(tr["x_in"][m] - tr["x_out"][m], M_E * tr["T_in"][m], rtol=0.01)
    np.testing.assert_allclose(tr["elongation"], tr["x_in"] - tr["x_out"], rtol=1e-9, atol=1e-15)


def test_reversal_holds_T_out_through_the_band():
    rig = make_rig()
    up = drive(rig, ramp(0.0, 0.006))
    T_in0, T_out0, x_out0 = up["T_in"][-1], up["T_out"][-1], up["x_out"][-1]
    dn = drive(rig, ramp(0.006, 0.0, step=5e-7))
    i19 = np.argmax(dn["T_in"] <= T_in0 * math.exp(-1.9 * K))
    i21 = np.argmax(dn["T_in"] <= T_in0 * math.exp(-2.1 * K))
    assert 0 < i19 < i21
    assert dn["T_out"][i19] == pytest.approx(T_out0, rel=0.01)
    assert np.all(dn["x_out"][: i19 + 1] == x_out0)  # distal end stuck in the band
    assert dn["T_out"][i21] < 0.99 * T_out0
    assert dn["T_out"][i21] == pytest.approx(dn["T_in"][i21] * math.exp(K), rel=0.01)


def test_minor_loop_return_point_memory():
    rig = make_rig()
    up = drive(rig, ramp(0.0, 0.005))
    A, T_outA, x_A = up["T_in"][-1], up["T_out"][-1], up["x_in"][-1]
    B = A * math.exp(-K)  # inside the band [A e^-2K, A]
    x = x_A
    while rig.state.truth.T_in > B:
        x -= 1e-6
        rig.step(x, DT)
    assert rig.state.truth.T_out == pytest.approx(T_outA, rel=1e-9)
    tr = drive(rig, ramp(x, x_A + 0.002))
    i = np.argmax(tr["T_out"] > T_outA * (1 + 1e-6))
    assert i > 0
    assert tr["T_in"][i] == pytest.approx(A, rel=0.01)        # resumes rising at T_in = A
    np.testing.assert_allclose(tr["T_out"][:i], T_outA, rtol=1e-9)
    assert tr["T_in"][-1] > 1.2 * A
    assert tr["T_out"][-1] == pytest.approx(tr["T_in"][-1] * math.exp(-K), rel=0.01)


def _exact_pull_compliance(runs, mu, EA):
    """(1/EA) int_0^L exp(-mu theta(s)) ds, integrated run by run in closed form [m/N]."""
    total, theta = 0.0, 0.0
    for r in runs:
        if math.isinf(r.radius):
            total += math.exp(-mu * theta) * r.length
        else:
            a = r.length / r.radius
            total += math.exp(-mu * theta) * (1.0 - math.exp(-mu * a)) * r.radius / mu
            theta += a
    return total / EA


def test_nonuniform_route_same_ratio_different_elongation():
    sheath = SheathConfig(EA=EA)  # default route: two half turns of different radius
    total_angle = sum(0.0 if math.isinf(r.radius) else r.length / r.radius for r in sheath.runs)
    length = sum(r.length for r in sheath.runs)
    rig = make_rig(SPRING, sheath=sheath)
    tr = drive(rig, ramp(0.0, 0.006))
    m = tr["T_in"] > 0.5
    np.testing.assert_allclose(tr["T_out"][m] / tr["T_in"][m], math.exp(-MU * total_angle), rtol=0.01)
    me_route = _exact_pull_compliance(sheath.runs, MU, EA)
    Kr = MU * total_angle
    me_uniform = length * (1 - math.exp(-Kr)) / (EA * Kr)
    assert abs(me_route / me_uniform - 1) > 0.05
    np.testing.assert_allclose(tr["x_in"][m] - tr["x_out"][m], me_route * tr["T_in"][m], rtol=0.01)


def test_joint_limit_slope_is_M_e():
    load = LoadConfig(joint_stiffness=100.0, joint_limit=0.01, limit_stiffness=2.0e6, tissue=False, force=0.0)
    rig = make_rig(load)
    tr = drive(rig, ramp(0.0, 0.0125))
    beyond = tr["x_out"] > load.joint_limit + 1e-6
    assert tr["T_in"][-1] > 20.0 and beyond.sum() > 100
    slope = np.polyfit(tr["T_in"][beyond], tr["x_in"][beyond], 1)[0]
    assert slope == pytest.approx(M_E, rel=0.01)
    # exactly: tendon plus the limit's own compliance seen through the capstan
    expected = M_E + math.exp(-K) / (load.joint_stiffness + load.limit_stiffness)
    assert slope == pytest.approx(expected, rel=1e-3)
    before = (tr["T_in"] > 0.2) & (tr["x_out"] < load.joint_limit)
    slope_free = np.polyfit(tr["T_in"][before], tr["x_in"][before], 1)[0]
    assert slope_free == pytest.approx(M_E + math.exp(-K) / load.joint_stiffness, rel=1e-3)


def test_load_cell_noise_statistics_and_seed():
    sigma, n = 0.05, 20000
    rig = make_rig(FREE, sheath=uniform_sheath(pretension=4.0), noise=sigma, seed=7)
    x0 = rig.state.truth.x_in
    states = [rig.step(x0, DT) for _ in range(n)]
    err = np.array([s.T_in - s.truth.T_in for s in states])
    assert abs(err.mean()) < 4 * sigma / math.sqrt(n)
    assert err.std() == pytest.approx(sigma, rel=6 / math.sqrt(2 * n))
    again = make_rig(FREE, sheath=uniform_sheath(pretension=4.0), noise=sigma, seed=7)
    other = make_rig(FREE, sheath=uniform_sheath(pretension=4.0), noise=sigma, seed=8)
    a = [again.step(x0, DT).T_in for _ in range(50)]
    b = [other.step(x0, DT).T_in for _ in range(50)]
    assert a == [s.T_in for s in states[:50]] and a != b


def test_encoder_quantisation():
    motor = MotorConfig(bandwidth_hz=1e6, max_speed=10.0, pulley_radius=0.005, encoder_lines_per_rev=67000)
    rig = make_rig(motor=motor)
    q = 2 * math.pi * motor.pulley_radius / motor.encoder_lines_per_rev
    states = [rig.step(x, DT) for x in ramp(0.0, 0.002, step=1e-7)]
    enc = np.array([s.x_in for s in states])
    true = np.array([s.truth.x_in for s in states])
    np.testing.assert_allclose(enc / q, np.round(enc / q), atol=1e-6)
    assert np.max(np.abs(enc - true)) <= q / 2 * (1 + 1e-9)
    assert np.std(enc - true) == pytest.approx(q / math.sqrt(12), rel=0.05)


def test_motor_bandwidth_and_speed_limit():
    motor = MotorConfig(bandwidth_hz=40.0, max_speed=0.05)
    rig = make_rig(motor=motor)
    x = rig.step(1e-5, DT).truth.x_in
    assert x == pytest.approx(1e-5 * (1 - math.exp(-2 * math.pi * motor.bandwidth_hz * DT)), rel=1e-12)
    rig2 = make_rig(motor=motor)
    xs = [rig2.step(0.1, DT).truth.x_in for _ in range(3)]
    np.testing.assert_allclose(np.diff([0.0] + xs), motor.max_speed * DT, rtol=1e-12)


def test_tension_never_negative_when_pushed():
    rig = make_rig()
    drive(rig, ramp(0.0, 0.004))
    for x in ramp(0.004, -0.005, step=2e-6):
        t = rig.step(x, DT).truth
        assert np.all(t.profile >= 0.0) and t.x_out >= 0.0
    assert t.T_in == 0.0 and t.T_out == 0.0 and t.elongation == 0.0 and t.x_out == 0.0
    assert t.x_in < 0.0  # the proximal end went past the slack point
    t = drive(rig, ramp(-0.005, 0.003))  # pulls taut again, full slip from zero
    assert t["T_out"][-1] == pytest.approx(t["T_in"][-1] * math.exp(-K), rel=0.01)


def test_pretension_starts_in_equilibrium():
    P = 3.0
    load = LoadConfig(joint_stiffness=100.0, joint_limit=0.1, tissue=False, force=1.0)
    rig = make_rig(load, sheath=uniform_sheath(pretension=P))
    t = rig.state.truth
    np.testing.assert_allclose(t.profile, P)
    assert t.x_out == pytest.approx((P - load.force) / load.joint_stiffness, rel=1e-12)
    assert t.x_in - t.x_out == pytest.approx(P * L / EA, rel=1e-9)
    t2 = drive(rig, [t.x_in] * 10)
    np.testing.assert_allclose(t2["T_in"], P, rtol=1e-12)
    np.testing.assert_allclose(t2["x_out"], t.x_out, rtol=1e-12)
    at_stop = make_rig(LoadConfig(force=5.0, tissue=False), sheath=uniform_sheath(pretension=P)).state.truth
    assert at_stop.x_out == 0.0 and at_stop.T_out == P


@pytest.mark.parametrize("kt", [300.0, 1000.0], ids=["partial-distal-slip", "whole-tendon"])
def test_tissue_switch_at_fixed_x_in(kt):
    """Tissue on after a free pull: slip spreads from the distal end, T(u) = max(T_p e^-Ku, T_d e^-K(1-u))."""
    load = LoadConfig(joint_stiffness=100.0, joint_limit=0.1, tissue_stiffness=kt, tissue_contact=0.005,
                      tissue=False, force=0.0)
    rig = make_rig(load)
    t0 = drive(rig, ramp(0.0, 0.016))
    Tp, x_in = t0["T_in"][-1], t0["x_in"][-1]
    rig.set_load(tissue=True)
    t1 = rig.state.truth

    def u_star(Td):
        return min(1.0, max(0.0, (math.log(Tp / Td) + K) / (2 * K)))

    def elong(Td):
        u = u_star(Td)
        return L / (EA * K) * (Tp * (1 - math.exp(-K * u)) + Td * (1 - math.exp(-K * (1 - u))))

    def x_load(Td):  # beyond contact: Td = kj x + kt (x - xc)
        return (Td + kt * load.tissue_contact) / (load.joint_stiffness + kt)

    Td = brentq(lambda T: x_load(T) + elong(T) - x_in, t0["T_out"][-1], 100.0, xtol=1e-12)
    assert t1.x_in == x_in
    assert t1.T_out == pytest.approx(Td, rel=0.01)
    assert t1.x_out == pytest.approx(x_load(Td), rel=0.01)
    assert t1.T_in == pytest.approx(max(Tp, Td * math.exp(-K)), rel=0.01)
    assert (0.0 < u_star(Td) < 1.0) == (kt == 300.0)


def test_force_reduction_from_pull_slip_rescales_the_profile():
    load = LoadConfig(joint_stiffness=100.0, joint_limit=0.1, tissue=False, force=8.0)
    rig = make_rig(load)
    t0 = drive(rig, ramp(0.0, 0.008))
    assert t0["x_out"][-1] > 0.0
    f_new = 2.0
    rig.set_load(force=f_new)
    t = rig.state.truth
    # whole tendon slides toward the actuator: still the pull curve; x_out + M_e T_in = x_in
    x_in = t0["x_in"][-1]
    Td = (x_in + f_new / load.joint_stiffness) / (1 / load.joint_stiffness + M_E * math.exp(K))
    assert t.T_out == pytest.approx(Td, rel=0.01)
    assert t.T_in == pytest.approx(Td * math.exp(K), rel=0.01)
    assert t.x_out == pytest.approx((Td - f_new) / load.joint_stiffness, rel=0.01)
    before = rig.state
    rig.set_load(force=f_new)  # no change of the law: nothing moves
    assert rig.state.truth.T_out == before.truth.T_out and rig.state.truth.x_out == before.truth.x_out


def test_random_history_keeps_invariants():
    rng = np.random.default_rng(3)
    rig = make_rig(LoadConfig(joint_stiffness=100.0, joint_limit=0.01, tissue_contact=0.004, force=2.0),
                   sheath=SheathConfig(EA=EA), motor=MotorConfig(), n=100)
    dg = np.diff(rig.log_gain)
    cmd = 0.0
    for k in range(3000):
        cmd = float(np.clip(cmd + rng.normal(0, 1e-4), -0.002, 0.014))
        if k % 500 == 250:
            rig.set_load(tissue=bool(rng.integers(2)), force=float(rng.uniform(0, 4)))
        t = rig.step(cmd, DT).truth
        T = t.profile
        assert np.all(T >= 0.0) and t.x_out >= 0.0
        if t.T_out > 1e-9:
            assert np.all(np.abs(np.diff(np.log(T))) <= dg + 1e-9)
            assert t.x_in - t.x_out == pytest.approx(t.elongation, rel=1e-9, abs=1e-15)


def test_bad_inputs_raise_value_errors_naming_the_field():
    bad = SheathConfig(runs=(RunConfig(-1.0),))
    with pytest.raises(ValueError, match=r"sheath\.runs\[0\]\.length"):
        SimulatedRig(bad, SimulatedRigConfig())
    with pytest.raises(ValueError, match=r"rig\.simulated\.n_elements"):
        SimulatedRig(SheathConfig(), SimulatedRigConfig(n_elements=0))
    with pytest.raises(ValueError, match="sheath.EA"):
        SimulatedRig(SheathConfig(EA=0.0), SimulatedRigConfig())
    with pytest.raises(ValueError, match=r"rig\.simulated\.mu"):
        SimulatedRig(SheathConfig(), SimulatedRigConfig(mu=-0.1))
    rig = SimulatedRig.from_config(Config())
    for x in (math.nan, math.inf):
        with pytest.raises(ValueError, match="x_in_cmd"):
            rig.step(x, DT)
    with pytest.raises(ValueError, match="dt"):
        rig.step(0.0, 0.0)
    with pytest.raises(ValueError, match="force"):
        rig.set_load(force=-1.0)
    assert rig.state.t == 0.0  # nothing advanced
