"""Where the demo's overruns come from: the loops' own work, or stalls of the whole machine.

Runs ``teleop demo`` (any ``--config``) with the per-cycle trace of both loops (``TELEOP_CYCLE_TRACE``,
:mod:`teleop.timing.cycles`) and, beside it, three witnesses that sample the machine:

* a *canary* per CPU: a 1 kHz sleeper pinned to that CPU at ``SCHED_FIFO`` 50 (above every thread of
  the demo; it uses ~1 % of a CPU) that records each wake-up later than 0.5 ms. Nothing in the guest but
  interrupts, kernel threads and the scheduler's own limits can hold it back, so a late canary is a
  stall of that CPU, not of our loops;
* ``/proc/stat`` every 2 ms: the hypervisor's *steal* per CPU (10 ms resolution): a canary stall with
  steal rising is the virtual machine stopped by its host;
* ``/sys/kernel/debug/sched/debug`` every 5 ms when readable (debugfs mounted, root): per CPU the
  real-time run queue's ``rt_time`` in the current period and ``rt_throttled``. Linux gives real-time
  threads at most ``sched_rt_runtime_us`` (950 ms) of each ``sched_rt_period_us`` (1 s) per CPU and
  then stops them all for the rest of the period (up to 50 ms): a canary stall without steal while
  the CPU ran other (normal) processes is that throttling.

Then every overrun of either loop is attributed: a *machine stall* when a canary was held (late by
more than 0.5 ms) at some time from 3 ms before the previous cycle's start to 3 ms after the late
cycle's start (split by whether steal rose), else the loop's own (its step, the interpreter lock, the
scheduler); the loop's own are listed with the step before them, wall and CPU time (a step whose
CPU time is far above its usual ~0.15-0.2 ms while nothing else of the loop changed is a stall the
hypervisor did not report as steal: with paravirtual steal accounting only reported steal is taken
out of a thread's CPU time). Prints the counts, the worst stalls with what the CPU did meanwhile,
and the demo's own lines. Never fails on time; measured figures depend on the machine's load at the
time (printed).

``python benchmarks/bench_stalls.py [demo arguments...]`` e.g. ``--config configs/instrument-3dof.yaml``.
"""
from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
LATE = 0.5e-3            # [s] a canary wake-up this late is a stall of its CPU
NEAR = 3e-3              # [s] an overrun this close to a canary stall is attributed to it
SCHED_DEBUG = Path("/sys/kernel/debug/sched/debug")
_RT = re.compile(r"rt_rq\[(\d+)\]:/\n\s+\.rt_nr_running\s+: (\d+)\n"
                 r"\s+\.rt_throttled\s+: (\d+)\n\s+\.rt_time\s+: ([\d.]+)")


# ---- the witnesses (each runs as its own process: python bench_stalls.py --witness KIND OUT [CPU]) ----
def _stopper() -> list[bool]:
    stop = [False]
    signal.signal(signal.SIGTERM, lambda *a: stop.__setitem__(0, True))
    return stop


def canary(cpu: int, out: str) -> None:
    """Sleep to a 1 ms grid pinned to ``cpu`` at SCHED_FIFO 50; save ``(deadline, lateness)`` of late wake-ups."""
    os.sched_setaffinity(0, {cpu})
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(50))
    except OSError:
        pass                                  # without the privilege the canary is a normal process
    import gc
    gc.disable()
    stop, late, n, P = _stopper(), [], 0, 1e-3
    nxt = time.monotonic() + P
    while not stop[0]:
        d = nxt - time.monotonic()
        if d > 0:
            time.sleep(d)
        now = time.monotonic()
        if now - nxt > LATE:
            late.append((nxt, now - nxt))
        n += 1
        nxt += P
        if now > nxt:
            nxt = now + P
    np.savez(out, late=np.asarray(late).reshape(-1, 2), wakes=n)


