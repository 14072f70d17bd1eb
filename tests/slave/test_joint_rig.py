"""SimulatedInstrument: cross-check with the single-tendon rig, torque balance, dead zone, pretension, inputs."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from slave.pair_rig import SimulatedInstrument
from slave.rig import RigInputError
from slave.simulated import SimulatedRig
from teleop.config.load import config_from_dict
from teleop.config.schema import SimulatedJointConfig
from teleop.errors import ConfigError
from tests.slave.joint_helpers import DT, joint_config

R, K_J, K_T, T_C, HI, K_LIM = 0.004, 0.005, 0.02, 0.2, 1.2, 50.0


def test_one_taut_tendon_equals_the_single_tendon_rig():
    """Tendon b slack: the joint is tendon a on a spring load, which SimulatedRig solves exactly."""
    quiet = {"n_elements": 100, "sensors": {"load_cell_noise": 0.0}}
    cfg = config_from_dict({"instrument": {"joints": [{
        "name": "j", "pulley_radius": R, "limits": [-1.2, HI]}]}, "rig": {"simulated": {**quiet, "joints": [{
        "name": "j", "stiffness": K_J, "damping": 0.0, "limit_stiffness": K_LIM,
        "load": {"tissue_stiffness": K_T, "tissue_contact": T_C}}]}}})
    inst = SimulatedInstrument.from_config(cfg)
    single = SimulatedRig.from_config(config_from_dict({"rig": {"simulated": {**quiet, "load": {
        "joint_stiffness": K_J / R ** 2, "tissue_stiffness": K_T / R ** 2, "tissue_contact": R * T_C,
        "joint_limit": R * HI, "limit_stiffness": K_LIM / R ** 2, "tissue": True, "force": 0.0}}}}))
    t = np.arange(9000) * DT
    # pull (into the limit), partial release, re-pull past the peak, minor loops, release to slack
    x = np.interp(t, [0, 2, 3, 4, 5, 6, 7, 9], [0, 0.0075, 0.006, 0.0078, 0.004, 0.0065, 0.001, 0.0])
    worst = np.zeros(3)
    for xx in x:
        a = inst.step([[xx, -0.02]], DT).truth
        b = single.step(xx, DT).truth
        assert a.T_in[0, 1] == 0.0 and a.T_out[0, 1] == 0.0
        worst = np.maximum(worst, np.abs([a.T_in[0, 0] - b.T_in, a.T_out[0, 0] - b.T_out, a.x_out[0, 0] - b.x_out]))
    assert worst[0] < 1e-8 and worst[1] < 1e-8 and worst[2] < 1e-12


def test_torque_balance_holds_every_step_and_tendons_stay_lipschitz():
    cfg = joint_config(damping=0.001)
    inst = SimulatedInstrument.from_config(cfg)
    j = cfg.rig.simulated.joint(cfg.instrument.joints[0].name)
    assert j.damping == 0.001
    x0 = inst.state.x_in_cmd.copy()
    t = np.arange(3000) * DT
    u = 0.006 * np.sin(np.pi * t / 1.5) ** 2
    theta_prev = 0.0
    for _k, uu in enumerate(u):
        tr = inst.step(x0 + [[uu + 1e-4, -0.8 * uu + 1e-4]], DT).truth
        th = tr.theta[0]
        load = inst.load_torque(0, th) + j.damping * (th - theta_prev) / DT
        assert tr.torque[0] == pytest.approx(load, abs=1e-9)
        theta_prev = th
        for p, pair in zip(tr.profiles, inst.tendons[0], strict=False):
            g = pair.log_gain
            lp = np.log(np.maximum(p, 1e-300))
            if p.min() > 0:
                assert np.all(np.abs(np.diff(lp)) <= np.diff(g) + 1e-9)
    assert 0.3 < tr.theta.max() or theta_prev > 0.0


def test_dead_zone_after_a_reversal_inside_the_band():
    """Releasing the pulled tendon by less than the capstan band does not move the joint (eqs. (14)-(21))."""
    inst = SimulatedInstrument.from_config(joint_config())
    x0 = inst.state.x_in_cmd.copy()
    for k in range(1500):
        inst.step(x0 + [[4e-6 * k, -4e-6 * k]], DT)
    for _ in range(200):       # let the motors arrive
        inst.step(x0 + [[4e-6 * 1499, -4e-6 * 1499]], DT)
    th = inst.state.truth.theta[0]
    T_out = inst.state.truth.T_out[0, 0]
    T_in = inst.state.truth.T_in[0, 0]
    for k in range(1, 100):      # back off tendon a by 0.1 mm: T_in falls, the tip does not move
        s = inst.step(x0 + [[4e-6 * 1499 - 1e-6 * k, -4e-6 * 1499]], DT)
    assert s.truth.T_in[0, 0] < 0.9 * T_in
    assert s.truth.T_in[0, 0] > T_in * math.exp(-2 * inst.K[0, 0])
    assert s.truth.theta[0] == pytest.approx(th, abs=1e-12)
    assert s.truth.T_out[0, 0] == pytest.approx(T_out, abs=1e-9)


def test_pretension_start_state_and_symmetric_pull():
    inst = SimulatedInstrument.from_config(joint_config(pretension=2.0))
    st = inst.state
    assert np.all(st.truth.T_in == 2.0) and np.all(st.truth.T_out == 2.0) and st.truth.theta[0] == 0.0
    assert np.allclose(st.truth.elongation, st.truth.x_in)           # x_out = 0 at theta = 0
    x0 = st.x_in_cmd.copy()
    for _ in range(200):
        s = inst.step(x0 + 1e-4, DT)      # pull both equally: tensions rise, the joint hardly turns
    assert s.truth.T_in.min() > 2.5 and abs(s.truth.theta[0]) < 0.02


def test_set_load_rebalances_with_the_motors_held():
    inst = SimulatedInstrument.from_config(joint_config())
    x0 = inst.state.x_in_cmd.copy()
    for k in range(1000):
        inst.step(x0 + [[5e-6 * k, -5e-6 * k]], DT)
    th_tissue = inst.state.truth.theta[0]
    x_held = inst.state.truth.x_in.copy()
    inst.set_load(tissue=False)
    tr = inst.state.truth
    assert tr.theta[0] > th_tissue + 0.05 and np.array_equal(tr.x_in, x_held)
    assert tr.torque[0] == pytest.approx(inst.load_torque(0, tr.theta[0]), abs=1e-9)
    with pytest.raises(RigInputError, match="tissue"):
        inst.set_load(tissue="no")
    with pytest.raises(RigInputError, match="force=2.0: a joint instrument's distal load is tissue contact only"):
        inst.set_load(force=2.0)


def test_one_rig_protocol_over_arrays_of_tendons():
    """A single tendon and a joint instrument are both a Rig; their states are one RigState type whose
    arrays have the rig's tendon shape: () and (n_joints, 2)."""
    from slave.rig import Rig, RigState
    from slave.simulated import SimulatedRig
    from teleop.config.schema import Config
    inst, one = SimulatedInstrument.from_config(joint_config()), SimulatedRig.from_config(Config())
    for rig, shape in ((inst, (len(inst.joint_names), 2)), (one, ())):
        st = rig.step(rig.state.x_in_cmd, DT)
        assert isinstance(rig, Rig) and type(st) is RigState
        assert np.shape(st.x_in) == np.shape(st.T_in) == np.shape(st.x_in_cmd) == shape


