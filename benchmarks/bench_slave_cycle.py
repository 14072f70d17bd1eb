"""The slave's cycle with its recording in the loop or off it: time per SlaveNode.step [ms].

One SlaveNode of a single tendon (simulated 200-element rig, estimator, 50-point profile) follows a
ramp of engaged commands through in-memory links for ``n`` cycles, once with the CSV and Rerun writes
in the loop (:class:`teleop.recording.measured.CsvRecorder`, :class:`teleop.rerun.logger.RerunLogger`) and once
off the loop as ``teleop slave`` writes them (:class:`teleop.recording.csv_proc.ProcessCsvRecorder`,
:class:`teleop.rerun.process.RerunProcessLogger`: each in a child process); then the same node class on the 3-joint
instrument (configs/instrument-3dof.yaml: three pair axes, calibrated on its simulator first, each
joint following a slow sine of angle) with no recording (the step alone) and with the recording off the loop.
Then the single tendon's step with the recording off the loop saving the Rerun view (``save``) and serving it
(``serve``: gRPC on loopback, :mod:`teleop.rerun.serve`), and the difference of their p50s.
Prints p50/p99/max of the step time and the share of steps over 0.8 ms (what would overrun a 1 kHz loop
with 0.2 ms of wake-up and transport), and the load average. Never fails on time.
"""
from __future__ import annotations

import math
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from estimator.sheath import SheathModel
from slave.node import SlaveNode, warm_up
from slave.node_base import SlaveLinks
from slave.simulated import SimulatedRig
from slave.tendon_axis import csv_columns
from teleop.config.load import load_config
from teleop.config.schema import Config
from teleop.recording.csv_proc import ProcessCsvRecorder
from teleop.recording.measured import CsvRecorder
from teleop.rerun.logger import RerunLogger
from teleop.rerun.process import RerunProcessLogger
from teleop.session.transport import Received
from teleop.timing.clock import FakeClock
from teleop.wire.messages import Command


class LatestTopic:
    """In-memory latest-wins topic (receive time = the clock's): the node's links without Zenoh."""

    def __init__(self, clock):
        self.clock, self.last, self.count = clock, None, 0

    def put(self, msg) -> None:
        self.last = Received(msg, self.clock.now())
        self.count += 1

    def latest(self):
        return self.last

    def age(self, now: float) -> float:
        return math.inf if self.last is None else now - self.last.t_recv


def run(off_loop: bool, n: int, tmp: Path, mode: str = "save") -> np.ndarray:
    cfg = Config()
    warm_up(cfg)
    clock = FakeClock()
    links = SlaveLinks(*(LatestTopic(clock) for _ in range(4)))
    rig = SimulatedRig.from_config(cfg)
    model = SheathModel(K=rig.K, compliance=rig.M_e / rig.K if rig.K else rig.M_e)
    csv_cls, rr_cls = (ProcessCsvRecorder, RerunProcessLogger) if off_loop else (CsvRecorder, RerunLogger)
    tag = ("offloop" if off_loop else "inloop") + f"-{mode}"
    serve = None
    if mode == "serve":              # the stream served on free loopback ports (teleop.rerun.serve), no web viewer
        from teleop.rerun.serve import ServeSpec
        from teleop.session.transport import free_tcp_port
        serve = ServeSpec("127.0.0.1", free_tcp_port(), 0, int(Config().recording.rerun_serve.memory_limit))
    times = np.empty(n)
    with csv_cls(tmp / f"{tag}.csv", csv_columns(True), {"source": "bench"}, flush_every=500) as rec, \
            rr_cls("bench", tag, mode, tmp / f"{tag}.rrd", serve=serve) as rr:
        node = SlaveNode(cfg, rig, links, recorder=rec, rerun=rr, calibrate=False, model=model)
        x = 0.0
        for k in range(n):
            t = clock.advance(1e-3)
            x = 0.004 * (1 - math.cos(2 * math.pi * 0.25 * t))
            links.command.put(Command(k, t, (x,)))
            t0 = time.perf_counter()
            node.step(t)
            times[k] = time.perf_counter() - t0
    return times * 1e3


