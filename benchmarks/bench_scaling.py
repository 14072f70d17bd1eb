"""How the live loop's cost grows with the number of tendons: slave and master step times at 2, 6, 16 and 32
tendons, with and without the recorder, beside bare Zenoh and the teleoperation round trip in the same run.

1. In one process, for instruments of 1, 3, 8 and 16 antagonistic joints (2, 6, 16, 32 tendons; the joints of
   configs/instrument-3dof.yaml repeated under distinct names, one device axis each, the simulated rig of
   100 elements per tendon): the instrument is calibrated on its simulator first
   (:func:`bench_slave_cycle.simulator_calibration`), then a MasterNode (the demo's scripted operator,
   protocol ``short`` on every joint) and a SlaveNode on that calibration step in turn on one fake clock,
   linked by latest-wins topics that encode every message as a Zenoh publisher does
   (:class:`bench_master_cycle._Topic`). Each step's wall time is taken; without the recorder nothing is
   written, with it the sides write as ``teleop slave`` and ``teleop master`` do: each CSV through a child
   process (:class:`teleop.recording.csv_proc.ProcessCsvRecorder`), the slave's Rerun through another
   (:class:`teleop.rerun.process.RerunProcessLogger`).
   The cost per added tendon is the least-squares slope of p50 (and of p99) over the four sizes.
2. In the same run, in real processes on 127.0.0.1: the bare Zenoh ping-pong of
   :func:`bench_roundtrip.bare_pingpong` and ``teleop demo --protocol short`` (recorder + slave + master,
   :func:`bench_roundtrip.demo_roundtrip`) at 2 and 16 tendons: the command -> estimate-echo round trip,
   the slave's step time and both loops' overruns.

Prints a table, never fails on time. ``python benchmarks/bench_scaling.py [--quick] [--cycles N] [--seconds S]``
(``--quick``: 2 and 16 tendons only, fewer cycles and a shorter ping-pong, under a minute).
"""
from __future__ import annotations

import argparse
import dataclasses
import os
import tempfile
import time
from pathlib import Path

import numpy as np
from bench_master_cycle import _Topic  # sibling scripts: the benchmarks folder is the running script's own
from bench_roundtrip import bare_pingpong, demo_roundtrip
from bench_slave_cycle import simulator_calibration

ROOT = Path(__file__).resolve().parents[1]
JOINTS = (1, 3, 8, 16)                     # antagonistic joints: 2, 6, 16, 32 tendons
DEMO_JOINTS = (1, 8)                       # the round trip in real processes: 2 and 16 tendons


def instrument(n_joints: int, rerun: str = "save"):
    """configs/instrument-3dof.yaml with its joints (and their simulated physics) repeated to ``n_joints``,
    named ``<joint><k>``, device axis k for joint k; ``recording.rerun`` = ``rerun``."""
    from teleop.arms import repeated_joints
    from teleop.config.load import load_config
    base = load_config(ROOT / "configs" / "instrument-3dof.yaml", {"recording.rerun": rerun})
    return repeated_joints(base, n_joints, f"scaling{n_joints}")


