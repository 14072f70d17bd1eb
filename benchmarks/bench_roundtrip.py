"""Round trip of the teleoperation link beside a bare Zenoh ping-pong, measured in the same run.

1. Bare Zenoh: two processes on 127.0.0.1; the ping process publishes a 40-byte message at 1 kHz
   (paced by :class:`teleop.timing.clock.Pacer`, Zenoh priority REAL_TIME, not express, like the nodes), the
   pong process echoes each one from its subscriber callback; the ping measures send -> echo
   received. Both processes get the nodes' scheduling (:func:`teleop.timing.realtime.promote_threads` at
   ``master.realtime_priority``: the pinging thread on top, Zenoh's threads 5 below), so that the
   two figures differ by what the teleoperation adds, not by the scheduler.
2. ``teleop demo --protocol short`` (recorder + slave + master as three processes, configs/sim.yaml),
   in the same run: the master's command -> estimate-echo round trip, both loops' overruns (all
   cycles and teleoperation only), step times, scheduling and the slave's command-locked cycles,
   from ``summary.json``.

Prints the figures, never fails on time. ``python benchmarks/bench_roundtrip.py [seconds]``.
"""
from __future__ import annotations

import json
import os
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
_MSG = struct.Struct("<Id32x")     # seq, send time [s], padding: 44 bytes like a Command


def _priority() -> int:
    from teleop.config.load import load_config
    return load_config(ROOT / "configs" / "sim.yaml").master.realtime_priority


def _session(listen, connect):
    from teleop.config.schema import TransportConfig
    from teleop.session.transport import Session
    return Session(TransportConfig(listen=tuple(listen), connect=tuple(connect)))


def pong(endpoint: str, seconds: float) -> None:
    """Echo every message on ``bench/ping`` to ``bench/pong`` (runs in its own process)."""
    import zenoh
    with _session([endpoint], []) as s:
        z = s.zenoh_session
        pub = z.declare_publisher("bench/pong", express=False, priority=zenoh.Priority.REAL_TIME,
                                  congestion_control=zenoh.CongestionControl.DROP)
        sub = z.declare_subscriber("bench/ping", lambda sample: pub.put(sample.payload.to_bytes()))  # noqa: F841
        from teleop.timing.realtime import promote_threads
        promote_threads(_priority())              # the main thread only sleeps; Zenoh's threads echo
        print("ready", flush=True)
        time.sleep(seconds + 5.0)


def ping(endpoint: str, seconds: float, rate_hz: float = 1000.0) -> dict:
    """Publish at ``rate_hz`` for ``seconds``; round-trip statistics [ms] of the echoes."""
    import zenoh

    from teleop.timing.clock import MonotonicClock, Pacer
    rtt: list[float] = []
    with _session([], [endpoint]) as s:
        z = s.zenoh_session
        pub = z.declare_publisher("bench/ping", express=False, priority=zenoh.Priority.REAL_TIME,
                                  congestion_control=zenoh.CongestionControl.DROP)

        def on_pong(sample):
            _seq, t = _MSG.unpack(sample.payload.to_bytes())
            rtt.append(time.monotonic() - t)
        sub = z.declare_subscriber("bench/pong", on_pong)  # noqa: F841
        deadline = time.monotonic() + 5.0
        while not rtt and time.monotonic() < deadline:        # routes up
            pub.put(_MSG.pack(0, time.monotonic()))
            time.sleep(0.01)
        rtt.clear()
        from teleop.timing.realtime import demote_threads, promote_threads
        scheduling = promote_threads(_priority())
        clock = MonotonicClock()
        pacer = Pacer(clock, rate_hz)
        n = int(seconds * rate_hz)
        try:
            for k in range(n):
                pacer.wait()
                pub.put(_MSG.pack(k, time.monotonic()))
        finally:
            demote_threads()
        time.sleep(0.2)
        stats = pacer.stats()
    d = np.asarray(rtt) * 1e3
    return {"sent": n, "echoed": int(d.size), "p50_ms": float(np.percentile(d, 50)),
            "p99_ms": float(np.percentile(d, 99)), "max_ms": float(d.max()),
            "overrun_fraction": float(stats.get("overrun_fraction", 0.0)), "scheduling": scheduling}


def bare_pingpong(seconds: float) -> dict:
    from teleop.session.transport import free_tcp_port, loopback_endpoint
    ep = loopback_endpoint(free_tcp_port())
    proc = subprocess.Popen([sys.executable, __file__, "--pong", ep, str(seconds)], stdout=subprocess.PIPE, text=True,
                            cwd=ROOT)
    try:
        proc.stdout.readline()                                # "ready"
        return ping(ep, seconds)
    finally:
        proc.kill()
        proc.wait()


