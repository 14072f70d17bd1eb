"""Friction that changes during a session, tracked online: the per-cycle form of the friction step and the friction
drift (``estimator.online.friction_observer``) against replaying the change the diagnosis fitted.

Per seed and effect (``friction_step``: the sheath reshaped at one instant; ``curvature_drift``: friction drifting),
:func:`study.scenarios.record` runs the simulated rig with the effect at ``--level`` of its realistic range for
``--duration`` seconds and ``teleop analyze FILE --model-out`` fits its model (a subprocess: the command a lab runs).
The model then runs per cycle on three sessions of the same rig (K, EA, load and noise from the seed):

* ``same``: the analysed session itself;
* ``moved``: a session 1.5 times as long, so the change comes at another instant (the step at 1.5 times its
  instant, the drift running on for longer);
* ``none``: a session in which the friction stays at its starting level (the sheath is not moved).

Each through three estimators built from the model file (:func:`slave.tendon_model.tendon_model_estimator`): the
model's base form (its calibration, no extension), the model with the fitted change replayed from the session's start
(the batch model's form) and the model with the friction tracked online (what the slave runs). Scored as the
distal-tension RMSE [N] against the measured distal load cell after the first ``--settle`` seconds. Prints a Markdown
table (medians over the seeds, and the worst) and the command line; never fails on the figures.

    .venv/bin/python benchmarks/bench_friction_tracking.py [--seeds 1,2,3,4,5] [--level 0.7] [--duration 60]
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from estimator.data import noise_level
from slave.tendon_model import check_tendon, tendon_model_estimator
from study.scenarios import record
from teleop.config.model_file import ModelFile, load_model
from teleop.recording.measured import write_measured_csv

EFFECTS = ("friction_step", "curvature_drift")
FORMS = ("base", "replayed", "tracked")


def _base_form(mf: ModelFile) -> ModelFile:
    """The model file with its extensions removed: its calibration alone."""
    return dataclasses.replace(mf, extensions=())


def _run(mf: ModelFile, data, track: bool | None, settle: float) -> tuple[float, float]:
    """Per-cycle distal-tension RMSE [N] after ``settle`` s, and the friction exponent at the end [-]."""
    sigma = noise_level(np.asarray(data.T_in))
    rate = (len(data.time) - 1) / float(data.time[-1] - data.time[0])
    est = tendon_model_estimator(mf, sigma, 0.02, rate, track_friction=track)
    out = np.array([est.step(float(a), float(b), float(c)).T_out for a, b, c in
                    zip(data.T_in, data.x_in, data.time, strict=True)])
    keep = np.asarray(data.time) >= settle
    err = out[keep] - np.asarray(data.T_out)[keep]
    return float(np.sqrt(np.mean(err * err))), est.friction


def one(effect: str, seed: int, level: float, duration: float, settle: float, work: Path) -> dict:
    """One seed of one effect: record, analyze --model-out, the three sessions through the three forms."""
    rec = record(effect, seed=seed, level=level, duration=duration)
    csv, model = work / f"{effect}-{seed}.csv", work / f"{effect}-{seed}.model.yaml"
    write_measured_csv(csv, rec.data, overwrite=True)
    p = subprocess.run([sys.executable, "-m", "live.cli", "analyze", str(csv), "--model-out", str(model)],
                       capture_output=True, text=True)
    row: dict = {"effect": effect, "seed": seed, "truth": rec.truth["parameters"], "K": rec.truth["K"]}
    if p.returncode != 0:
        return {**row, "error": (p.stderr.strip().splitlines() or ["?"])[-1]}
    mf = load_model(model)
    check_tendon(mf)
    row["named"] = [e.id for e in mf.extensions]
    if effect not in row["named"]:
        return {**row, "error": f"the diagnosis names {'+'.join(row['named']) or 'no extension'}"}
    sessions = {"same": rec.data, "moved": record(effect, seed=seed, level=level, duration=1.5 * duration).data,
                "none": record(None, seed=seed, duration=duration).data}
    for name, data in sessions.items():
        for form, m, track in (("base", _base_form(mf), False), ("replayed", mf, False), ("tracked", mf, True)):
            row[f"{name}/{form}"], K_end = _run(m, data, track, settle)
            if form == "tracked":
                row[f"{name}/K_end"] = K_end
    return row


def table(rows: list[dict]) -> str:
    """Medians over the seeds (the worst in brackets) per effect and session."""
    lines = ["| effect | session | seeds | RMSE T_out base form [N] | change replayed [N] | friction tracked [N] |",
             "|---|---|---|---|---|---|"]
    for effect in EFFECTS:
        ok = [r for r in rows if r["effect"] == effect and "error" not in r]
        for session in ("same", "moved", "none"):
            if not ok:
                continue
            cells = []
            for form in FORMS:
                v = np.array([r[f"{session}/{form}"] for r in ok])
                cells.append(f"{np.median(v):.3f} ({v.max():.3f})")
            lines.append(f"| `{effect}` | {session} | {len(ok)} | " + " | ".join(cells) + " |")
        for r in rows:
            if r["effect"] == effect and "error" in r:
                lines.append(f"| `{effect}` | seed {r['seed']} not run: {r['error']} | | | | |")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", default="1,2,3,4,5")
    ap.add_argument("--level", type=float, default=0.7, help="position in each effect's realistic range [0, 1]")
    ap.add_argument("--duration", type=float, default=60.0, help="the analysed session's length [s]")
    ap.add_argument("--settle", type=float, default=10.0, help="seconds left out of the score at the start [s]")
    ap.add_argument("--json", default=None, help="write the rows as JSON here")
    a = ap.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for effect in EFFECTS:
            for seed in (int(s) for s in a.seeds.split(",")):
                rows.append(r := one(effect, seed, a.level, a.duration, a.settle, Path(tmp)))
                print(json.dumps({k: v for k, v in r.items() if k != "truth"}, default=float), flush=True)
    print(f"\n`python benchmarks/bench_friction_tracking.py --seeds {a.seeds} --level {a.level} --duration "
          f"{a.duration:g}`: per seed, the effect at level {a.level} of its realistic range in a {a.duration:g} s "
          f"simulated session (study.scenarios protocol, 1 kHz, spring load), scored after {a.settle:g} s against "
          "the measured distal load cell; medians over the seeds, the worst in brackets\n")
    print(table(rows))
    if a.json:
        Path(a.json).write_text(json.dumps(rows, indent=1, default=float) + "\n")


if __name__ == "__main__":
    main()