class Loop:
    """A master and a slave of ``cfg``'s instrument on one fake clock (module docstring, 1.), with the recorder's
    writers (``record``) or none; :meth:`run` steps them in turn and times each step. Close it when done."""

    def __init__(self, cfg, cal, record: bool, tmp: Path):
        from master.devices import make_device
        from master.node import MasterNode
        from master.node import csv_columns as master_columns
        from master.node import csv_units as master_units
        from master.node_base import MasterLinks
        from slave.node import SlaveNode, recording, warm_up
        from slave.node_base import SlaveLinks
        from slave.rigs import RIG_TYPES
        from teleop.recording.csv_proc import ProcessCsvRecorder
        from teleop.rerun.layout import joint_views
        from teleop.rerun.process import RerunProcessLogger
        from teleop.timing.clock import FakeClock

        warm_up(cfg)
        self.clock, self.dt = FakeClock(100.0), 1.0 / cfg.rig.rate_hz
        cmd, est, mhb, shb = (_Topic(self.clock) for _ in range(4))
        rig = RIG_TYPES["simulated"](cfg, None)
        self.rig_cpu, rig_step = 0, rig.step

        def timed_step(x_in_cmd, dt):     # the simulated instrument's share of the slave's step
            c = time.thread_time_ns()
            st = rig_step(x_in_cmd, dt)
            self.rig_cpu += time.thread_time_ns() - c
            return st
        rig.step = timed_step
        tag = f"{cfg.instrument.id}-{'rec' if record else 'bare'}"
        name, columns, meta = recording(cfg, rig)
        self.writers = (ProcessCsvRecorder(tmp / f"{tag}-{name}", columns, meta, flush_every=500),
                        ProcessCsvRecorder(tmp / f"{tag}-master.csv", master_columns(cfg), {"source": "bench"},
                                           units=master_units(cfg), flush_every=500),
                        RerunProcessLogger("bench", tag, "save", tmp / f"{tag}.rrd", joints=joint_views(cfg))
                        ) if record else (None, None, None)
        srec, mrec, rr = self.writers
        self.slave = SlaveNode(cfg, rig, SlaveLinks(est, shb, cmd, mhb), recorder=srec, rerun=rr, calibration=cal)
        self.master = MasterNode(cfg, make_device(cfg, "short"), MasterLinks(cmd, mhb, est, shb), recorder=mrec)
        if rr is not None:
            rr.flush()                # the Rerun child up and idle: its start-up is not the loop's

    def run(self, cycles: int) -> np.ndarray:
        """``cycles`` cycles: per cycle the wall time and the thread CPU time of the slave's step, the same of
        the master's, and the thread CPU time of the simulated rig's step inside the slave's [ms], (5, cycles)."""
        out = np.empty((5, cycles))
        pc, tt, master, slave = time.perf_counter_ns, time.thread_time_ns, self.master, self.slave
        for k in range(cycles):
            t = self.clock.advance(self.dt)
            self.rig_cpu = 0
            w0, c0 = pc(), tt()
            master.step(t)
            w1, c1 = pc(), tt()
            slave.step(t)
            w2, c2 = pc(), tt()
            out[:, k] = w2 - w1, c2 - c1, w1 - w0, c1 - c0, self.rig_cpu
        return out * 1e-6

    def close(self) -> None:
        for w in self.writers:
            if w is not None:
                w.close()


def slope(tendons, values) -> float:
    """Least-squares slope of ``values`` against ``tendons`` (a first-degree fit): the cost per added tendon."""
    return float(np.polyfit(np.asarray(tendons, dtype=float), np.asarray(values, dtype=float), 1)[0])


#: the figures of one side's step: wall-time p50, p99 and thread-CPU-time p50, p99 [ms]
_FIGURES = ((0, 50), (0, 99), (1, 50), (1, 99))


