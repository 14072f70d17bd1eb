"""PairEstimator against the simulated pair: torque (J2) and angle (J3) vs truth, pair coupling, batch = online."""
from __future__ import annotations

import math

import numpy as np
import pytest

from estimator.distal_slip import distal_clip, distal_gains, distal_tension, elongation
from estimator.online.pair import PairEstimator
from estimator.online.pair_batch import estimate_pair_batch
from estimator.sheath import SheathModel, profile_update
from tests.slave.joint_helpers import Loop, joint_config, max_fs


def test_distal_tension_inverts_the_distal_slip_rule_exactly():
    rng = np.random.default_rng(7)
    g, w = SheathModel(K=0.8, compliance=1e-4).nodes(60)
    dlo, dhi = distal_gains(g)
    for _ in range(500):
        T = np.full(g.size, rng.uniform(0, 3))
        for T_in in rng.uniform(0, 20, 4):
            profile_update(T, g, T_in)
        e0 = elongation(T, w)
        target = e0 * rng.uniform(-0.2, 2.5)
        Td = distal_tension(T, dlo, dhi, w, e0, target)
        distal_clip(T, dlo, dhi, Td)
        if target <= 0:
            assert Td == 0.0 and not T.any()
        else:
            assert elongation(T, w) == pytest.approx(target, rel=1e-12)
            assert T[-1] == pytest.approx(Td, rel=1e-12)


@pytest.fixture(scope="module")
def paper_runs():
    """The paper's protocol on tendon a then tendon b, with and without the pair coupling (no pretension)."""
    out = {}
    for coupling in (True, False):
        loop = Loop(joint_config(), coupling=coupling)
        out[coupling] = (loop.protocol(0), loop.protocol(1, start=-0.02), loop)
    return out


# columns of the antagonist's true proximal tension and (true, estimated) distal tension, per pulling side
ANTAGONIST = {0: (8, 6, 7), 1: (9, 4, 5)}


def test_torque_and_angle_track_the_simulator_on_the_paper_protocol(paper_runs):
    for side, rows in enumerate(paper_runs[True][:2]):
        assert np.ptp(rows[:, 0]) > 0.03                     # a real torque range [N m]
        assert max_fs(rows) <= 0.04                          # acceptance: <= 0.05
        assert np.abs(rows[:, 3] - rows[:, 2]).max() < 0.01  # angle within 0.6 deg over ~1 rad
        assert rows[:, ANTAGONIST[side][0]].min() > 0.1      # the antagonist never went slack


def test_pair_coupling_is_what_keeps_the_antagonist_right(paper_runs):
    """Without (J4)-(J6) the loose tendon's distal tension is off by its capstan band most of the run."""
    for side, (with_c, without) in enumerate(zip(paper_runs[True][:2], paper_runs[False][:2], strict=False)):
        _, true, est = ANTAGONIST[side]
        err = lambda r, est=est, true=true: np.abs(r[:, est] - r[:, true]).mean()   # noqa: E731
        assert err(with_c) < 0.3 * err(without)
        assert max_fs(with_c) < max_fs(without)


def test_pretension_is_carried_through():
    loop = Loop(joint_config(pretension=2.0))
    rows = loop.protocol(0)
    ref = Loop(joint_config(pretension=2.0), coupling=False).protocol(0)
    assert max_fs(rows) <= 0.06 and max_fs(ref) > 0.2
    assert rows[:, 8].min() > 1.5                           # the antagonist held its pretension


def test_batch_equals_online():
    loop = Loop(joint_config(), settle=50)
    loop.protocol(0, targets=(8.0, 3.0, 8.0), dwell=50)
    est = loop.est
    # replay the loop's proximal samples through both implementations
    rng = np.random.default_rng(0)
    n = 3000
    t = np.arange(n) * 1e-3
    Ta = 4 + 4 * np.sin(t * 3) + rng.normal(0, 0.02, n)
    Tb = 0.3 + rng.normal(0, 0.02, n)
    xa = 1e-3 * np.sin(t * 3) + 6e-5 * Ta
    xb = -1e-3 * np.sin(t * 3)
    on = PairEstimator(est.tendons[0].model, est.tendons[1].model, est.r, n_nodes=40, pretension=0.3)
    rows = [on.step(*v) for v in zip(Ta, xa, Tb, xb, strict=False)]
    b = estimate_pair_batch(Ta, xa, Tb, xb, est.tendons[0].model, est.tendons[1].model, est.r, n_nodes=40,
                             pretension=0.3)
    assert np.allclose(b.torque, [s.torque for s in rows], rtol=0, atol=1e-12)
    assert np.allclose(b.angle, [s.angle for s in rows], rtol=0, atol=1e-12)
    assert np.allclose(b.T_out, [s.T_out for s in rows], rtol=0, atol=1e-12)
    assert np.ptp(b.angle) > 0.3
    # with the noise band (a joint's tendons: slack release side) the batch steps the estimator: the same numbers
    on = PairEstimator(est.tendons[0].model, est.tendons[1].model, est.r, n_nodes=40, pretension=0.3,
                        tension_noise=0.02)
    rows = [on.step(*v) for v in zip(Ta, xa, Tb, xb, t, strict=False)]
    bb = estimate_pair_batch(Ta, xa, Tb, xb, est.tendons[0].model, est.tendons[1].model, est.r, n_nodes=40,
                              pretension=0.3, tension_noise=0.02, time=t)
    assert np.array_equal(bb.torque, [s.torque for s in rows]) and np.array_equal(bb.T_out, [s.T_out for s in rows])
    assert np.abs(bb.T_out - b.T_out).max() > 1e-3                  # and the band changed them
    with pytest.raises(ValueError, match="time"):
        estimate_pair_batch(Ta, xa, Tb, xb, est.tendons[0].model, est.tendons[1].model, est.r, tension_noise=0.02,
                             time=t[:-1])