def demo_roundtrip(timeout: float = 120.0, config: Path | None = None) -> dict:
    """``teleop demo --protocol short`` (``config``: ``--config`` it) in real processes: round trip [ms],
    overruns, the sides' pacer figures and the recorder's message counts from its summaries."""
    with tempfile.TemporaryDirectory() as tmp:
        run = Path(tmp) / "run"
        extra = [] if config is None else ["--config", str(config)]
        # --keep-realtime: the sides at SCHED_FIFO as configured, as the bare ping-pong beside it, on any machine
        subprocess.run([sys.executable, "-m", "live.cli", "demo", "--protocol", "short", "--keep-realtime", *extra,
                        "--run-dir", str(run), "--timeout", str(timeout)], check=False, cwd=ROOT, capture_output=True,
                       timeout=timeout + 30, env=dict(os.environ, PYTHONUNBUFFERED="1"))
        s = json.loads((run / "summary.json").read_text())
        rec_summary = run / "recorder" / "summary.json"
        rec = json.loads(rec_summary.read_text()) if rec_summary.is_file() else {}
    lat = s["master"]["latency_rtt"]
    sides = {side: s[side]["pacer"] for side in ("master", "slave")}
    return {"p50_ms": lat["p50_ms"], "p99_ms": lat["p99_ms"], "max_ms": lat["max_ms"], "n": lat["n"],
            "master_overruns": sides["master"]["overrun_fraction"],
            "slave_overruns": sides["slave"]["overrun_fraction"], "pacer": sides,
            "recorded_missing": sum(v["missing"] for v in rec.get("streams", {}).values()),
            "recorded": sum(v["count"] for v in rec.get("streams", {}).values())}


def main(seconds: float = 10.0) -> None:
    print(f"load average before the run {os.getloadavg()[0]:.1f}", flush=True)
    bare = bare_pingpong(seconds)
    demo = demo_roundtrip()
    load = os.getloadavg()[0]
    print(f"machine: {os.cpu_count()} cores, load average {load:.1f} during the run")
    print(f"bare zenoh ping-pong, 2 processes, 1 kHz, {seconds:g} s ({bare['scheduling']}): "
          f"p50 {bare['p50_ms']:.3f} ms, "
          f"p99 {bare['p99_ms']:.3f} ms, max {bare['max_ms']:.2f} ms ({bare['echoed']}/{bare['sent']} echoed, "
          f"pacer overruns {100 * bare['overrun_fraction']:.2f} %)")
    print(f"teleop demo (recorder+slave+master), command -> estimate echo: p50 {demo['p50_ms']:.3f} ms, "
          f"p99 {demo['p99_ms']:.3f} ms, max {demo['max_ms']:.2f} ms over {demo['n']} echoes")
    print(f"  overruns: master {100 * demo['master_overruns']:.2f} %, slave {100 * demo['slave_overruns']:.2f} %; "
          f"recorder: {demo['recorded']} messages, {demo['recorded_missing']} missing by seq")
    for side, pc in demo["pacer"].items():
        cyc, ovr = pc.get("cycles_by_state", {}), pc.get("overruns_by_state", {})
        tele = [k for k in cyc if k not in ("STARTING", "CALIBRATING")]
        n_tele, o_tele = sum(cyc[k] for k in tele), sum(ovr.get(k, 0) for k in tele)
        step, late, cpu = pc.get("step_ms", {}), pc.get("lateness_ms", {}), pc.get("step_cpu_ms", {})
        ms = lambda v: "-" if v is None else f"{v:.2f}"    # noqa: E731
        print(f"  {side}: {pc.get('scheduling', '?')}, overruns outside calibration {o_tele}/{n_tele}"
              f" ({100 * o_tele / max(n_tele, 1):.2f} %), {pc.get('stalls', '?')} stalls > 1 period, "
              f"{pc.get('late_starts', '?')} late starts > 1/2 period; step p50 {ms(step.get('p50'))} p99 "
              f"{ms(step.get('p99'))} ms (its CPU time p50 {ms(cpu.get('p50'))} p99 {ms(cpu.get('p99'))} ms), "
              f"lateness p99 {ms(late.get('p99'))} ms" + (f", {pc['locked']} cycles started by a command"
                                                         if "locked" in pc else ""))


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--pong":
        pong(sys.argv[2], float(sys.argv[3]))
    else:
        import argparse
        ap = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
        ap.add_argument("seconds", nargs="?", type=float, default=10.0, help="bare ping-pong duration [s]")
        main(ap.parse_args().seconds)