def measure_steps(cycles: int, tmp: Path, joints=JOINTS, rounds: int = 10) -> dict:
    """``{(n_joints, record): (slave wall p50, p99, CPU p50, p99, master wall p50, p99, CPU p50, p99, rig CPU p50)}``
    [ms]. Every loop is built first (calibrated on its simulator, warmed up by a tenth of ``cycles``), then they
    run in ``rounds`` turns of ``cycles / rounds`` cycles each, so that the machine's load falls on every size
    alike."""
    loops: dict[tuple[int, bool], Loop] = {}
    x: dict[tuple[int, bool], list[np.ndarray]] = {}
    try:
        for nj in joints:
            cfg = instrument(nj)
            cal = simulator_calibration(cfg)
            for record in (False, True):
                loops[nj, record] = lp = Loop(cfg, cal, record, tmp)
                lp.run(max(cycles // 10, 1))
        for _ in range(rounds):
            for key, lp in loops.items():
                x.setdefault(key, []).append(lp.run(max(cycles // rounds, 1)))
    finally:
        for lp in loops.values():
            lp.close()
    out = {}
    for (nj, record), blocks in x.items():
        a = np.concatenate(blocks, axis=1)
        v = out[nj, record] = tuple(float(np.percentile(a[side + row], q)) for side in (0, 2) for row, q in _FIGURES
                                    ) + (float(np.percentile(a[4], 50)),)
        print(f"  {2 * nj:3d} tendons, recorder {'on ' if record else 'off'}: slave p50 {v[0]:.3f} p99 {v[1]:.3f} "
              f"(CPU {v[2]:.3f} / {v[3]:.3f}; the simulated rig's CPU p50 {v[8]:.3f}) ms, master p50 {v[4]:.3f} "
              f"p99 {v[5]:.3f} (CPU {v[6]:.3f} / {v[7]:.3f}) ms", flush=True)
    return out


def demo_config(n_joints: int, tmp: Path) -> Path:
    """The generated instrument as a config file for ``teleop demo``, calibrating into ``tmp``."""
    from teleop.config.load import write_config
    cfg = instrument(n_joints)
    cfg = dataclasses.replace(cfg, calibration=dataclasses.replace(cfg.calibration, dir=str(tmp / "calibration")))
    path = tmp / f"scaling{n_joints}.yaml"
    write_config(cfg, path)
    return path


def print_table(steps: dict, joints=JOINTS) -> None:
    """The step table (markdown) and the cost per added tendon."""
    print("| tendons | slave p50 / p99 (CPU p50 / p99) [ms] | slave + recorder | of which the simulated rig "
          "(CPU p50) | master p50 / p99 (CPU p50 / p99) [ms] | master + recorder |")
    print("|---:|---|---|---|---|---|")
    for nj in joints:
        cells = [f"{v[0]:.3f} / {v[1]:.3f} ({v[2]:.3f} / {v[3]:.3f})" for side in (0, 4) for rec in (False, True)
                 for v in [steps[nj, rec][side:side + 4]]]
        cells.insert(2, f"{steps[nj, False][8]:.3f}")
        print(f"| {2 * nj} | " + " | ".join(cells) + " |")
    tendons = [2 * nj for nj in joints]
    parts = []
    for label, col in (("slave p50", 0), ("slave CPU p50", 2), ("simulated rig CPU p50", 8), ("master p50", 4),
                       ("master CPU p50", 6)):
        per = [slope(tendons, [steps[nj, rec][col] for nj in joints]) * 1e3 for rec in (False, True)]
        parts.append(f"{label} {per[0]:.1f} us ({per[1]:.1f} us with the recorder)")
    print("cost per added tendon (least-squares slope over " + ", ".join(map(str, tendons)) + " tendons): "
          + "; ".join(parts))


def print_roundtrips(bare: dict, demos: dict) -> None:
    """The bare ping-pong and the demo round trips, and what the teleoperation adds to bare Zenoh."""
    print(f"bare zenoh ping-pong, 2 processes, 1 kHz ({bare['scheduling']}): p50 {bare['p50_ms']:.3f} ms, "
          f"p99 {bare['p99_ms']:.3f} ms ({bare['echoed']}/{bare['sent']} echoed)")
    for nj, d in demos.items():
        st = d["pacer"]["slave"].get("step_ms", {})
        print(f"teleop demo, {2 * nj} tendons (recorder+slave+master processes), command -> estimate echo: "
              f"p50 {d['p50_ms']:.3f} ms ({d['p50_ms'] - bare['p50_ms']:+.3f} over bare), p99 {d['p99_ms']:.3f} ms "
              f"({d['p99_ms'] - bare['p99_ms']:+.3f}); slave step p50 {st.get('p50', float('nan')):.2f} p99 "
              f"{st.get('p99', float('nan')):.2f} ms; overruns master {100 * d['master_overruns']:.2f} %, slave "
              f"{100 * d['slave_overruns']:.2f} %; recorder {d['recorded']} messages, {d['recorded_missing']} missing")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    ap.add_argument("--quick", action="store_true",
                    help="2 and 16 tendons only, fewer cycles and a shorter ping-pong (a smoke test)")
    ap.add_argument("--cycles", type=int, help="cycles per size and recorder setting (default 1500, quick 300)")
    ap.add_argument("--seconds", type=float, help="bare ping-pong duration [s] (default 5, quick 2)")
    a = ap.parse_args()
    cycles = a.cycles or (300 if a.quick else 1500)
    joints = JOINTS[::2] if a.quick else JOINTS
    seconds = a.seconds or (2.0 if a.quick else 5.0)
    load0 = os.getloadavg()[0]
    print(f"machine: {os.cpu_count()} CPUs, load average {load0:.2f} at the start", flush=True)
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        print(f"step times over {cycles} cycles per size, in turns, master + slave in one process:", flush=True)
        steps = measure_steps(cycles, tmp, joints)
        bare = bare_pingpong(seconds)
        demos = {nj: demo_roundtrip(config=demo_config(nj, tmp)) for nj in DEMO_JOINTS}
    print()
    print_table(steps, joints)
    print_roundtrips(bare, demos)
    print(f"load average {load0:.2f} at the start, {os.getloadavg()[0]:.2f} at the end (1 min), "
          f"on {os.cpu_count()} CPUs")


if __name__ == "__main__":
    main()
