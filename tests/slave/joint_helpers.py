"""Shared test helpers: a simulated joint in closed loop with the pair controller and the estimator,
driven through the seed paper's protocol (pull to 20 N, release to 5 N, pull to 20 N, release) by a
scripted joint-angle command that watches the pulling tendon's load cell."""
from __future__ import annotations

import numpy as np

from estimator.online.pair import PairEstimator
from estimator.sheath import SheathModel
from slave.pair_control import PairController
from slave.pair_rig import SimulatedInstrument
from teleop.config.load import config_from_dict
from teleop.config.schema import TendonConfig

DT = 1e-3
ROUTE_B = [{"length": 0.5}, {"length": 0.8, "radius": 0.25}, {"length": 0.3, "radius": 0.1}]


def joint_config(pretension: float = 0.0, seed: int = 0, n_elements: int = 100, **physics):
    """One joint with different routes and mu for its two tendons; a tissue spring on both sides;
    ``physics``: settings of its simulated physics (rig.simulated.joints: stiffness, damping, ...)."""
    j = {"name": "j", "pretension": pretension, "tendons": {"b": {"runs": ROUTE_B}}}
    sim = {"name": "j", "load": {"tissue_stiffness": 0.05}, "tendons": {"a": {"mu": 0.1}, "b": {"mu": 0.12}}, **physics}
    return config_from_dict({"instrument": {"joints": [j]}, "rig": {"simulated": {
        "n_elements": n_elements, "sensors": {"seed": seed}, "joints": [sim]}}})


def route_model(t: TendonConfig, K: float) -> SheathModel:
    """The estimator's model of a tendon: its route shape and L/EA from the config, friction exponent K."""
    g = t.geometry()
    s = np.linspace(0.0, g.length, 257)
    return SheathModel(K=K, compliance=g.length / t.EA, wrap_shape=g.wrap_angle(s) / g.total_angle)


class Loop:
    """Rig + controller + estimator of joint 0, stepped together (the slave's cycle without transport)."""

    def __init__(self, cfg, *, K=None, coupling=True, min_tension=0.25, settle=300):
        self.rig = SimulatedInstrument.from_config(cfg)
        j = cfg.instrument.joints[0]
        self.joint = j
        K = self.rig.K[0] if K is None else K
        self.est = PairEstimator(route_model(j.tendons.a, K[0]), route_model(j.tendons.b, K[1]), j.pulley_radius,
                                  pretension=j.pretension, coupling=coupling)
        self.T_set = j.pretension if j.pretension > 0 else min_tension
        st = self.rig.state
        self.ctl = PairController(j.pulley_radius, self.T_set, 0.01, 0.01, 0.05, tuple(st.x_in[0]))
        self.state = st
        self.sample = self.est.step(st.T_in[0, 0], st.x_in[0, 0], st.T_in[0, 1], st.x_in[0, 1], st.t)
        self.cmd = None
        self.rows: list[tuple] = []
        for _ in range(settle):
            self.step(None)

    def step(self, cmd):
        st = self.state
        x = self.ctl.step(cmd, st.T_in[0], DT, self.sample.x_out)
        st = self.state = self.rig.step([x], DT)
        s = self.sample = self.est.step(st.T_in[0, 0], st.x_in[0, 0], st.T_in[0, 1], st.x_in[0, 1], st.t)
        tr = st.truth
        self.rows.append((tr.torque[0], s.torque, tr.theta[0], s.angle, tr.T_out[0, 0], s.T_out[0], tr.T_out[0, 1],
                          s.T_out[1], tr.T_in[0, 1], tr.T_in[0, 0], int(self.ctl.mode)))
        return s

    def protocol(self, side: int, targets=(20.0, 5.0, 20.0), speed=1.25, dwell=200, start=0.0):
        """Run the paper's protocol on tendon ``side`` (0 = a, 1 = b); returns the rows of this run as an array
        (columns: torque, torque_hat, theta, angle_hat, T_out_a, ..._hat, T_out_b, ..._hat, T_in_b, T_in_a, mode)."""
        first = len(self.rows)
        c = start
        sgn = 1.0 if side == 0 else -1.0
        for target in tuple(targets) + (self.T_set + 0.5,):
            direction = 1.0 if target > self.state.T_in[0, side] else -1.0
            for _ in range(20000):
                T = self.state.T_in[0, side]
                if (T >= target) if direction > 0 else (T <= target):
                    break
                c += sgn * direction * speed * DT
                self.step(c)
            for _ in range(dwell):
                self.step(c)
        self.cmd = c
        return np.array(self.rows[first:])


def max_fs(rows: np.ndarray, true_col: int = 0, est_col: int = 1) -> float:
    """Max |estimate - truth| over the range of the truth (full-scale error)."""
    return float(np.abs(rows[:, est_col] - rows[:, true_col]).max() / np.ptp(rows[:, true_col]))
