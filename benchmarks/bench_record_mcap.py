"""The recorder's MCAP writer: CPU time per message at the live session's mix (one command and one single-tendon
estimate per 1 ms cycle, a heartbeat per 100 ms), each estimate as JSON plus its four CRTK ROS 2 messages (CDR).

    .venv/bin/python benchmarks/bench_record_mcap.py [cycles]

Prints the CPU time per message and the share of one core a 1 kHz session takes on the recorder's writer thread.
"""
from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

from estimator.phase import Phase
from live.record.mcap_file import McapRecording
from teleop.config.schema import Config
from teleop.wire.messages import Command, Heartbeat, Side, SideState, tendon_estimate


def session(cycles: int) -> list:
    out: list = []
    for k in range(cycles):
        t = 10.0 + 1e-3 * k
        if k % 100 == 0:
            out.append((t, "teleop/b/slave/heartbeat", Heartbeat(Side.SLAVE, k // 100, t, SideState.ENGAGED)))
        out.append((t + 2e-4, "teleop/b/master/command", Command(k, t, (1e-4 * k,), True, 1)))
        out.append((t + 3e-4, "teleop/b/slave/estimate",
                    tendon_estimate(k, k, t, 5.0, 5e-4, 4.0, 5e-5, 4.5e-4, Phase.PULL, tuple(range(16)))))
    return out


def main(cycles: int = 5000) -> None:
    msgs = session(cycles)
    with tempfile.TemporaryDirectory() as d:
        mc = McapRecording(Path(d) / "b.mcap", Config(), time.time() - time.monotonic())
        c0 = time.process_time()
        for t, key, m in msgs:
            mc.write(t, key, m)
        mc.close()
        cpu = time.process_time() - c0
        size = (Path(d) / "b.mcap").stat().st_size
    per_cycle = cpu / cycles
    print(f"{len(msgs)} messages ({cycles} cycles): {cpu / len(msgs) * 1e6:.0f} us CPU per message, "
          f"{per_cycle * 1e6:.0f} us per 1 ms cycle = {per_cycle / 1e-3:.0%} of one core at 1 kHz; "
          f"{size / cycles:.0f} bytes per cycle in the file (zstd)")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 5000)
