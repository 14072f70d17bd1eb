"""Run every benchmark and print its figures (`make bench`): each one as its own process, so that the
thread settings a benchmark makes before numpy loads hold for it."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent

BENCHES = ["bench_estimator", "bench_rig", "bench_joint_rig", "bench_codec", "bench_diagnosis", "bench_analyze",
           "bench_lumped", "bench_slave_cycle", "bench_roundtrip", "bench_mrd", "bench_stability", "bench_noise_band",
           "bench_crtk", "bench_record_mcap", "bench_scaling", "bench_bimanual_arms"]


def main() -> int:
    """Run each benchmark of BENCHES that exists, in order; returns the first non-zero exit code (0 if none)."""
    failed = 0
    for name in BENCHES:
        path = HERE / f"{name}.py"
        if not path.exists():
            continue
        print(f"== {name}", flush=True)
        code = subprocess.run([sys.executable, str(path)], check=False).returncode
        if code and not failed:
            failed = code
        print(flush=True)
    return failed


if __name__ == "__main__":
    sys.exit(main())
