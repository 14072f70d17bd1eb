"""PairController: modes and side switching, bumpless take-over, tension loop on the simulated pair."""
from __future__ import annotations

import math

import numpy as np
import pytest

from slave.pair_control import PairController, PairMode
from tests.slave.joint_helpers import DT, Loop, joint_config, route_model


def make(**kw):
    args = dict(pulley_radius=0.004, set_tension=0.25, gain=0.01, band=0.01, max_speed=0.05, x_init=(1e-4, 2e-4))
    args.update(kw)
    return PairController(**args)


def test_modes_follow_the_sign_of_the_command_with_hysteresis():
    c = make()
    seq = [(None, PairMode.IDLE), (0.005, PairMode.IDLE), (0.011, PairMode.PULL_A), (0.006, PairMode.PULL_A),
           (0.004, PairMode.IDLE), (-0.011, PairMode.PULL_B), (-0.006, PairMode.PULL_B), (math.nan, PairMode.IDLE),
           (0.2, PairMode.PULL_A), (-0.2, PairMode.PULL_B)]
    for cmd, mode in seq:
        c.step(cmd, (0.25, 0.25), DT)
        assert c.mode == mode, cmd
    assert c.switches == 6


def test_take_over_is_bumpless_and_position_follows_the_command():
    c = make()
    xa, xb = c.step(0.02, (0.25, 0.25), DT)
    assert (xa, xb) == pytest.approx((1e-4, 2e-4))          # entering PULL_A: no jump
    xa, _ = c.step(0.12, (0.25, 0.25), DT)
    assert xa == pytest.approx(1e-4 + 0.004 * 0.10)         # x = x_ref + r (c - c_ref)
    c.step(0.0, (0.25, 0.25), DT)                            # idle
    x_b0 = c.x_cmd[1]
    _, xb = c.step(-0.02, (0.25, 0.25), DT)
    assert xb == pytest.approx(x_b0)
    _, xb = c.step(-0.10, (0.25, 0.25), DT)
    assert xb == pytest.approx(x_b0 + 0.004 * 0.08)          # b pulls for - commands


def test_tension_loop_is_integral_and_rate_limited():
    c = make()
    x0 = c.x_cmd[1]
    c.step(None, (0.25, 0.15), DT)                          # b too loose by 0.1 N: reel in g * 0.1 * dt
    assert c.x_cmd[1] - x0 == pytest.approx(0.01 * 0.1 * DT)
    c.step(None, (0.25, -1e3), DT)                          # absurd reading: at most max_speed * dt
    assert c.x_cmd[1] - x0 == pytest.approx(0.01 * 0.1 * DT + 0.05 * DT)


def test_feedforward_follows_the_estimated_joint_not_the_command():
    c = make(play=0.0)
    c.step(0.02, (5.0, 0.25), DT, x_out_hat=(0.0, 0.0))
    x_b0 = c.x_cmd[1]
    # commanded travel but the puller's tip stuck (dead zone, limit): the antagonist holds
    c.step(0.2, (6.0, 0.25), DT, x_out_hat=(0.0, 0.0))
    assert c.x_cmd[1] == pytest.approx(x_b0)
    # the puller's tip moved 0.3 mm toward the actuator: the antagonist pays out 0.3 mm
    c.step(0.2, (6.0, 0.25), DT, x_out_hat=(3e-4, -3e-4))
    assert c.x_cmd[1] == pytest.approx(x_b0 - 3e-4)


def test_antagonist_holds_its_set_tension_on_the_simulated_pair():
    loop = Loop(joint_config())
    T_b = np.array([r[8] for r in loop.rows])
    assert abs(T_b[-50:].mean() - 0.25) < 0.02             # idle: both tendons at T_set
    rows = loop.protocol(0)
    T_b = rows[:, 8]
    assert 0.1 < T_b.min() and T_b.max() < 0.6               # never slack, never pulled tight
    assert rows[:, 9].max() > 19.9                           # tendon a reached the protocol's 20 N


