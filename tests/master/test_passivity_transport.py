"""Passivity over the real transport: delay and loss injected between two zenoh sessions on loopback.

In-process (deterministic) version of the two-process loop: a :class:`MasterNode` and a
:class:`SlaveNode` each with its own zenoh session (peer mode, 127.0.0.1, multicast off), the
master's commands and the slave's estimates passed through a :class:`live.faults.FaultInjector`
(20 ms each way = 40 ms round trip, 10 % of the messages lost, seeded). Both nodes and both injectors
run on one FakeClock; after each step the test waits until zenoh has delivered every message the
injector released (it waits for delivery, never for time), so a run is the same every time.

The coupled loop: a hand with arm impedance (mass m, spring k_h to the intended position, damper
b_h; Hogan's model with dynamics) holds the handle; the slave is the simulated tendon-sheath rig
(calibrated model, estimator) pressing on stiff tissue; the master renders -force_scale T_out_hat.
With the passivity controller off the observer at the master port sees the network generate
energy (E < 0) and the handle oscillation grows; with it on, E >= 0 at every sample, the hand
has no limit cycle, drifts slowly (the release time of :mod:`master.passivity`) and the force stays
within the clamp.
"""
from __future__ import annotations

import numpy as np
import pytest

from estimator.sheath import SheathModel
from live.faults import FaultInjector
from master.device import DeviceState
from master.node import MasterNode
from master.node_base import MasterLinks
from slave.node import SlaveNode
from slave.node_base import SlaveLinks
from slave.simulated import SimulatedRig
from teleop.config.load import config_from_dict
from teleop.session.transport import Session, free_tcp_port, loopback_endpoint, zenoh_config
from teleop.timing.clock import FakeClock
from teleop.timing.loop_metrics import CHATTER_LIMITS, chatter
from teleop.wire.keys import command_key, estimate_key, heartbeat_key
from teleop.wire.messages import Command, Estimate, Heartbeat, Side, SideState

DT = 1e-3
DELAY, LOSS = "20ms", 0.1


class ArmHand:
    """The handle held by a hand with dynamics: m a = k_h (x_h - x) - b_h v + F_device."""

    def __init__(self, m=0.4, k_h=150.0, b_h=4.0, step=0.01, t_step=0.3):
        self.m, self.k_h, self.b_h, self.step_to, self.t_step = m, k_h, b_h, step, t_step
        self.x = self.v = self.f = 0.0
        self.t0: float | None = None
        self.engaged_at: float | None = None

    def watch(self, T_in, engaged):
        self.engaged = engaged

    def read(self, t):
        if self.t0 is None:
            self.t0 = t
        if getattr(self, "engaged", False) and self.engaged_at is None:
            self.engaged_at = t
        x_h = self.step_to if self.engaged_at is not None and t - self.engaged_at >= self.t_step else 0.0
        # semi-implicit Euler of m a = k_h (x_h - x) - b_h v + F
        self.v += (self.k_h * (x_h - self.x) - self.b_h * self.v + self.f) / self.m * DT
        self.x += self.v * DT
        return DeviceState(t, self.x)

    def set_force(self, force, t):
        self.f = force

    def close(self):
        self.f = 0.0


CFG = {
    "instrument": {"id": "pctx"},
    "rig": {"simulated": {"load": {"tissue_stiffness": 6000.0}, "sensors": {"load_cell_noise": 0.0}}},
    "master": {"mapping": {"motion_scale": 1.0, "force_scale": 0.5, "force_limit": 20.0, "ramp_time": 0.05,
                           "force_rate_limit": 1.0e5}},
    "estimator": {"profile_points": 0},
    "recording": {"rerun": "off"},
    # a stiff, fast force channel at the edge of stability: the point of the test, past the hard bounds
    "safety": {"override": ["master.mapping.force_limit", "master.mapping.force_rate_limit",
                            "master.mapping.passivity"]},
}


def _wait_delivered(subs, injector, base, what):
    target = base + injector.counts["passed"]
    for _ in range(2000):
        if sum(s.count + s.errors for s in subs) >= target:
            return
        subs[0].wait(subs[0].count + 1, timeout=0.005)
    raise AssertionError(f"zenoh did not deliver the {what} within 10 s")