def test_sensors_are_seeded_noisy_and_quantised():
    a, b = (SimulatedInstrument.from_config(joint_config(seed=3)) for _ in range(2))
    c = SimulatedInstrument.from_config(joint_config(seed=4))
    x0 = a.state.x_in_cmd.copy()
    ra = [a.step(x0 + 1e-4, DT) for _ in range(50)]
    rb = [b.step(x0 + 1e-4, DT) for _ in range(50)]
    rc = [c.step(x0 + 1e-4, DT) for _ in range(50)]
    assert all(np.array_equal(p.T_in, q.T_in) for p, q in zip(ra, rb, strict=False))
    assert not np.array_equal(ra[-1].T_in, rc[-1].T_in)
    noise = np.array([s.T_in - s.truth.T_in for s in ra])
    assert 0.01 < noise.std() < 0.03
    q = a.encoder_resolution
    assert np.allclose(ra[-1].x_in / q, np.round(ra[-1].x_in / q))
    assert np.abs(ra[-1].x_in - ra[-1].truth.x_in).max() <= q / 2 + 1e-15


@pytest.mark.parametrize("cmd, dt, match", [
    ([[0.0, 0.0], [0.0, 0.0]], DT, r"shape \(1, 2\)"),
    ([[math.nan, 0.0]], DT, "finite"),
    ([[0.0, 0.0]], 0.0, "dt must be"),
    ([[0.0, 0.0]], math.inf, "dt must be"),
    ("x", DT, "numbers"),
])
def test_bad_step_inputs_name_the_argument(cmd, dt, match):
    inst = SimulatedInstrument.from_config(joint_config())
    with pytest.raises(RigInputError, match=match):
        inst.step(cmd, dt)


