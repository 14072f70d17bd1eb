"""Simulated joint instrument speed: real-time factor of the 3-joint instrument (configs/instrument-3dof.yaml)
at 1 kHz, alone and with the slave's per-cycle work (pair controllers + joint estimators).
Prints figures, never fails on time; the aim is >= 5x real time."""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from estimator.online.pair import PairEstimator
from estimator.sheath import SheathModel
from slave.pair_control import PairController
from slave.pair_rig import SimulatedInstrument
from teleop.config.load import load_config

CONFIG = Path(__file__).resolve().parents[1] / "configs" / "instrument-3dof.yaml"


def bench(n_elements: int, seconds: float = 10.0, with_slave: bool = False) -> float:
    cfg = load_config(CONFIG, {"rig.simulated.n_elements": n_elements})
    inst = SimulatedInstrument.from_config(cfg)
    dt = 1.0 / cfg.rig.rate_hz
    joints = cfg.instrument.joints
    st = inst.state
    ctls = [PairController(j.pulley_radius, 0.25, 0.01, 0.01, 0.05, tuple(st.x_in[i])) for i, j in enumerate(joints)]
    ests = [PairEstimator(*(SheathModel(K=k, compliance=1e-4) for k in inst.K[i]), j.pulley_radius)
            for i, j in enumerate(joints)]
    n = int(seconds / dt)
    t = np.arange(n) * dt
    # each joint swings back and forth through both sides with minor loops (rad of command)
    cmd = 0.6 * np.sin(2 * np.pi * 0.2 * t) + 0.05 * np.sin(2 * np.pi * 1.3 * t)
    samples = [e.step(st.T_in[i, 0], st.x_in[i, 0], st.T_in[i, 1], st.x_in[i, 1], 0.0) for i, e in enumerate(ests)]
    x0 = st.x_in_cmd.copy()

    def one(k: int):
        nonlocal st
        if with_slave:
            x = np.array([c.step(cmd[k], st.T_in[i], dt, samples[i].x_out) for i, c in enumerate(ctls)])
        else:
            u = 0.004 * cmd[k]
            x = x0 + np.array([[u, -u]] * len(joints))
        st = inst.step(x, dt)
        if with_slave:
            for i, e in enumerate(ests):
                samples[i] = e.step(st.T_in[i, 0], st.x_in[i, 0], st.T_in[i, 1], st.x_in[i, 1], st.t)

    for k in range(300):           # warm-up (numba)
        one(k)
    t0 = time.perf_counter()
    for k in range(n):
        one(k)
    return seconds / (time.perf_counter() - t0)


def main() -> None:
    cfg = load_config(CONFIG)
    print(f"simulated 3-joint instrument ({CONFIG.name}: {len(cfg.instrument.joints)} joints, 2 tendons each, "
          f"{cfg.rig.rate_hz:.0f} Hz)")
    for n in (100, 200):
        for with_slave in (False, True):
            rtf = bench(n, with_slave=with_slave)
            what = "rig + controllers + estimators" if with_slave else "rig alone"
            print(f"  {n:3d} elements/tendon, {what:31s}: real-time factor {rtf:6.1f}x "
                  f"({1e6 / (rtf * cfg.rig.rate_hz):6.1f} us/step; aim >= 5x)")


if __name__ == "__main__":
    main()