@pytest.mark.parametrize("kw, match", [({"pulley_radius": 0.0}, "pulley_radius"), ({"gain": -1.0}, "gain"),
                                       ({"band": math.nan}, "band"), ({"play": -1.0}, "play")])
def test_bad_settings_are_named(kw, match):
    with pytest.raises(ValueError, match=match):
        make(**kw)


def test_travel_limits_clip_every_motor_command():
    c = make(x_limits=((0.0, 2e-3), (-1e-3, 1e-3)))
    c.step(0.02, (0.25, 0.25), DT)
    xa, xb = c.step(5.0, (0.25, 0.25), DT)                  # a runaway command: 20 mm of tendon a
    assert xa == 2e-3 and xb == pytest.approx(2e-4)
    for _ in range(100):
        xa, xb = c.step(None, (0.25, 50.0), DT)              # tension loop paying b out hard
    assert xb == -1e-3
    with pytest.raises(ValueError, match="x_limits"):
        make(x_limits=((1.0, 0.0), (0.0, 1.0)))


def test_backlash_compensation_pays_out_the_band_over_the_play_and_takes_it_back():
    c = make(band_compliance=(1e-4, 2e-4), band_width=0.005, friction_exponent=(0.5, 0.5))
    ref = make()
    for cmd, T in ((0.02, 0.25), (0.10, 6.0), (0.20, 10.0)):      # pulling: the same commands as uncompensated
        assert c.step(cmd, (T, 0.25), DT)[0] == pytest.approx(ref.step(cmd, (T, 0.25), DT)[0])
    # turned back by 2 w: tendon a pays out c_rev,a T0 (T0 the tension where the command turned), linear in
    # between; inside the band (T_in e^2K >= T0) the payout does not depend on the tension
    for back, share in ((0.0025, 0.25), (0.005, 0.5), (0.010, 1.0), (0.05, 1.0)):
        xa, xr = c.step(0.20 - back, (8.0, 0.25), DT)[0], ref.step(0.20 - back, (8.0, 0.25), DT)[0]
        assert xr - xa == pytest.approx(share * 1e-4 * 10.0)
    # past the band the payout follows the band at the pull-branch tension T_in e^2K, filtered: 0 when slack
    for _ in range(100):                                           # 10 time constants
        xa, xr = c.step(0.14, (2.0, 0.25), DT)[0], ref.step(0.14, (2.0, 0.25), DT)[0]
    assert xr - xa == pytest.approx(1e-4 * 2.0 * math.e, rel=1e-3)
    for _ in range(100):
        xa, xr = c.step(0.13, (0.0, 0.25), DT)[0], ref.step(0.13, (0.0, 0.25), DT)[0]
    assert 0.0 <= xr - xa < 1e-4 * 2.0 * math.e * 1e-4
    # a pull after the release takes the same travel back over the same play: no ratchet
    rng = np.random.default_rng(1)
    for cmd in 0.15 + 0.004 * rng.standard_normal(200):          # jitter of the hand about one command
        c.step(cmd, (8.0, 0.25), DT)
        ref.step(cmd, (8.0, 0.25), DT)
    xa, xr = c.step(0.30, (9.0, 0.25), DT)[0], ref.step(0.30, (9.0, 0.25), DT)[0]
    assert xa == pytest.approx(xr)
    # tendon b pulling (- commands): the same, on b
    c.step(-0.05, (0.25, 0.25), DT), ref.step(-0.05, (0.25, 0.25), DT)
    c.step(-0.20, (0.25, 7.0), DT), ref.step(-0.20, (0.25, 7.0), DT)
    xb, xr = c.step(-0.18, (0.25, 6.0), DT)[1], ref.step(-0.18, (0.25, 6.0), DT)[1]
    assert xr - xb == pytest.approx(2e-4 * 7.0)
    with pytest.raises(ValueError, match="band_width"):
        make(band_compliance=(1e-4, 1e-4), band_width=0.0)
    with pytest.raises(ValueError, match="band_compliance"):
        make(band_compliance=(1e-4, -1e-4))
    with pytest.raises(ValueError, match="friction_exponent"):
        make(band_compliance=(1e-4, 1e-4), friction_exponent=(math.nan, 0.5))