def test_config_errors_name_the_joint_and_key():
    with pytest.raises(ConfigError, match=r"instrument.joints must be a list of 1 to 16"):
        SimulatedInstrument((), config_from_dict({}).rig.simulated)
    cfg = joint_config()
    bad = cfg.instrument.joints[0].__class__(name="wrist", pulley_radius=-1.0)
    with pytest.raises(ConfigError, match=r"instrument.joints\[0\] \(wrist\).pulley_radius"):
        SimulatedInstrument((bad,), cfg.rig.simulated)
    sim = dataclasses.replace(cfg.rig.simulated, joints=(SimulatedJointConfig("j", stiffness=-1.0),))
    with pytest.raises(ConfigError, match=r"rig.simulated.joints \(j\).stiffness"):
        SimulatedInstrument(cfg.instrument.joints, sim)


def test_one_to_four_independent_joints():
    j = joint_config().instrument.joints[0]
    joints = [j.__class__(**{**j.__dict__, "name": f"j{i}", "pulley_radius": 0.003 + 0.001 * i}) for i in range(4)]
    inst = SimulatedInstrument(joints, joint_config().rig.simulated)
    x0 = inst.state.x_in_cmd.copy()
    for _ in range(300):
        s = inst.step(x0 + [[3e-3, -3e-3], [0, 0], [-3e-3, 3e-3], [0, 0]], DT)
    th = s.truth.theta
    assert th[0] > 0.2 and th[2] < -0.2 and abs(th[1]) < 1e-9 and abs(th[3]) < 1e-9   # joints do not interact
    assert s.T_in.shape == (4, 2) and len(s.truth.profiles) == 8
    with pytest.raises(ConfigError, match="1 to 16"):
        SimulatedInstrument(joints * 4 + joints[:1], joint_config().rig.simulated)


def test_the_step_over_all_joints_is_the_per_joint_kernel_bit_for_bit():
    """The rig steps every joint in one compiled call and reads its truth in another: the same numbers as
    estimator.kernels.step_joint joint by joint and numpy's sums (the per-joint loop it replaced)."""
    from pathlib import Path

    from estimator.kernels import RIGID_STOP, step_joint
    from teleop.config.load import load_config
    cfg = load_config(Path(__file__).resolve().parents[2] / "configs" / "instrument-3dof.yaml")
    rig = SimulatedInstrument.from_config(cfg)
    T = [[rig.state.truth.profiles[2 * i + k].copy() for k in range(2)] for i in range(rig.n_joints)]
    theta, x0 = rig.state.truth.theta.copy(), rig.state.truth.x_in.copy()
    for n in range(1500):
        if n == 800:
            rig.set_load(tissue=True)
            T = [[rig.state.truth.profiles[2 * i + k].copy() for k in range(2)] for i in range(rig.n_joints)]
            theta = rig.state.truth.theta.copy()
        phase = 2 * math.pi * n * DT
        cmd = x0 + 0.004 * np.array([[math.sin(phase), -math.sin(phase)],
                                     [math.sin(1.3 * phase), -0.8 * math.sin(phase)],
                                     [0.5 * math.sin(phase), -math.sin(0.7 * phase)]])
        x = rig._x + rig.drive.move(rig._x, cmd, DT)
        for i, (j, s) in enumerate(zip(rig.joints, rig.sims, strict=False)):          # the per-joint loop
            (pa, pb), kt = rig.tendons[i], s.load.tissue_stiffness if rig.tissue[i] else 0.0
            theta[i] = step_joint(T[i][0], pa.lo, pa.hi, pa.dlo, pa.dhi, pa.w, pa.c_pull, pa.c_rel,
                                  T[i][1], pb.lo, pb.hi, pb.dlo, pb.dhi, pb.w, pb.c_pull, pb.c_rel, x[i, 0], x[i, 1],
                                  j.pulley_radius, theta[i], s.stiffness, s.damping / DT, kt, s.load.tissue_contact,
                                  j.limits[0], j.limits[1], s.limit_stiffness, s.load.torque,
                                  rig._slope[i] + s.damping / DT, *RIGID_STOP)
        tr = rig.step(cmd, DT).truth
        r = np.array([j.pulley_radius for j in rig.joints])
        assert np.array_equal(tr.theta, theta) and np.array_equal(tr.x_in, x)
        assert all(np.array_equal(tr.profiles[2 * i + k], T[i][k]) and not tr.profiles[2 * i + k].flags.writeable
                   for i in range(rig.n_joints) for k in range(2))
        assert np.array_equal(tr.T_in, [[T[i][k][0] for k in range(2)] for i in range(rig.n_joints)])
        assert np.array_equal(tr.T_out, [[T[i][k][-1] for k in range(2)] for i in range(rig.n_joints)])
        assert np.array_equal(tr.elongation, [[float(rig.tendons[i][k].w @ T[i][k]) for k in range(2)]
                                              for i in range(rig.n_joints)])
        assert np.array_equal(tr.torque, r * (tr.T_out[:, 0] - tr.T_out[:, 1]))
        assert np.array_equal(tr.x_out, np.column_stack((r * theta, -r * theta)))
    assert np.ptp(theta) > 0.1                                          # the joints moved


