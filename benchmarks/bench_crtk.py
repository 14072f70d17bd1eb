"""What ROS 2 publishing costs the slave's 1 kHz loop: time per SlaveNode.step [ms] with ``ros2`` off and on.

One SlaveNode of a single tendon (simulated rig, estimator, no recording) follows engaged commands
through in-memory links, paced at 1 kHz on the real clock as ``teleop slave`` paces it: after each step
the loop opens the idle window (:data:`teleop.timing.realtime.IDLE`) until its next deadline less 0.1 ms and
sleeps. With ``ros2`` on, the CRTK side (:mod:`teleop.ros2.side`) is attached on a loopback Zenoh
session with a ROS 2 subscriber of every topic, and its thread publishes the 7 topics at
``ros2.rate_hz`` (100 Hz); ``path`` is ``on`` with that thread stopped (what the loop itself adds: the
hook, the estimate tee, the merged command source). Prints p50/p99/max of the step time, the overruns of the 1 kHz grid,
the publications done, and the cost of one ``offer`` call alone. Never fails on time.
"""
from __future__ import annotations

import math
import os
import sys
import time
import timeit

import numpy as np
from bench_slave_cycle import LatestTopic  # a sibling script: the benchmarks folder is the running script's own

from estimator.sheath import SheathModel
from slave.node import SlaveNode, warm_up
from slave.node_base import SlaveLinks
from slave.simulated import SimulatedRig
from teleop.config.schema import Config, Ros2Config, TransportConfig
from teleop.ros2.crtk import slave_topics
from teleop.ros2.side import attach_slave
from teleop.ros2.wire import topic_key
from teleop.session.transport import Session, free_tcp_port, loopback_endpoint
from teleop.timing.clock import MonotonicClock
from teleop.timing.realtime import IDLE
from teleop.wire.messages import Command, SideState


def run(mode: str, n: int) -> tuple[np.ndarray, int, int]:
    """(step times [ms], overruns of the 1 kHz grid, CRTK publications) of ``n`` paced cycles; ``mode``: off,
    on, or path (on with the publisher thread stopped: the loop's own added work alone)."""
    cfg = Config(ros2=Ros2Config(enabled=mode != "off"))
    clock = MonotonicClock()
    links = SlaveLinks(*(LatestTopic(clock) for _ in range(4)))
    rig = SimulatedRig.from_config(cfg)
    ep = loopback_endpoint(free_tcp_port())
    with Session(TransportConfig(listen=(ep,), connect=()), clock=clock) as session, \
            Session(TransportConfig(listen=(), connect=(ep,)), clock=clock) as ros:
        commands = links.command                # the master's commands (attach_slave merges servo_jp in)
        crtk = attach_slave(session, cfg, links)
        if mode == "path" and crtk is not None:
            crtk._stop.set()
        received = [0]
        for topic, typ in slave_topics(cfg).items():
            ros.zenoh_session.declare_subscriber(topic_key(0, topic, typ),
                                                 lambda s: received.__setitem__(0, received[0] + 1))
        node = SlaveNode(cfg, rig, links, calibrate=False, model=SheathModel(K=rig.K, compliance=rig.M_e))
        times, overruns = np.empty(n), 0
        t_next = time.monotonic()
        for k in range(n):
            t_next += 1e-3
            t = clock.now()
            x = 0.002 * (1 - math.cos(2 * math.pi * 0.5 * k * 1e-3))
            commands.put(Command(k, t, (x,)))
            t0 = time.perf_counter()
            node.step(t)
            times[k] = time.perf_counter() - t0
            IDLE.open(t_next - 1e-4)
            late = t_next - time.monotonic()
            if late < 0:
                overruns += 1
                t_next = time.monotonic()
            else:
                time.sleep(late)
        IDLE.release()
        published = 0 if crtk is None else crtk.published
        assert node.state == SideState.ENGAGED
    return times * 1e3, overruns, published


def main() -> None:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 5000
    warm_up(Config())
    print(f"SlaveNode.step of a single tendon, {n} cycles paced at 1 kHz (load {os.getloadavg()[0]:.2f})")
    for mode in ("off", "on", "path", "off", "on", "path"):
        ms, overruns, published = run(mode, n)
        print(f"  ros2 {mode:4s}: p50 {np.percentile(ms, 50):.3f} ms, p99 {np.percentile(ms, 99):.3f} ms, "
              f"max {ms.max():.3f} ms, overruns {overruns}/{n}, CRTK publications {published}")

    from teleop.ros2.side import CrtkSide
    side = CrtkSide.__new__(CrtkSide)
    side._slot = None
    per = min(timeit.repeat(lambda: side.offer(SideState.ENGAGED, None), number=100000, repeat=5)) / 100000
    print(f"  one offer() alone: {per * 1e6:.3f} us")


if __name__ == "__main__":
    main()
