"""The master's cycle in isolation: CPU time per MasterNode.step, and where it goes.

One MasterNode (configs/sim.yaml: a single tendon, the scripted operator of the demo's protocol with
its arm) and one SlaveNode (simulated rig, estimator) run in one process on one fake clock, linked by
in-memory latest-wins topics;
each cycle the master steps, then the slave (the command-locked order of the demo); every message
is encoded as it is put, as a Zenoh publisher does (the Zenoh put itself, ~25-40 us with one remote
subscriber on this machine, is not in these figures). The master's CSV
goes to its writing process (:class:`teleop.recording.csv_proc.ProcessCsvRecorder`), Rerun is off.

Prints the master step's *thread CPU time* (:func:`time.thread_time_ns`: what the step itself costs,
not the time other processes or threads took from it; this is the figure that does not depend on the
machine's load) and its wall time, p50 / p99 / p99.9 / max, and with ``--profile`` the functions that
take the time (cProfile over the same run). ``--sleep 0.0007`` sleeps between cycles as the real loop
does: on a machine with other work the step's own CPU time then grows (cold caches; measured 42 ->
68 us p50 at a load average of 6.6 on 2 CPUs). Never fails on time.

``python benchmarks/bench_master_cycle.py [--protocol short] [--profile] [--sleep S] [--csv OUT]``
"""
from __future__ import annotations

import argparse
import math
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from teleop.session.transport import Received
from teleop.timing.clock import FakeClock
from teleop.wire.codec import encode

ROOT = Path(__file__).resolve().parents[1]


class _Topic:
    """Latest-wins topic: the publisher's side encodes (what a Zenoh publisher does in the loop), the
    subscriber gets the message as sent (a real one decodes it on Zenoh's thread, not in the loop);
    the receive time is the fake clock's."""

    def __init__(self, clock):
        self.clock, self.last, self.count, self.errors = clock, None, 0, 0

    def put(self, msg) -> None:
        encode(msg)
        self.last = Received(msg, self.clock.now())
        self.count += 1

    def latest(self):
        return self.last

    def age(self, now: float) -> float:
        return math.inf if self.last is None else now - self.last.t_recv


def run(protocol: str, profile: bool, tmp: Path, csv: Path | None = None,
        sleep: float = 0.0) -> tuple[np.ndarray, np.ndarray, dict]:
    """Master step (thread CPU time [us], wall time [us]) per cycle and the master's stats."""
    from estimator.sheath import SheathModel
    from master.devices import make_device
    from master.node import MasterNode, csv_columns, csv_units
    from master.node_base import MasterLinks
    from slave.node import SlaveNode, warm_up
    from slave.node_base import SlaveLinks
    from slave.simulated import SimulatedRig
    from teleop.config.load import load_config
    from teleop.recording.csv_proc import ProcessCsvRecorder

    cfg = load_config(ROOT / "configs" / "sim.yaml", {"recording.rerun": "off"})
    warm_up(cfg)
    clock = FakeClock(100.0)
    cmd, est, mhb, shb = (_Topic(clock) for _ in range(4))
    rig = SimulatedRig.from_config(cfg)
    model = SheathModel(K=rig.K, compliance=rig.M_e / rig.K if rig.K else rig.M_e)
    slave = SlaveNode(cfg, rig, SlaveLinks(est, shb, cmd, mhb), calibrate=False, model=model)
    device = make_device(cfg, protocol)
    dt = 1.0 / cfg.master.rate_hz
    cpu, wall = [], []
    prof = None
    if profile:
        import cProfile
        prof = cProfile.Profile()
    with ProcessCsvRecorder(csv or tmp / "master.csv", csv_columns(cfg), {"source": "bench"}, units=csv_units(cfg),
                            flush_every=100) as rec:
        master = MasterNode(cfg, device, MasterLinks(cmd, mhb, est, shb), recorder=rec)
        tt, pc = time.thread_time_ns, time.perf_counter_ns
        n_max = int(600 * cfg.master.rate_hz)
        for _ in range(n_max):
            if master.done:
                break
            t = clock.advance(dt)
            if prof is not None:
                prof.enable()
            c0, w0 = tt(), pc()
            master.step(t)
            c1, w1 = tt(), pc()
            if prof is not None:
                prof.disable()
            cpu.append(c1 - c0)
            wall.append(w1 - w0)
            slave.step(t)
            if sleep > 0:
                time.sleep(sleep)
    if prof is not None:
        import pstats
        pstats.Stats(prof).sort_stats("tottime").print_stats(25)
    return np.asarray(cpu) * 1e-3, np.asarray(wall) * 1e-3, master.stats()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--protocol", default="paper,minor")
    ap.add_argument("--profile", action="store_true")
    ap.add_argument("--sleep", type=float, default=0.0,
                    help="sleep this long [s] after each cycle, as the real loop does (its caches go cold)")
    ap.add_argument("--csv", type=Path, help="keep the master's recording here (two versions of the code: same file?)")
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        cpu, wall, st = run(a.protocol, a.profile, Path(d), a.csv, a.sleep)
    cpu, wall = cpu[200:], wall[200:]

    def pct(x: np.ndarray) -> str:
        return (f"p50 {np.percentile(x, 50):6.1f}, p99 {np.percentile(x, 99):6.1f}, "
                f"p99.9 {np.percentile(x, 99.9):7.1f}, max {x.max():7.1f} us")
    print(f"master step, {len(cpu)} cycles ({a.protocol}, sleep {1e3 * a.sleep:g} ms between cycles; "
          f"engaged {st['engage_count']} time(s), safe events {st['safe_events']}, finished {st['finished']}):")
    print(f"  thread CPU time {pct(cpu)}  (mean {cpu.mean():.1f} us)")
    print(f"  wall time       {pct(wall)}  (mean {wall.mean():.1f} us)")
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} CPUs")


if __name__ == "__main__":
    main()
