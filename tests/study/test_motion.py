"""Operator-like motion (study/motion.py) and the lab loads of both simulators' scenario generators."""
from __future__ import annotations

import numpy as np
import pytest

from study.lumped.scenarios import record as lumped_record
from study.lumped.simulator import Load
from study.motion import HAND_SPEED, hand_motion
from study.scenarios import record


def test_hand_motion_is_seeded_bounded_and_holds():
    x = hand_motion(60.0, 1000.0, 1e-3, 10e-3, np.random.default_rng(4))
    again = hand_motion(60.0, 1000.0, 1e-3, 10e-3, np.random.default_rng(4))
    other = hand_motion(60.0, 1000.0, 1e-3, 10e-3, np.random.default_rng(5))
    assert x.shape == (60000,) and np.array_equal(x, again) and not np.array_equal(x, other)
    v = np.abs(np.diff(x)) * 1000.0
    assert v.max() <= HAND_SPEED * (1 + 1e-9) and v.max() > 0.5 * HAND_SPEED
    assert x[0] == 0.0 and x.min() >= 0.0 and x.max() <= 10e-3 + 1e-12
    assert 0.1 < np.mean(v < 1e-6) < 0.7                    # holds, and mostly moves
    reversals = np.sum(np.diff(np.sign(np.diff(x)[np.abs(np.diff(x)) > 1e-9])) != 0)
    assert reversals > 30                                   # many moves of both signs in a minute
    with pytest.raises(ValueError, match="x_top"):
        hand_motion(5.0, 100.0, 1e-3, 1e-3, np.random.default_rng(0))


def test_lumped_tissue_stiffens_and_contact_starts_in_free_space():
    tissue = Load("tissue", stiffness=500.0, limit=2e-3)
    lx, lF, ls = tissue.graph()
    assert np.all(np.diff(ls[1:]) > 0) and lF[0] == 0.0                 # slope rises piece by piece
    assert tissue.position_at(500.0 * 2e-3 * np.expm1(1.0)) == pytest.approx(2e-3, rel=0.05)
    contact = Load("contact", stiffness=50.0, limit=2e-3, contact_stiffness=2000.0)
    assert contact.position_at(0.05) == pytest.approx(1e-3)              # free space: the soft spring
    assert contact.position_at(0.1 + 2050.0 * 1e-3) == pytest.approx(3e-3)
    with pytest.raises(ValueError, match="load.limit"):
        Load("tissue", stiffness=500.0)


@pytest.mark.parametrize("load", ["tissue", "contact"])
def test_both_simulators_record_hand_motion_on_the_lab_loads(load):
    base = record(None, seed=3, duration=8.0, rate_hz=500.0)
    rec = record(None, seed=3, duration=8.0, rate_hz=500.0, motion="hand", load=load)
    assert rec.truth["K"] == base.truth["K"] and rec.truth["load"]["kind"] == load and rec.truth["motion"] == "hand"
    assert 5.0 < rec.data.T_in.max() < 30.0
    lum = lumped_record(None, seed=3, duration=8.0, rate_hz=500.0, motion="hand", load=load)
    assert lum.truth["load"]["kind"] == load and lum.truth["K"] == lumped_record(None, seed=3, duration=5.0).truth["K"]
    assert np.abs(np.diff(lum.data.x_in)).max() * 500.0 <= 1.2 * HAND_SPEED
    with pytest.raises(ValueError, match="motion"):
        record(None, seed=3, duration=8.0, motion="robot")