def simulator_calibration(cfg: Config):
    """The calibration the slave would reload for ``cfg``'s joint instrument: its power-up routine run
    to the end on a simulator of the instrument (an :class:`slave.calibration_file.InstrumentCalibration`)."""
    from slave.kinds import axis_kind
    from slave.rigs import RIG_TYPES
    kind, dt = axis_kind(cfg), 1.0 / cfg.rig.rate_hz
    sim = RIG_TYPES["simulated"](cfg, None)
    routine = kind.routine(cfg, sim)
    st = sim.state
    while not routine.done:
        st = kind.routine_step(routine, sim, st, dt)
    return kind.calibration_of(cfg, routine)


def run_joints(n: int, tmp: Path, record: bool = True) -> np.ndarray:
    """The 3-joint instrument's SlaveNode with the recording off the loop (``record``) or with no recording at
    all (the step in isolation): step times [ms]."""
    from slave.node import recording
    from slave.rigs import RIG_TYPES
    from teleop.rerun.layout import joint_views
    cfg = load_config(Path(__file__).resolve().parents[1] / "configs" / "instrument-3dof.yaml",
                      {"recording.rerun": "save"})
    warm_up(cfg)
    dt = 1.0 / cfg.rig.rate_hz
    cal = simulator_calibration(cfg)
    clock = FakeClock()
    links = SlaveLinks(*(LatestTopic(clock) for _ in range(4)))
    inst = RIG_TYPES["simulated"](cfg, None)
    name, columns, meta = recording(cfg, inst)
    times = np.empty(n)

    def loop(node: SlaveNode) -> None:
        for k in range(n):
            t = clock.advance(dt)
            a = 0.3 * math.sin(2 * math.pi * 0.25 * t)
            links.command.put(Command(k, t, (a, -a, 0.5 * a)))
            t0 = time.perf_counter()
            node.step(t)
            times[k] = time.perf_counter() - t0

    if not record:
        loop(SlaveNode(cfg, inst, links, calibration=cal))
        return times * 1e3
    with ProcessCsvRecorder(tmp / name, columns, meta, flush_every=500) as rec, \
            RerunProcessLogger("bench", "joints", "save", tmp / "joints.rrd", joints=joint_views(cfg)) as rr:
        loop(SlaveNode(cfg, inst, links, recorder=rec, rerun=rr, calibration=cal))
    return times * 1e3


def main(n: int = 5000) -> None:
    with tempfile.TemporaryDirectory() as d:
        for off_loop in (False, True):
            t = run(off_loop, n, Path(d))[200:]
            print(f"slave step, recording {'off the loop (child processes)' if off_loop else 'in the loop'}: "
                  f"p50 {np.percentile(t, 50):.3f} ms, p99 {np.percentile(t, 99):.3f} ms, max {t.max():.2f} ms, "
                  f"steps > 0.8 ms {100 * np.mean(t > 0.8):.2f} %")
        p50 = {}
        (Path(d) / "serving").mkdir()
        for mode in ("save", "serve"):
            t = run(True, n, Path(d) / "serving", mode)[200:]
            p50[mode] = np.percentile(t, 50)
            print(f"slave step, recording off the loop, Rerun {mode}"
                  f"{' (gRPC on loopback)' if mode == 'serve' else ''}: "
                  f"p50 {p50[mode]:.4f} ms, p99 {np.percentile(t, 99):.3f} ms, max {t.max():.2f} ms")
        print(f"serving costs the slave's step {1e3 * (p50['serve'] - p50['save']):+.1f} us at p50 (goal <= 50 us)")
        for record in (False, True):
            t = run_joints(n, Path(d), record)[200:]
            print(f"slave step, 3-joint instrument (3 pair axes), "
                  f"{'recording off the loop' if record else 'no recording (the step alone)'}: "
                  f"p10 {np.percentile(t, 10):.3f} ms, p50 {np.percentile(t, 50):.3f} ms, "
                  f"p99 {np.percentile(t, 99):.3f} ms, max {t.max():.2f} ms, "
                  f"steps > 0.8 ms {100 * np.mean(t > 0.8):.2f} %")
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} CPUs")


if __name__ == "__main__":
    import argparse
    ap = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    ap.add_argument("cycles", nargs="?", type=int, default=5000, help="slave cycles to time")
    main(ap.parse_args().cycles)