def proc_stat(out: str) -> None:
    """``/proc/stat`` per CPU every 2 ms: time, then (user, nice, system, idle, iowait, irq, softirq, steal) ticks."""
    stop, ts, rows = _stopper(), [], []
    while not stop[0]:
        with open("/proc/stat") as fh:
            lines = fh.read().split("\n")
        rows.append([[int(x) for x in ln.split()[1:9]] for ln in lines
                     if ln.startswith("cpu") and not ln.startswith("cpu ")])
        ts.append(time.monotonic())
        time.sleep(0.002)
    np.savez(out, t=np.asarray(ts), cpu=np.asarray(rows))


def rt_queue(out: str) -> None:
    """The real-time run queue of each CPU every 5 ms: time, then (running, throttled, rt_time [ms]) per CPU."""
    stop, rows = _stopper(), []
    while not stop[0]:
        t = time.monotonic()
        found = sorted(_RT.findall(SCHED_DEBUG.read_text()))
        rows.append([t] + [float(x) for c in found for x in c[1:]])
        time.sleep(0.005)
    np.save(out, np.asarray(rows))


# ---- the run ------------------------------------------------------------------------------------------
def _start(kind: str, out: Path, *extra: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, __file__, "--witness", kind, str(out), *extra])


def _stop(procs) -> None:
    for p in procs:
        p.send_signal(signal.SIGTERM)
    for p in procs:
        p.wait(30)


def _attribute(d: Path) -> None:
    cpus = os.cpu_count() or 1
    can = [np.load(d / f"canary{c}.npz") for c in range(cpus)]
    st = np.load(d / "stat.npz")
    t_st, ticks = st["t"], st["cpu"]
    hz = os.sysconf("SC_CLK_TCK")
    rt = np.load(d / "rt.npy") if (d / "rt.npy").is_file() else None
    stalls = sorted((float(a), float(b), c) for c, z in enumerate(can) for a, b in z["late"])
    parts = [f"cpu{c} {int(z['wakes'])} wakes, {len(z['late'])} late > {LATE * 1e3:g} ms" for c, z in enumerate(can)]
    print("canaries: " + ", ".join(parts))

    def window(a: float, b: float):
        i0 = max(0, np.searchsorted(t_st, a - 0.015) - 1)
        i1 = min(len(t_st) - 1, np.searchsorted(t_st, a + b + 0.015))
        return (ticks[i1] - ticks[i0]) * 1e3 / hz          # ms per CPU per column

    def throttled(a: float, b: float, cpu: int) -> bool | None:
        if rt is None or rt.shape[1] < 1 + 3 * (cpu + 1):
            return None
        sel = (rt[:, 0] >= a - 0.01) & (rt[:, 0] <= a + b + 0.01)
        return bool(np.any(rt[sel, 2 + 3 * cpu] > 0))

    kinds = {}
    print("worst machine stalls (canary lateness), what the CPU did meanwhile [ms]:")
    for a, b, c in sorted(stalls, key=lambda s: -s[1])[:8]:
        w = window(a, b)[c]
        thr = throttled(a, b, c)
        print(f"  cpu{c} at {a:.3f} s: {b * 1e3:5.1f} ms; steal {w[7]:.0f}, user {w[0]:.0f}, nice {w[1]:.0f}, "
              f"system {w[2]:.0f}, idle {w[3]:.0f}, softirq {w[6]:.0f}; rt throttled: "
              f"{'unknown (no sched debug)' if thr is None else thr}")
    for a, b, c in stalls:
        w = window(a, b)[c]
        thr = throttled(a, b, c)
        k = "VM (steal)" if w[7] > 0 else "rt throttling" if thr else "other (no steal)"
        kinds[k] = kinds.get(k, 0) + 1
    print(f"canary stalls by cause: {kinds}")
    if rt is not None and rt.size:
        for c in range(cpus):
            col = 3 + 3 * c
            if col < rt.shape[1]:
                print(f"  cpu{c}: real-time time in a 1 s period up to {rt[:, col].max():.0f} ms (limit 950), "
                      f"throttled in {100 * np.mean(rt[:, col - 1] > 0):.2f} % of the samples")
    for side in ("master", "slave"):
        path = d / f"{side}_cycles.npz"
        if not path.is_file():
            continue
        cy = np.load(path)["cycles"]
        t, late, step, ov = cy.T[:4]
        cpu = cy[:, 4] if cy.shape[1] > 4 else np.full(len(t), np.nan)
        idx = np.nonzero(ov > 0)[0]
        # at a machine stall: a canary was held within NEAR of the time between the previous cycle's start
        # and this one's (a stall while the loop slept or stepped; the late cycle starts when it ends)
        near = [any(a <= t[i] + NEAR and a + b >= (t[i - 1] if i else t[i]) - NEAR for a, b, _ in stalls) for i in idx]
        own = idx[~np.asarray(near, dtype=bool)] if len(idx) else idx
        prev = step[np.maximum(own - 1, 0)] * 1e3 if len(own) else np.array([0.0])
        prev_cpu = cpu[np.maximum(own - 1, 0)] * 1e3 if len(own) else np.array([0.0])
        print(f"{side}: {len(t)} cycles, {len(idx)} overruns ({100 * len(idx) / max(1, len(t)):.2f} %): "
              f"{int(np.sum(near))} at a machine stall, {len(own)} the loop's own (the step before: p50 "
              f"{np.median(prev):.2f} ms, max {prev.max():.2f} ms; its CPU time p50 {np.median(prev_cpu):.2f} ms); "
              f"step p50 {1e3 * np.median(step):.3f} ms, p99 {1e3 * np.percentile(step, 99):.3f} ms; step CPU time "
              f"p50 {1e3 * np.nanmedian(cpu) if np.isfinite(cpu).any() else np.nan:.3f} ms, "
              f"p99 {1e3 * np.nanpercentile(cpu, 99) if np.isfinite(cpu).any() else np.nan:.3f} ms")
        print(f"  {side} own overruns at (s into the loop, lateness ms, step before ms / its CPU ms): "
              + ", ".join(f"{t[i] - t[0]:.3f} {1e3 * late[i]:.2f} {1e3 * step[max(i - 1, 0)]:.2f}/"
                          f"{1e3 * cpu[max(i - 1, 0)]:.2f}" for i in own[:12]))
        g = np.load(path)["gc"]
        if len(g):
            print(f"  {side} garbage collections: {len(g)}, {1e3 * g[:, 1].sum():.2f} ms in all, longest "
                  f"{1e3 * g[:, 1].max():.2f} ms (generation {int(g[np.argmax(g[:, 1]), 2])})")


