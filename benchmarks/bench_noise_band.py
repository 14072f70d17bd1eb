"""The live estimator's noise band (docs/model.md, "On a noisy load cell"): distal-tension and elongation error of
the profile memory with and without the band, on clean recordings of the independent lumped simulator and of the
project's rig, with the true K, route and L/EA given to the estimator (so only the memory rule is compared) and the
noise of T_in measured from the data. Prints figures (fractions of each recording's full scale), never fails.

    .venv/bin/python benchmarks/bench_noise_band.py [--recordings 24]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_diagnosis import known_route  # noqa: E402

from estimator.data import noise_level  # noqa: E402
from estimator.online.distal import estimate_batch  # noqa: E402
from estimator.sheath import SheathModel  # noqa: E402

#: clean recordings of the two seed sets of docs/model.md: the rule was written on the first, checked on the second
SETS = (("lumped", 2900500), ("lumped", 2800500), ("rig", 2900500))


def one(sim: str, seed: int, duration: float = 60.0) -> tuple[np.ndarray, np.ndarray]:
    """(envelope, banded) x (T_out rms, T_out mean, T_out max, elongation rms) [fraction of full scale]."""
    if sim == "lumped":
        from slave.lumped_scenarios import record
        rec = record(None, seed=seed, level=0.2, duration=duration)
        tr = rec.truth
        model = SheathModel(K=tr["K"], compliance=tr["L"] / tr["EA"], wrap_shape=known_route(tr))
    else:
        from slave.scenarios import record
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


if __name__ == "__main__":
    main(sys.argv[1:])
