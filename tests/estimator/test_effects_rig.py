"""A cross-check of the effect kernel against the simulated rig: two implementations of the same physics, driven
differently (the rig by x_in over 100 elements, the kernel by the rig's T_in on 32 nodes). Each physical effect of
RIG_CASES, switched on in both, gives T_out and x_out within its tolerances, far closer to the rig than the base.

Tolerances: in N and m, stated per effect.
"""
import math

import numpy as np
import pytest

from estimator.geometry import SheathGeometry
from estimator.offline.effects import catalogue as effects_module
from estimator.offline.effects.catalogue import (
    predict,
)
from estimator.offline.effects.types import (
    Series,
)
from slave.simulated import SimulatedRig
from study.scenarios import protocol
from teleop.config.effects import EffectsConfig, EffectSwitch
from teleop.config.schema import LoadConfig, RunConfig, SensorConfig, SheathConfig, SimulatedRigConfig
from tests.estimator.effects_series import EA, K, L, series

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
