"""Simulated rig speed: real-time factor at 1 kHz with 200 elements. Prints figures, never fails on time."""
from __future__ import annotations

import time

import numpy as np

from slave.simulated import SimulatedRig
from teleop.config.schema import Config


def bench_rig(seconds: float = 20.0, tissue: bool = True) -> float:
    cfg = Config()
    rig = SimulatedRig.from_config(cfg)
    rig.set_load(tissue=tissue)
    dt = 1.0 / cfg.rig.rate_hz
    n = int(seconds * cfg.rig.rate_hz)
    t = np.arange(n) * dt
    # pull/release cycles of several amplitudes with minor loops, in metres of proximal travel
    x_cmd = 0.004 * (1 - np.cos(2 * np.pi * 0.25 * t)) + 0.0008 * np.sin(2 * np.pi * 1.3 * t) ** 2
    for k in range(200):  # warm-up (numba)
        rig.step(float(x_cmd[k]), dt)
    t0 = time.perf_counter()
    for k in range(n):
        rig.step(float(x_cmd[k]), dt)
    wall = time.perf_counter() - t0
    return seconds / wall


def main() -> None:
    cfg = Config()
    print(f"simulated rig ({cfg.rig.simulated.n_elements} elements, {cfg.rig.rate_hz:.0f} Hz)")
    for tissue in (True, False):
        rtf = bench_rig(tissue=tissue)
        print(f"  tissue={'on ' if tissue else 'off'}: real-time factor {rtf:7.1f}x  "
              f"({1e6 / (rtf * cfg.rig.rate_hz):5.2f} us/step; aim >= 20x)")


if __name__ == "__main__":
    main()