def test_bad_arguments_are_named():
    m = SheathModel(K=0.5, compliance=1e-4)
    with pytest.raises(ValueError, match="pulley_radius"):
        PairEstimator(m, m, 0.0)
    with pytest.raises(ValueError, match="play"):
        PairEstimator(m, m, 0.004, play=-1.0)
    with pytest.raises(ValueError, match="pretension"):
        PairEstimator(m, m, 0.004, pretension=(1.0, 2.0, 3.0))
    with pytest.raises(ValueError, match="x_b has a non-finite value at sample 2"):
        estimate_pair_batch(np.ones(3), np.zeros(3), np.ones(3), [0, 0, math.nan], m, m, 0.004)
    est = PairEstimator(m, m, 0.004)
    with pytest.raises(ValueError, match="finite"):
        est.step(math.nan, 0.0, 1.0, 0.0)


def test_a_slack_tendon_does_not_count_in_the_angle():
    m = SheathModel(K=0.5, compliance=1e-4)
    est = PairEstimator(m, m, 0.004, pretension=0.25)
    est.step(0.25, 0.0, 0.25, 0.0)                           # zero pose
    s = est.step(5.0, 0.004, 0.0, -0.009)                   # b slack: its motor paid out far too much
    assert s.angle == pytest.approx(s.angle_a) and abs(s.angle_b - s.angle_a) > 0.5
    s = est.step(5.0, 0.004, 0.05, -0.009)                  # half taut (taut_tension 0.1 N): half weight
    assert s.angle == pytest.approx((s.angle_a + 0.5 * s.angle_b) / 1.5)
    s = est.step(5.0, 0.004, 3.0, -0.0036)                  # both taut: the mean (J3)
    assert s.angle == pytest.approx(0.5 * (s.angle_a + s.angle_b))


@pytest.mark.parametrize("coupling,noise", [(True, 0.0), (False, 0.0), (True, 0.02), (False, 0.02)])
def test_the_compiled_step_is_the_per_tendon_step_bit_for_bit(coupling, noise):
    """Every sample after the first runs in one compiled call (joint_kernels.step_pair): the same estimates,
    profiles, phases, rates and coupling state as the tendons' own steps plus couple(), which the first
    sample (and any call without a time) still takes, with the noise band too (velocities and slide states);
    a non-finite sample is refused with nothing changed."""
    ma, mb = SheathModel(K=0.9, compliance=2e-4), SheathModel(K=1.1, compliance=1.5e-4)
    ref, new = (PairEstimator(ma, mb, 0.004, n_nodes=60, pretension=(1.0, 1.2), coupling=coupling,
                               tension_noise=noise) for _ in range(2))
    ref._compiled = False                                           # the per-tendon path
    rng = np.random.default_rng(3)
    t = np.arange(4000) * 1e-3
    c = 0.003 * np.sin(2 * np.pi * 0.7 * t) + 0.001 * np.sin(2 * np.pi * 3.1 * t)
    Ta = 1.5 + 400 * np.maximum(c, -0.002) + rng.normal(0, 0.02, t.size)
    Tb = 1.5 - 300 * c + rng.normal(0, 0.02, t.size)
    Ta[1500:1600] = -0.1                                            # tendon a slack for a while
    xa, xb = c + 1e-4 * Ta, -c + 1e-4 * Tb
    phases, angles, slid = set(), [], set()
    for k in range(t.size):
        tk = None if k == 2000 else t[k]
        a, b = ref.step(Ta[k], xa[k], Tb[k], xb[k], tk), new.step(Ta[k], xa[k], Tb[k], xb[k], tk)
        assert a == b and np.array_equal(ref._state, new._state)
        for u, v in zip(ref.tendons, new.tendons, strict=False):
            assert np.array_equal(u.profile, v.profile) and np.array_equal(u._phase_state, v._phase_state)
            assert (u.T_out, u.elongation, u.phase, u._rate, u._T_prev, u._t_prev, u.velocity, u._x_prev) == \
                (v.T_out, v.elongation, v.phase, v._rate, v._T_prev, v._t_prev, v.velocity, v._x_prev)
            assert np.array_equal(u._slide, v._slide)
            slid.add(float(v._slide[0]))
        phases.update(b.phase)
        angles.append(b.angle)
    assert len(phases) >= 3 and np.ptp(angles) > 0.5                # every phase law and a real stroke [rad]
    assert slid == ({-1.0, 0.0, 1.0} if noise else {0.0})           # the band's slides both ways, or none
    before = new.tendons[0].profile.copy()
    with pytest.raises(ValueError, match="finite"):
        new.step(math.nan, 0.0, 1.0, 0.0, 6.0)
    assert np.array_equal(new.tendons[0].profile, before)
