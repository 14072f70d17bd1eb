"""PairController: modes and side switching, bumpless take-over, tension loop on the simulated pair."""
from __future__ import annotations

import math

import numpy as np
import pytest

from slave.pair_control import PairController, PairMode
from tests.slave.joint_helpers import DT, Loop, joint_config


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