def _dead_zone(loop: Loop) -> tuple[float, float, float]:
    """Pull tendon a to 15 N into the tissue, then turn the command back at 0.5 rad/s: the command travel [rad]
    before the joint has turned back 0.5 mrad, the tension the reversal started from [N], the command then [rad]."""
    c = 0.0
    while loop.state.T_in[0, 0] < 15.0:
        c += 1.25 * DT
        loop.step(c)
    for _ in range(200):
        loop.step(c)
    T0, theta0, c0 = loop.state.T_in[0, 0], loop.state.truth.theta[0], c
    while loop.state.truth.theta[0] > theta0 - 5e-4:
        c -= 0.5 * DT
        loop.step(c)
    return c0 - c, T0, c


def _release(loop: Loop, c: float) -> tuple[float, float]:
    """The command from ``c`` back to 0.02 rad at 0.5 rad/s, then held 0.3 s: the least tension of tendon a
    [N] on the way, and the joint angle at the end [rad]."""
    low = math.inf
    while c > 0.02:
        c -= 0.5 * DT
        loop.step(c)
        low = min(low, loop.state.truth.T_in[0, 0])
    for _ in range(300):
        loop.step(c)
    return low, loop.state.truth.theta[0]


def _compensated(cfg, k_factor: float = 1.0) -> Loop:
    """The joint's loop with backlash compensation from models of its tendons with K times ``k_factor``."""
    loop = Loop(cfg)
    K, j = loop.rig.K[0], loop.joint
    ma, mb = route_model(j.tendons.a, K[0] * k_factor), route_model(j.tendons.b, K[1] * k_factor)
    loop.ctl.band_compliance = (ma.reversal_compliance, mb.reversal_compliance)
    loop.ctl.friction_exponent = (ma.K, mb.K)
    return loop


def test_the_reversal_band_predicts_the_dead_zone_and_compensation_removes_it():
    cfg = joint_config()
    plain = Loop(cfg)
    j, K = plain.joint, plain.rig.K[0]
    model_a = route_model(j.tendons.a, K[0])
    dz, T0, c = _dead_zone(plain)
    low, theta_end = _release(plain, c)
    predicted = model_a.reversal_compliance * T0 / j.pulley_radius
    print(f"dead zone {dz:.4f} rad, predicted {predicted:.4f} rad")
    assert 0.9 * predicted < dz < 1.2 * predicted, (dz, predicted)     # + the tissue spring, the 0.5 mrad
    comp = _compensated(cfg)
    dz_comp, _, c = _dead_zone(comp)
    low_comp, theta_end_comp = _release(comp, c)
    print(f"with compensation {dz_comp:.4f} rad; tension a at least {low:.3f} / {low_comp:.3f} N, "
          f"end angle {theta_end:.4f} / {theta_end_comp:.4f} rad")
    assert dz_comp < 0.15 * dz, (dz_comp, dz)                             # what is left: the play, 2 w
    # the payout shrinks with the tension: the released tendon is never slack, the joint ends where it would
    assert low_comp > 0.5 * low and abs(theta_end_comp - theta_end) < 0.01


@pytest.mark.parametrize("k_factor, dz_share", [(0.7, 0.6), (1.5, 0.15)])
def test_a_miscalibrated_band_still_shortens_the_dead_zone_and_never_slackens_the_tendon(k_factor, dz_share):
    cfg = joint_config()
    plain = Loop(cfg)
    dz, _, c = _dead_zone(plain)
    low, theta_end = _release(plain, c)
    comp = _compensated(cfg, k_factor)      # K off by k_factor: c_rev and e^2K of the wrong friction
    dz_comp, _, c = _dead_zone(comp)
    low_comp, theta_end_comp = _release(comp, c)
    assert dz_comp < dz_share * dz, (dz_comp, dz)
    assert low_comp > 0.5 * low and abs(theta_end_comp - theta_end) < 0.01
