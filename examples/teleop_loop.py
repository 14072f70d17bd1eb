"""Master and slave in one script: the haptic loop over Zenoh on 127.0.0.1 for a few seconds.

    python examples/teleop_loop.py

Two Zenoh sessions in this process, one listening on a free loopback port and one connecting to it
(multicast scouting off), carry the commands and the estimates. The slave node drives the simulated
tendon-sheath rig and estimates the distal tension from the proximal load cell and encoder (profile
memory, :class:`estimator.DistalEstimator`) with the rig's own sheath model (examples/calibrate.py
calibrates it instead); the master node runs a scripted operator through the seed paper's protocol
(pull to 20 N, release to 5 N, pull, release) and renders the estimate as force. Both nodes are
stepped in turn at 1 kHz on the monotonic clock (``teleop demo`` runs them as two processes).
Prints the estimate against the simulator's truth once a second and the command round trip at the end.
"""
from __future__ import annotations

import time

import numpy as np

from estimator import SheathModel
from live.sides import master_links, slave_links
from master.devices import make_device
from master.node import MasterNode
from slave.node import SlaveNode, warm_up
from slave.simulated import SimulatedRig
from teleop.config.load import load_config
from teleop.session.transport import Session, free_tcp_port, loopback_endpoint, zenoh_config
from teleop.timing.clock import MonotonicClock

MAX_SECONDS = 12.0     # the protocol takes about 6 s once both sides are up


def run(cfg, clock: MonotonicClock, master: MasterNode, slave: SlaveNode, rig: SimulatedRig) -> np.ndarray:
    """Step both nodes at the master's rate until the protocol is done; rows of (t [s], T_out_hat, T_out [N])."""
    period, rows = 1.0 / cfg.master.rate_hz, []
    t0 = t_next = clock.now()
    while not master.done and clock.now() - t0 < MAX_SECONDS:
        now = clock.now()
        master.step(now)
        slave.step(now)
        sample, truth = slave.axes[0].sample, rig.state.truth
        if sample is not None and truth is not None:
            rows.append((now - t0, sample.T_out, truth.T_out))
            if len(rows) % 1000 == 0:
                print(f"t = {now - t0:4.1f} s  master {master.state.name:8s} slave {slave.state.name:8s} "
                      f"T_in {float(rig.state.T_in):6.2f} N  distal tension: estimate {sample.T_out:6.2f} N, "
                      f"true {truth.T_out:6.2f} N")
        t_next += period
        time.sleep(max(0.0, t_next - clock.now()))
    return np.asarray(rows)


def main() -> int:
    cfg = load_config(None, {"instrument.id": "example", "transport.multicast_scouting": False,
                             "master.device.type": "simulated", "recording.rerun": "off"})
    warm_up(cfg)                                  # compile the kernels before the loop
    rig = SimulatedRig.from_config(cfg)
    model = SheathModel.from_geometry(cfg.sheath.geometry(), cfg.rig.simulated.mu, cfg.sheath.EA)
    ep = loopback_endpoint(free_tcp_port())
    clock = MonotonicClock()
    device = make_device(cfg, "paper")
    try:
        with Session(zenoh_config(cfg.transport, listen=(ep,), connect=()), clock=clock) as zs, \
                Session(zenoh_config(cfg.transport, listen=(), connect=(ep,)), clock=clock) as zm:
            slave = SlaveNode(cfg, rig, slave_links(zs, cfg.instrument.id, None), calibrate=False, model=model)
            master = MasterNode(cfg, device, master_links(zm, cfg.instrument.id, None))
            rows = run(cfg, clock, master, slave, rig)
    finally:
        device.close()
    err = rows[:, 1] - rows[:, 2]
    lat = master.latency_stats()
    print(f"protocol {'finished' if master.done else 'not finished'} after {rows[-1, 0]:.1f} s; "
          f"{master.commands_sent} commands, {lat['n']} echoed")
    print(f"distal tension estimate: rms error {np.sqrt(np.mean(err ** 2)):.3f} N, max {np.abs(err).max():.3f} N "
          f"(true peak {rows[:, 2].max():.2f} N)")
    print(f"round trip (command -> estimate echo): p50 {lat['p50_ms']:.2f} ms, p99 {lat['p99_ms']:.2f} ms")
    return 0 if master.done else 1


if __name__ == "__main__":
    raise SystemExit(main())
