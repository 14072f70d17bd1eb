"""Human arm + device model: natural frequency and damping, friction holds, stability at any step."""
from __future__ import annotations

import math

import numpy as np
import pytest

from master.arm import ArmParameters, HumanArm
from teleop.errors import ConfigError


def test_free_response_matches_the_second_order_system():
    a = ArmParameters(mass=1.0, damping=4.0, stiffness=400.0, device_mass=0.0, device_damping=0.0,
                      device_friction=0.0)
    arm = HumanArm(a, max_substep=1e-4)
    arm.reset(0.01)
    dt, xs = 1e-3, []
    for _ in range(2000):
        xs.append(arm.step(dt, 0.0, 0.0, 0.0))
    xs = np.array(xs)
    up = np.flatnonzero((xs[:-1] < 0) & (xs[1:] >= 0))      # upward zero crossings: one per period
    period = np.diff(up).mean() * dt
    wn = math.sqrt(400.0)
    wd = wn * math.sqrt(1 - a.damping_ratio ** 2)
    assert period == pytest.approx(2 * math.pi / wd, rel=0.02)
    assert a.natural_frequency_hz == pytest.approx(wn / (2 * math.pi))
    assert abs(xs[-1]) < 1e-4                                 # decays


def test_coulomb_friction_holds_a_force_below_it_and_yields_above():
    a = ArmParameters(mass=0.5, damping=0.0, stiffness=1e-6, device_mass=0.1, device_damping=0.0,
                      device_friction=0.3)
    arm = HumanArm(a)
    for _ in range(100):
        arm.step(1e-3, 0.0, 0.0, 0.25)
    assert arm.p == 0.0 and arm.v == 0.0
    for _ in range(100):
        arm.step(1e-3, 0.0, 0.0, 0.5)
    assert arm.v == pytest.approx(0.2 / 0.6 * 0.1, rel=0.05)   # (F - F_c) t / m


def test_stiff_arm_with_a_long_step_stays_bounded():
    arm = HumanArm(ArmParameters(stiffness=800.0, mass=1.0, damping=5.0))
    arm.reset(0.05)
    for _ in range(200):
        arm.step(0.02, 0.0, 0.0, 0.0)                          # 20 ms steps, cut into 1 ms sub-steps
    assert abs(arm.p) < 1e-3


def test_bad_parameters_are_named():
    with pytest.raises(ConfigError, match="master.device.arm.mass"):
        ArmParameters(mass=0.0)
    with pytest.raises(ConfigError, match="device_friction"):
        ArmParameters(device_friction=-1.0)
