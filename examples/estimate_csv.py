"""Estimate the distal tension and elongation of a recorded tendon from its proximal channels only.

    python examples/estimate_csv.py                                  # a simulated bench recording
    python examples/estimate_csv.py rec.csv --K 0.8 --compliance 1e-4
    python examples/estimate_csv.py rec.csv                          # K and L/EA fitted (needs T_out or x_out)

The recording is a measured-data CSV (docs/reference/formats.md: time [s], x_in [m], T_in [N], optional T_out [N]
and x_out [m]). Without a file, 20 s of the simulated bench rig (study/scenarios.py) are written to a
temporary directory first, with the rig's friction exponent K and compliance L/EA. With a file and
without ``--K``/``--compliance`` both are fitted on the first 60 % of the recording and the error is
reported on the rest. The estimate itself reads only ``time``, ``x_in`` and ``T_in``.
"""
from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

from estimator import SheathModel, estimate_batch, fit_single
from estimator.data import MeasuredData
from teleop.recording.measured import write_measured_csv
from teleop.recording.measured_csv import read_measured_csv


def simulated_recording(folder: Path) -> tuple[Path, float, float]:
    """Write 20 s of the simulated bench rig (no hidden effect) to ``folder``; (path, K [-], L/EA [m/N])."""
    from study.scenarios import record
    rec = record(None, seed=2, duration=20.0)
    path = folder / "bench.csv"
    write_measured_csv(path, rec.data)
    return path, float(rec.truth["K"]), float(rec.truth["compliance"])


def fitted_model(data: MeasuredData) -> tuple[float, float, int]:
    """K [-] and L/EA [m/N] fitted on the first 60 % (profile-memory estimator); the first held-out index."""
    fit = fit_single(data.time, data.T_in, data.x_in, T_out=data.T_out, x_out=data.x_out)
    f = fit.fits["profile"]
    # with T_out alone L/EA is not identifiable and does not change T_out: any positive value will do
    return f.K, f.compliance if f.compliance is not None else 1e-4, fit.split


def report(data: MeasuredData, model: SheathModel, first: int) -> None:
    """Run the estimator over the recording and print its errors against the distal channels from ``first`` on."""
    est = estimate_batch(data.T_in, data.x_in, model, time=data.time)
    span = data.time[-1] - data.time[first]
    print(f"estimated distal tension: peak {est.T_out.max():.2f} N (proximal peak {data.T_in.max():.2f} N)")
    for name, hat, truth, unit, scale in (("distal tension", est.T_out, data.T_out, "N", 1.0),
                                         ("distal displacement", est.x_out, data.x_out, "mm", 1e3)):
        if truth is None:
            continue
        err, rng = hat[first:] - truth[first:], np.ptp(truth[first:])
        rms = float(np.sqrt(np.mean(err ** 2)))
        print(f"{name}: rms error {rms * scale:.3f} {unit} ({100 * rms / rng:.2f} % of its "
              f"{rng * scale:.2f} {unit} range) over {span:.1f} s")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("csv", nargs="?", help="measured-data CSV (default: a simulated recording)")
    p.add_argument("--K", type=float, help="friction exponent mu * total wrap angle [-]")
    p.add_argument("--compliance", type=float, help="tendon compliance L/EA [m/N]")
    args = p.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        K, compliance = args.K, args.compliance
        if args.csv is None:
            path, K, compliance = simulated_recording(Path(tmp))
            how = "the simulated rig's"
        else:
            path, how = Path(args.csv), "given"
        data = read_measured_csv(path)
        first = 0
        if K is None or compliance is None:
            K, compliance, first = fitted_model(data)
            how = f"fitted on the first {data.time[first] - data.time[0]:.1f} s"
        print(f"recording: {path.name}, {data.time.size} samples over {data.time[-1] - data.time[0]:.1f} s")
        print(f"model: K = {K:.3f}, L/EA = {compliance:.3g} m/N ({how})")
        report(data, SheathModel(K=K, compliance=compliance), first)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
