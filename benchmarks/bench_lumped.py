"""Lumped-mass simulator speed: real-time factor of the chain alone and of whole 90 s recordings
(study.lumped.scenarios.record, randomised rate, route and load). CPU time of this process, one
thread; prints figures, never fails on time (aim: a 90 s recording in a few seconds)."""
from __future__ import annotations

import argparse
import math
import time

import numpy as np

from estimator.geometry import SheathGeometry
from study.lumped.scenarios import record
from study.lumped.simulator import Load, LumpedTendon


def bench_chain(seconds: float = 30.0, rate_hz: float = 1000.0, substep_hz: float = 10000.0,
                n_nodes: int = 48) -> float:
    """Real-time factor of LumpedTendon.run on pull/release cycles with minor loops [-]."""
    geo = SheathGeometry([(0.3, math.inf), (0.5, 0.5 / 3.0), (0.4, math.inf), (0.3, 0.3 / 3.3)])
    tl = LumpedTendon(geo, 0.1, 15000.0, Load("joint", stiffness=150.0, limit=0.002, stop=3e5),
                      n_nodes=n_nodes, substep_hz=substep_hz)
    t = np.arange(int(seconds * rate_hz)) / rate_hz
    x = 0.002 * (1 - np.cos(2 * np.pi * 0.25 * t)) + 0.0004 * np.sin(2 * np.pi * 1.3 * t) ** 2
    tl.run(x[:100], rate_hz)                                   # compile (cached after the first run)
    tl.reset()
    c0 = time.process_time()
    tl.run(x, rate_hz)
    return seconds / (time.process_time() - c0)


def bench_record(seeds: range, duration: float = 90.0) -> list[tuple[int, float, float]]:
    """(seed, rate [Hz], CPU seconds) of one clean recording per seed."""
    record(seed=seeds[0], duration=5.0)                         # compile
    rows = []
    for s in seeds:
        c0 = time.process_time()
        rec = record(seed=s, duration=duration)
        rows.append((s, rec.truth["rate_hz"], time.process_time() - c0))
    return rows


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seeds", type=int, default=4, help="number of 90 s recordings to time")
    args = ap.parse_args(argv if argv is not None else [])
    print("lumped chain (48 nodes, 1 kHz samples):")
    for sub in (5000.0, 10000.0, 20000.0):
        rtf = bench_chain(substep_hz=sub)
        print(f"  substep {sub / 1000:4.0f} kHz: real-time factor {rtf:6.1f}x  ({1e6 / (rtf * sub):5.2f} us/substep)")
    rows = bench_record(range(args.seeds))
    print("lumped_scenarios.record, 90 s clean recordings:")
    for s, rate, cpu in rows:
        print(f"  seed {s}: {rate:6.0f} Hz  {cpu:5.2f} s CPU  real-time factor {90.0 / cpu:5.1f}x")
    cpu = np.array([r[2] for r in rows])
    print(f"  mean {cpu.mean():.2f} s, max {cpu.max():.2f} s CPU per 90 s recording (aim: a few seconds)")


if __name__ == "__main__":
    import sys
    main(sys.argv[1:])