def run_loop(passivity: bool, T: float = 3.0, seed: int = 1):
    cfg = config_from_dict({**CFG, "master": {**CFG["master"], "mapping": {**CFG["master"]["mapping"],
                                                                           "passivity": passivity}}})
    clock = FakeClock(1000.0)
    ep = loopback_endpoint(free_tcp_port())
    ident = cfg.instrument.id
    rig = SimulatedRig.from_config(cfg)
    with Session(zenoh_config(cfg.transport, listen=(ep,), connect=()), clock=clock) as zs, \
            Session(zenoh_config(cfg.transport, listen=(), connect=(ep,)), clock=clock) as zm:
        inj_m = FaultInjector(f"delay={DELAY},drop={LOSS},seed={seed},stream=command", clock)
        inj_s = FaultInjector(f"delay={DELAY},drop={LOSS},seed={seed + 100},stream=estimate", clock)
        s_cmd = zs.subscriber(command_key(ident), Command)
        s_hb = zs.subscriber(heartbeat_key(ident, "master"), Heartbeat)
        m_est = zm.subscriber(estimate_key(ident), Estimate)
        m_hb = zm.subscriber(heartbeat_key(ident, "slave"), Heartbeat)
        slave = SlaveNode(cfg, rig, SlaveLinks(inj_s.wrap(zs.publisher(estimate_key(ident)), "estimate"),
                                               inj_s.wrap(zs.publisher(heartbeat_key(ident, "slave")), "heartbeat"),
                                               s_cmd, s_hb),
                          calibrate=False, model=SheathModel(K=rig.K, compliance=rig.M_e / 1.0))
        hand = ArmHand()
        master = MasterNode(cfg, hand, MasterLinks(inj_m.wrap(zm.publisher(command_key(ident)), "command"),
                                                   inj_m.wrap(zm.publisher(heartbeat_key(ident, "master")),
                                                              "heartbeat"), m_est, m_hb))
        # both sessions see each other's subscribers before the clock starts (a put before that is lost)
        probe_c, probe_h = zm.publisher(command_key(ident)), zs.publisher(heartbeat_key(ident, "slave"))
        for _ in range(400):
            probe_c.put(Command(0, clock.now(), (0.0,), False))
            probe_h.put(Heartbeat(Side.SLAVE, 0, clock.now(), SideState.SAFE))
            if s_cmd.wait(1, 0.025) and m_hb.wait(1, 0.025):
                break
        base_s, base_m = s_cmd.count + s_hb.count, m_est.count + m_hb.count
        out = {k: [] for k in ("t", "x", "f", "E", "state")}
        n = int(round(T / DT))
        for _ in range(n):
            clock.advance(DT)
            now = clock.now()
            master.step(now)
            inj_m.pump(now)
            _wait_delivered([s_cmd, s_hb], inj_m, base_s, "commands")
            slave.step(now)
            inj_s.pump(now)
            _wait_delivered([m_est, m_hb], inj_s, base_m, "estimates")
            out["t"].append(now)
            out["x"].append(hand.x)
            out["f"].append(master.force[0])
            out["E"].append(master.passivity[0].energy)
            out["state"].append(int(master.state))
    return {k: np.asarray(v) for k, v in out.items()}, master, (inj_m.counts, inj_s.counts)


@pytest.fixture(scope="module")
def runs():
    return {pc: run_loop(pc, T=2.5, seed=1) for pc in (False, True)}


def test_the_injected_link_is_what_the_issue_asks_for(runs):
    _, _, (to_slave, to_master) = runs[True]
    for c in (to_slave, to_master):                  # commands / estimates: 10 % lost, the rest delayed 20 ms
        n = c["delayed"] + c["dropped"]
        assert 0.07 < c["dropped"] / n < 0.13 and c["delayed"] > 0.9 * c["passed"]


def test_without_the_passivity_controller_the_delayed_lossy_loop_is_not_passive(runs):
    out, master, _ = runs[False]
    assert out["E"].min() < -0.1                     # the network generated > 0.1 J at the master port (-0.39 J)
    assert np.abs(out["x"]).max() > 3 * 0.01         # the handle swings far past the 10 mm target (50 mm)
    assert master.safe_events >= 1                   # and only the safety layer stops it
    assert np.abs(out["f"]).max() <= 20.0            # even so, never above the clamp


def test_with_the_passivity_controller_it_stays_passive_stable_and_clamped(runs):
    out, master, _ = runs[True]
    assert out["E"].min() >= -1e-9                   # observer energy at every sample
    assert np.abs(out["x"]).max() < 0.01             # no overshoot past the target (7.5 mm)
    # no burst: the hand's motion above 30 Hz in its worst 100 ms window after the first 0.5 s stays
    # below the demo's command limit seen at the hand (20 um of tendon / motion_scale 0.2 = 100 um);
    # measured 17 um (0.5-1.5 s) and 23 um (1.5-2.5 s); the gain in one sample before: 41 and 19 um
    after = out["t"] >= out["t"][0] + 0.5
    assert chatter(out["t"][after], out["x"][after])[1] < CHATTER_LIMITS["x_in_cmd_m"] / 0.2
    # the price (TDPA's position drift): the force comes back over ~50 ms after each cut, so the hand
    # sinks slowly into the delayed tissue (4.1 mm at the end, 1.1 mm before), but the tissue still
    # pushes back: short of the hand's target and a clear mean force in the last second
    last = out["t"] >= out["t"][-1] - 1.0
    assert out["x"][-1] < 0.0075 and out["f"][last].mean() < -0.5
    assert np.mean(out["state"] == 3) > 0.95 and master.safe_events == 0
    assert np.abs(out["f"]).max() <= 20.0 and master.passivity[0].stats.active_steps > 100
