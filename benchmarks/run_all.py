"""Run every benchmark and print its figures (`make bench`)."""
from __future__ import annotations

import importlib
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

BENCHES = ["bench_estimator", "bench_rig", "bench_joint_rig", "bench_codec", "bench_diagnosis", "bench_analyze",
           "bench_lumped", "bench_slave_cycle", "bench_roundtrip", "bench_mrd", "bench_stability", "bench_noise_band"]


def main() -> None:
    for name in BENCHES:
        try:
            mod = importlib.import_module(name)
        except ModuleNotFoundError as exc:
            if exc.name != name:
                raise
            continue
        print(f"== {name}")
        mod.main()
        print()


if __name__ == "__main__":
    main()