def test_the_joint_settles_on_the_root_of_its_torque_balance():
    """Each step's angle is the root of the torque balance f(theta) (estimator.kernels.settle_joint) to round-off:
    within a few ulps of the angle a plain bisection of the same f finds, |f| at round-off of the torque scale; over
    pulls into tissue, reversals inside the band and releases to slack."""
    from estimator.distal_slip import elongation
    from estimator.kernels import (
        BALANCE_TOL,
        RIGID_STOP,
        advance_proximal,
        joint_torque_balance,
        load_torque,
        settle_joint,
    )
    cfg = joint_config(damping=0.001)
    rig = SimulatedInstrument.from_config(cfg)
    j, s = rig.joints[0], rig.sims[0]
    (pa, pb), r, kt = rig.tendons[0], j.pulley_radius, s.load.tissue_stiffness if rig.tissue[0] else 0.0
    Ta, Tb = (p.copy() for p in rig.state.truth.profiles)
    theta, x, worst, moved, resid = 0.0, rig.state.truth.x_in[0].copy(), 0.0, 0, 0.0
    start = x.copy()
    t = np.arange(4000) * DT
    u = 0.007 * np.sin(np.pi * t / 1.3) ** 2 * np.where(t > 2.6, -0.3, 1.0)
    for uu in u:
        x = x + rig.drive.move(x, start + [uu, -0.8 * uu], DT)
        advance_proximal(Ta, pa.lo, pa.hi, pa.w, pa.c_pull, pa.c_rel, x[0] - r * theta, 0.0, *RIGID_STOP)
        advance_proximal(Tb, pb.lo, pb.hi, pb.w, pb.c_pull, pb.c_rel, x[1] + r * theta, 0.0, *RIGID_STOP)
        law = (s.stiffness, s.damping / DT, kt, s.load.tissue_contact, j.limits[0], j.limits[1], s.limit_stiffness,
               s.load.torque)
        args = (Ta.copy(), pa.dlo, pa.dhi, pa.w, elongation(Ta, pa.w), x[0], Tb.copy(), pb.dlo, pb.dhi, pb.w,
                elongation(Tb, pb.w), x[1], r, theta, *law)
        scale = r * (Ta[-1] + Tb[-1]) + abs(load_torque(theta, law[0], *law[2:]))
        new = settle_joint(Ta, pa.dlo, pa.dhi, pa.w, x[0], Tb, pb.dlo, pb.dhi, pb.w, x[1], r, theta, *law,
                           rig._slope[0] + s.damping / DT)
        if scale > 0.0:
            resid = max(resid, abs(joint_torque_balance(new, *args)) / scale)
        lo, hi = new - 0.1, new + 0.1                      # f falls with theta: bisection on the same function
        assert joint_torque_balance(lo, *args) > 0 > joint_torque_balance(hi, *args)
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            if mid in (lo, hi):
                break
            lo, hi = (mid, hi) if joint_torque_balance(mid, *args) > 0 else (lo, mid)
        worst = max(worst, abs(new - 0.5 * (lo + hi)))
        moved += new != theta
        theta = new
    assert worst < 1e-12 and resid < 100 * BALANCE_TOL and moved > 3000
