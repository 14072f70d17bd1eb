"""Diagnose a recording: how far the base model is off, which physical effect explains it, and the gain.

    python examples/diagnose.py                     # a simulated recording with a hidden effect
    python examples/diagnose.py rec.csv             # your own measured-data CSV (docs/reference/formats.md)
    python examples/diagnose.py --effect stiction   # another hidden effect of the simulated rig

:func:`estimator.diagnose` fits the base model (the capstan law with profile memory) and every
extension of the effect catalogue on a training block, chooses by time-blocked validation inside it
and reports the held-out errors of the base and the chosen model on the rest (docs/concepts/diagnosis.md).
Without a file, 30 s of the simulated bench rig are recorded with one effect hidden (velocity-dependent
friction unless ``--effect`` names another), which the diagnosis does not see.
"""
from __future__ import annotations

import argparse

from estimator import MeasuredData, diagnose
from teleop.recording.measured_csv import read_measured_csv


def simulated(effect: str) -> tuple[MeasuredData, str]:
    """30 s of the simulated bench rig with ``effect`` hidden at 80 % of its realistic range: (data, effect)."""
    from study.scenarios import record
    rec = record(effect, seed=3, level=0.8, duration=30.0)
    return rec.data, str(rec.truth["effect"])


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("csv", nargs="?", help="measured-data CSV with T_out and/or x_out (default: simulated)")
    p.add_argument("--effect", default="velocity_friction", help="the effect hidden in the simulated recording")
    args = p.parse_args(argv)
    if args.csv is None:
        data, hidden = simulated(args.effect)
        print(f"recording: simulated bench rig, {data.time[-1]:.0f} s, hidden effect: {hidden}")
    else:
        data = read_measured_csv(args.csv)
        print(f"recording: {args.csv}, {data.time.size} samples over {data.time[-1] - data.time[0]:.1f} s")
    d = diagnose(data)
    also = f" (explains it as well: {', '.join(d['equivalent'])})" if d.get("equivalent") else ""
    print(f"cause: {d['cause']}" + also)
    for key, label, unit, scale in (("rmse_T_out_N", "distal tension", "N", 1.0),
                                    ("rmse_x_out_m", "distal displacement", "um", 1e6)):
        base, ext = d["base"].get(key), d["extended"].get(key)
        if base is not None and ext is not None:
            print(f"held-out {label} rms error: base model {base * scale:.3g} {unit}, "
                  f"with the cause {ext * scale:.3g} {unit}")
    if d.get("gain") is not None:
        print(f"gain on the held-out block: {100 * d['gain']:.0f} %")
    for name, q in d["parameters"].items():
        if q["effect"] != "base" and isinstance(q["value"], float):
            print(f"  {name} = {q['value']:.4g} {q['unit']} ({q['effect']})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
