"""The live estimator's noise band (docs/concepts/model.md, "The noise band"): distal-tension and elongation error of
the profile memory with and without the band, on clean recordings of the independent lumped simulator and of the
project's rig, with the true K, route and L/EA given to the estimator (so only the memory rule is compared) and the
noise of T_in measured from the data; and the joint torque error of the 3-joint instrument driven open loop through
two command profiles (the joints' band). Prints figures (fractions of full scale), never fails.

    .venv/bin/python benchmarks/bench_noise_band.py [--recordings 24]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from estimator.data import noise_level
from estimator.geometry import SheathGeometry
from estimator.online.distal import estimate_batch
from estimator.sheath import SheathModel
from slave.calibrate import wrap_shape

#: clean recordings (simulator, first seed): two independent seed sets of the lumped simulator and one of the rig
SETS = (("lumped", 2900500), ("lumped", 2800500), ("rig", 2900500))


def known_route(truth: dict) -> np.ndarray | None:
    """The normalised cumulative wrap angle of a simulated rig's route ``truth["route"]`` ((length [m], radius [m])
    pieces), shape (257,): the route a user who knows the instrument passes to the estimator."""
    return wrap_shape(SheathGeometry(truth["route"]))


def one(sim: str, seed: int, duration: float = 60.0) -> tuple[np.ndarray, np.ndarray]:
    """(envelope, banded) x (T_out rms, T_out mean, T_out max, elongation rms) [fraction of full scale]."""
    if sim == "lumped":
        from study.lumped.scenarios import record
        rec = record(None, seed=seed, level=0.2, duration=duration)
        tr = rec.truth
        model = SheathModel(K=tr["K"], compliance=tr["L"] / tr["EA"], wrap_shape=known_route(tr))
    else:
        from study.scenarios import record
        rec = record(None, seed=seed, level=0.2, duration=duration, rate_hz=1000.0)
        tr = rec.truth
        model = SheathModel(K=tr["K"], compliance=tr["compliance"], wrap_shape=known_route(tr))
    d, sg = rec.data, tr["signals"]
    T_true = sg["T_out"]
    elong = sg["x_in"] - sg["x_out"]
    taut = np.asarray(d.T_in) > 0.5            # slack samples hold x_out: elongation is not defined there
    fs_T, fs_e = float(np.ptp(T_true)), float(np.ptp(elong[taut]))
    out = []
    for noise in (0.0, noise_level(d.T_in)):
        b = estimate_batch(d.T_in, d.x_in, model, time=d.time, phase_band=0.0, tension_noise=noise)
        e = b.T_out - T_true
        el = (b.elongation - elong)[taut]
        out.append((np.sqrt(np.mean(e ** 2)) / fs_T, np.mean(e) / fs_T, np.max(np.abs(e)) / fs_T,
                    np.sqrt(np.mean(el ** 2)) / fs_e))
    return np.array(out[0]), np.array(out[1])


def joints(profile: int, seconds: float = 20.0) -> list[tuple[str, float, float]]:
    """Per joint of configs/instrument-3dof.yaml: torque rms [fraction of full scale] without and with the band,
    the instrument driven open loop (both tendons of every joint +-4 mm per rad of command) through ``profile``."""
    from estimator.online.pair import PairEstimator
    from slave.pair_rig import SimulatedInstrument
    from teleop.config.load import load_config
    cfg = load_config(Path(__file__).resolve().parents[1] / "configs" / "instrument-3dof.yaml")
    inst = SimulatedInstrument.from_config(cfg)
    dt, js, st = 1.0 / cfg.rig.rate_hz, cfg.instrument.joints, inst.state
    t = np.arange(int(seconds / dt)) * dt
    if profile == 0:      # swings through both sides with minor loops and a step
        cmd = (0.6 * np.sin(2 * np.pi * 0.2 * t) + 0.05 * np.sin(2 * np.pi * 1.3 * t)
               + 0.1 * (np.sin(2 * np.pi * 0.05 * t) > 0))
    else:                 # smaller, faster swings on a slow drift
        cmd = (0.3 * np.sin(2 * np.pi * 0.5 * t) + 0.15 * np.sin(2 * np.pi * 0.11 * t)
               + 0.02 * np.sin(2 * np.pi * 3.0 * t))
    x0, rows = st.x_in_cmd.copy(), []
    for c in cmd:
        st = inst.step(x0 + np.array([[0.004 * c, -0.004 * c]] * len(js)), dt)
        rows.append((st.t, st.x_in.copy(), st.T_in.copy(), st.truth.torque.copy()))
    tt = np.array([r[0] for r in rows])
    X, T, TQ = (np.array([r[k] for r in rows]) for k in (1, 2, 3))
    out = []
    for i, j in enumerate(js):
        models = [SheathModel(K=float(inst.K[i][k]), compliance=tg.geometry().length / tg.EA)
                  for k, tg in enumerate((j.tendons.a, j.tendons.b))]
        rms = []
        for noise in (0.0, (noise_level(T[:, i, 0]), noise_level(T[:, i, 1]))):
            e = PairEstimator(models[0], models[1], j.pulley_radius, pretension=j.pretension, tension_noise=noise)
            tq = np.array([e.step(float(T[k, i, 0]), float(X[k, i, 0]), float(T[k, i, 1]), float(X[k, i, 1]),
                                  float(tt[k])).torque for k in range(tt.size)])
            rms.append(float(np.sqrt(np.mean((tq - TQ[:, i]) ** 2)) / np.ptp(TQ[:, i])))
        out.append((j.name, rms[0], rms[1]))
    return out


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--recordings", type=int, default=24, help="clean recordings per set (default 24)")
    args = ap.parse_args(argv if argv is not None else [])
    print("live estimator, profile memory with and without the noise band (true parameters; median over recordings, "
          "fractions of full scale)")
    for sim, base in SETS:
        rows = np.array([one(sim, base + k) for k in range(args.recordings)])     # (n, 2, 4)
        med = np.median(rows, axis=0)
        bias = np.median(np.abs(rows[:, :, 1]), axis=0)
        print(f"  {sim:6s} {base}+ ({args.recordings}): T_out rms {med[0, 0]:.4f} -> {med[1, 0]:.4f}, |mean| "
              f"{bias[0]:.4f} -> {bias[1]:.4f}, max {med[0, 2]:.3f} -> {med[1, 2]:.3f}; elongation rms "
              f"{med[0, 3]:.4f} -> {med[1, 3]:.4f}")
    for profile in (0, 1):
        print(f"  3-joint instrument, open loop, profile {profile + 1}: torque rms " + ", ".join(
            f"{name} {a:.4f} -> {b:.4f}" for name, a, b in joints(profile)))


if __name__ == "__main__":
    main(sys.argv[1:])
