"""The one drive model (motor loop, encoder, load cell) of every simulated rig."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from slave.drive import NOISE_BLOCK, Drive
from slave.pair_rig import SimulatedInstrument
from slave.simulated import SimulatedRig
from teleop.config.load import load_config
from teleop.config.schema import MotorConfig, SensorConfig, SimulatedRigConfig


def rig(noise=0.1, seed=5, **motor):
    return SimulatedRigConfig(motor=MotorConfig(**motor), sensors=SensorConfig(load_cell_noise=noise, seed=seed))


def test_motor_step_is_the_exact_first_order_step_and_speed_limited():
    d = Drive(rig(bandwidth_hz=20.0, max_speed=0.05))
    h = 1e-3
    assert d.move(0.0, 1e-4, h) == pytest.approx(-math.expm1(-2 * math.pi * 20.0 * h) * 1e-4, rel=1e-15)
    assert d.move(0.0, 1.0, h) == pytest.approx(0.05 * h) and d.move(0.0, -1.0, h) == pytest.approx(-0.05 * h)
    arr = Drive(rig(bandwidth_hz=20.0, max_speed=0.05), (2, 2))
    out = arr.move(np.zeros((2, 2)), np.array([[1e-4, 1.0], [-1.0, 0.0]]), h)
    assert np.allclose(out, [[d.move(0.0, 1e-4, h), 0.05 * h], [-0.05 * h, 0.0]], rtol=1e-15, atol=0.0)


def test_encoder_quantises_and_the_noise_stream_is_the_same_for_any_shape():
    d1, d4 = Drive(rig()), Drive(rig(), (2, 2))
    q = d1.encoder_resolution
    assert q == pytest.approx(2 * math.pi * MotorConfig().pulley_radius / MotorConfig().encoder_lines_per_rev)
    assert d1.encoder(3.4 * q) == pytest.approx(3 * q) and np.allclose(d4.encoder(np.full((2, 2), 3.6 * q)), 4 * q)
    one = np.array([d1.load_cell_noise() for _ in range(4 * (NOISE_BLOCK + 10))])
    four = np.array([d4.load_cell_noise() for _ in range(NOISE_BLOCK + 10)]).ravel()
    assert np.array_equal(one, four) and 0.09 < one.std() < 0.11


def test_both_simulated_rigs_use_it():
    single = SimulatedRig.from_config(load_config())
    inst = SimulatedInstrument.from_config(load_config(Path(__file__).resolve().parents[2] / "configs" /
                                                       "instrument-3dof.yaml"))
    assert isinstance(single.drive, Drive) and single.drive.shape == ()
    assert isinstance(inst.drive, Drive) and inst.drive.shape == (3, 2)
