"""Each arm of the bimanual NOTES instrument on a fake clock: the haptic loop with and without backlash compensation.

The live demo (``teleop demo --config configs/notes-bimanual.yaml``) runs on real time, where the machine's stalls
add to the loop's figures. Here each arm's own config (teleop/arms.py) runs through the real slave and master
nodes on one fake clock at 1 kHz (benchmarks/stability_joints.py): calibration at power-up, then the paper's
protocol on every joint by the scripted hand, a one-way delay of ``--delay`` ms. Per joint and pulled tendon it
prints the transparency RMS and its three shares (estimate, loop, passivity; teleop/timing/loop_metrics.py) and the
worst force chatter, without and with ``pair_control.backlash_compensation``. Deterministic: the same figures on
any machine.

Usage: ``.venv/bin/python benchmarks/bench_bimanual_arms.py [--config FILE] [--delay MS]`` (~1 min of CPU).
"""
from __future__ import annotations

import argparse
from pathlib import Path

from stability_joints import calibration, run_joints

from teleop.arms import load_arms

ROOT = Path(__file__).resolve().parents[1]


def _line(label: str, row: dict) -> str:
    t = row["transparency"]
    sh = t.get("shares_rms_fs", {})
    return (f"{label:22s} rms {t['force_error_rms_fs']:.3f} FS  (estimate {sh.get('estimate', float('nan')):.3f}, "
            f"loop {sh.get('loop', float('nan')):.3f}, passivity {sh.get('passivity', float('nan')):.3f})  "
            f"chatter {row['chatter']['force_worst_N']:.3f} N")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default=str(ROOT / "configs" / "notes-bimanual.yaml"), help="a bimanual config")
    ap.add_argument("--delay", type=float, default=1.0, help="one-way delay of the links [ms] (default 1)")
    args = ap.parse_args()
    for arm in load_arms(args.config).arms:
        cal = calibration(base=arm.cfg)
        for comp in (False, True):
            r = run_joints(cal, delay=1e-3 * args.delay, overrides={"pair_control.backlash_compensation": comp},
                           base=arm.cfg)
            rows = {k: v for k, v in r.items() if isinstance(v, dict)}
            print(f"== arm {arm.name} ({arm.hand} hand), backlash compensation {'on' if comp else 'off'}: "
                  f"protocol {'finished' if r['finished'] else 'NOT finished'}, safe events {r['safe_events']}")
            for name, row in rows.items():
                print(_line(name, row))
            worst = max(v["transparency"]["force_error_rms_fs"] for v in rows.values())
            print(f"worst transparency rms {worst:.3f} FS over {len(rows)} pulls", flush=True)


if __name__ == "__main__":
    main()