def main(argv: list[str]) -> None:
    d = Path(tempfile.mkdtemp(prefix="bench_stalls-"))
    print(f"load average {os.getloadavg()[0]:.1f}; trace and samples in {d}", flush=True)
    procs = [_start("stat", d / "stat.npz")]
    procs += [_start("canary", d / f"canary{c}.npz", str(c)) for c in range(os.cpu_count() or 1)]
    try:
        SCHED_DEBUG.read_text()
        procs.append(_start("rt", d / "rt.npy"))
    except OSError:
        print("(no /sys/kernel/debug/sched/debug: real-time throttling not observed; as root: "
              "mount -t debugfs none /sys/kernel/debug)")
    time.sleep(0.5)
    env = dict(os.environ, TELEOP_CYCLE_TRACE=str(d))
    try:
        out = subprocess.run([sys.executable, "-m", "live.cli", "demo", "--keep-realtime", "--run-dir", str(d / "run"),
                              *argv],
                             capture_output=True, text=True, env=env, cwd=ROOT).stdout
    finally:
        _stop(procs)
    print("\n".join(ln for ln in out.splitlines() if " loop:" in ln or "round trip" in ln or "machine steal" in ln))
    print(f"load average {os.getloadavg()[0]:.1f}")
    _attribute(d)


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--witness":
        kind, out = sys.argv[2], sys.argv[3]
        {"canary": lambda: canary(int(sys.argv[4]), out), "stat": lambda: proc_stat(out),
         "rt": lambda: rt_queue(out)}[kind]()
    else:
        main(sys.argv[1:])
