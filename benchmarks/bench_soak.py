"""An hour at 1 kHz: recorder, slave and master on loopback for a set time, figures per window, a verdict.

The three processes of ``teleop demo`` (``teleop record``, ``teleop slave``, ``teleop master`` with the
scripted operator, configs/sim.yaml: the default recording) talk Zenoh on 127.0.0.1 with multicast
scouting off. The slave reloads a calibration made first (``teleop calibrate``); the master runs the
``paper,minor`` protocol over and over and stops at ``--duration`` (``--max-duration``), the slave a few
seconds later, the recorder once both have gone. Each process writes its live figures every
:data:`LIVE_EVERY` seconds (``TELEOP_LIVE_STATS``, live/side_files.py): cycles, overruns, messages sent,
the master's round-trip histogram, the recorder's count and seq gaps per stream.

Per ``--window`` (and at the end of the first minute, the memory baseline) it prints and appends to the
JSON file (rewritten whole after every window, so a run cut short keeps its figures): each loop's
overruns, the round trip's p50 and p99 in the window, the resident memory (RSS) of every process and of
its children (the sides' Rerun logging processes), the run directory's bytes and bytes per hour, how far
the recorder is behind the sides (commands and estimates sent and not yet written) and the messages it is
missing by seq. A recorder behind by thousands of messages is starved of CPU (it runs niced, below the two
real-time loops): it holds the backlog in memory, and what the senders' queues drop meanwhile is lost to it. At the end,
the messages lost (each side's sent count against what the recorder holds) and a verdict on the criteria: RSS growth
after the first minute below
:data:`RSS_GROWTH` per process, the last window's round-trip p99 within :data:`P99_DRIFT` of the first's,
no message lost, under :data:`BYTES_PER_HOUR` of disk per hour (the growing files at their rate over the run,
the journals' ring of at most 16 MB per side once).

``python benchmarks/bench_soak.py [--duration 3600] [--window 300] [--run-dir DIR] [--json FILE]``
(defaults: an hour, 5-minute windows, ``runs/soak-<timestamp>``, ``<run dir>/soak.json``). Prints
figures; exits 0 whatever the verdict (a timing benchmark on a shared machine), 2 when a process
could not start.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from live.record.budget import JOURNAL, LIVE_ENV, dir_bytes
from teleop.timing.latency import BIN, SPAN, bin_percentile

ROOT = Path(__file__).resolve().parents[1]

LIVE_EVERY = 2.0            # [s] the processes' live figures are this old at most
BASELINE = 60.0             # [s] memory is compared with its value at the end of the first minute
RSS_GROWTH = 20e6           # [B] allowed RSS growth of a process after the first minute
P99_DRIFT = 0.20            # [-] allowed change of the round-trip p99, last window against the first
BYTES_PER_HOUR = 1e9        # [B] disk per hour of the default recording
REP_S = 8.0                 # [s] one paper,minor round of the scripted operator takes longer than this


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--duration", type=float, default=3600.0, help="session length [s] (default 3600)")
    p.add_argument("--window", type=float, default=300.0, help="window of the figures [s] (default 300)")
    p.add_argument("--config", default=str(ROOT / "configs" / "sim.yaml"), help="config (default configs/sim.yaml)")
    p.add_argument("--run-dir", default=None, help="run directory (default runs/soak-<timestamp>)")
    p.add_argument("--json", default=None, help="figures file (default <run dir>/soak.json)")
    a = p.parse_args(argv)
    if not (a.duration > 0 and a.window > 0):
        p.error("--duration and --window must be > 0 s")
    return a


def prepare(args: argparse.Namespace) -> tuple[Path, Path]:
    """The run directory, its resolved config (calibration in the run directory) and the calibration file."""
    from teleop.config.load import load_config, write_config
    cfg = load_config(args.config)
    run_dir = Path(args.run_dir or Path(cfg.recording.dir) / time.strftime("soak-%Y%m%d-%H%M%S"))
    run_dir.mkdir(parents=True, exist_ok=True)
    cfg = dataclasses.replace(cfg, calibration=dataclasses.replace(cfg.calibration, dir=str(run_dir / "calibration")))
    cfg_file = write_config(cfg, run_dir / "config.yaml")
    with open(run_dir / "calibrate.log", "w") as fh:
        subprocess.run([sys.executable, "-m", "live.cli", "calibrate", "--config", str(cfg_file)], stdout=fh,
                       stderr=subprocess.STDOUT, check=True, cwd=ROOT, timeout=300)
    return run_dir, cfg_file


def launch(run_dir: Path, cfg_file: Path, duration: float) -> dict[str, subprocess.Popen]:
    """Recorder, slave (listening on a free loopback port) and master; {} when one did not start."""
    from live.record.beside_demo import start_recorder
    from teleop.session.transport import accepts_connections, free_tcp_port, loopback_endpoint
    base = [sys.executable, "-m", "live.cli"]
    env = dict(os.environ, PYTHONUNBUFFERED="1", **{LIVE_ENV: f"{LIVE_EVERY:g}"})
    common = ["--config", str(cfg_file), "--run-dir", str(run_dir)]
    deadline = time.monotonic() + 120.0
    rec, link = start_recorder(base, common + ["--max-duration", f"{duration + 120:g}"], run_dir, env, deadline)
    procs = {"recorder": rec}
    if link is None:
        return {}
    port = free_tcp_port()
    ep = loopback_endpoint(port)
    with open(run_dir / "slave.log", "w") as fh:
        procs["slave"] = subprocess.Popen(base + ["slave", "--listen", ep, "--exit-on-master-stop", "--max-duration",
                                                  f"{duration + 3:g}"] + link + common,
                                          stdout=fh, stderr=subprocess.STDOUT, env=env, cwd=ROOT)
    while not accepts_connections(port):
        if procs["slave"].poll() is not None or time.monotonic() > deadline:
            return {}
        time.sleep(0.05)
    protocol = ",".join(["paper,minor"] * (int(duration / REP_S) + 2))     # never finished before --duration
    with open(run_dir / "master.log", "w") as fh:
        procs["master"] = subprocess.Popen(base + ["master", "--connect", ep, "--protocol", protocol, "--max-duration",
                                                   f"{duration:g}"] + link + common,
                                           stdout=fh, stderr=subprocess.STDOUT, env=env, cwd=ROOT)
    return procs


def rss(pid: int) -> int | None:
    """Resident memory of process ``pid`` [B] (psutil, else /proc/<pid>/status VmRSS); None when gone."""
    try:
        import psutil
        return int(psutil.Process(pid).memory_info().rss)
    except ImportError:
        pass
    except Exception:  # noqa: BLE001 - psutil.NoSuchProcess and the like: the process has gone
        return None
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) * 1024
    except OSError:
        return None
    return None


def children(pid: int) -> list[int]:
    """The child processes of ``pid`` (a side's Rerun logging process)."""
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            text = stat.read_text()
        except OSError:
            continue
        if int(text.rsplit(")", 1)[1].split()[1]) == pid:
            out.append(int(stat.parent.name))
    return out


def memory(procs: dict[str, subprocess.Popen]) -> dict[str, int | None]:
    """RSS [B] of every process and of its live children (``<name>.child<k>``, k counting the live ones in the
    order they started: a side's Rerun child of the present segment is ``child0`` but for the moment a segment's
    child finishes beside the next one)."""
    out: dict[str, int | None] = {}
    for name, p in procs.items():
        out[name] = rss(p.pid)
        live = [r for r in (rss(c) for c in sorted(children(p.pid))) if r is not None]
        for k, r in enumerate(live):
            out[f"{name}.child{k}"] = r
    return out


def read_live(run_dir: Path) -> dict[str, dict]:
    """The latest live figures of each process ({} for one that has written none yet)."""
    out = {}
    for name, path in (("slave", run_dir / "slave_live.json"), ("master", run_dir / "master_live.json"),
                       ("recorder", run_dir / "recorder" / "live.json")):
        try:
            out[name] = json.loads(path.read_text())
        except (OSError, ValueError):
            out[name] = {}
    return out


def _hist(live: dict) -> np.ndarray:
    snap = live.get("rtt") or {}
    counts = np.zeros(int(round(SPAN / BIN)) + 1, dtype=np.int64)     # LatencyHistogram's bins, overflow last
    for i, c in (snap.get("bins") or {}).items():
        counts[min(int(i), counts.size - 1)] += c
    return counts


def disk_bytes(run_dir: Path) -> tuple[int, int]:
    """(all bytes of the run directory, those without the journals' bounded ring) [B]."""
    owners = dir_bytes(run_dir)
    return sum(owners.values()), sum(v for k, v in owners.items() if not k.endswith(JOURNAL))


def window(prev: dict, cur: dict, t0: float, t1: float) -> dict:
    """The figures of the window from state ``prev`` to ``cur`` (each: live figures, disk bytes, memory)."""
    out: dict = {"t_start_s": round(t0, 1), "t_end_s": round(t1, 1)}
    for side in ("master", "slave"):
        a, b = prev["live"].get(side, {}), cur["live"].get(side, {})
        out[f"{side}_overruns"] = b.get("overruns", 0) - a.get("overruns", 0)
        out[f"{side}_cycles"] = b.get("cycles", 0) - a.get("cycles", 0)
    d = _hist(cur["live"].get("master", {})) - _hist(prev["live"].get("master", {}))
    p50, p99 = bin_percentile(d, 50), bin_percentile(d, 99)
    out["rtt_n"] = int(d.sum())
    out["rtt_p50_ms"] = None if p50 is None else round(1e3 * p50, 4)
    out["rtt_p99_ms"] = None if p99 is None else round(1e3 * p99, 4)
    out["rss_bytes"] = cur["rss"]
    out["disk_bytes"], out["disk_bytes_no_journals"] = cur["disk"]
    dt = max(1e-9, cur["t"] - prev["t"])
    out["disk_bytes_per_hour"] = round((cur["disk"][1] - prev["disk"][1]) / dt * 3600)
    rec = cur["live"].get("recorder", {})
    streams = {k: v for k, v in rec.items() if isinstance(v, list)}
    out["recorder_messages"] = sum(v[0] for v in streams.values())
    out["missing_by_seq"] = sum(v[1] for v in streams.values())
    sent = sum(cur["live"].get(side, {}).get("sent", 0) for side in ("master", "slave"))
    fast = sum(v[0] for k, v in streams.items() if k.endswith(("/command", "/estimate")))
    out["recorder_behind"] = max(0, sent - fast)      # commands and estimates sent, not yet written [messages]
    return out


def line(w: dict) -> str:
    """One printed line of a window."""
    mem = ", ".join(f"{k} {v / 1e6:.0f}" for k, v in w["rss_bytes"].items() if v)
    return (f"[{w['t_start_s']:6.0f}-{w['t_end_s']:6.0f} s] overruns master {w['master_overruns']} slave "
            f"{w['slave_overruns']}; rtt p50 {w['rtt_p50_ms']} ms p99 {w['rtt_p99_ms']} ms (n {w['rtt_n']}); "
            f"RSS MB {mem}; disk {w['disk_bytes'] / 1e6:.1f} MB ({w['disk_bytes_per_hour'] / 1e9:.3f} GB/h); "
            f"recorder {w['recorder_messages']} messages, {w['recorder_behind']} behind, {w['missing_by_seq']} missing "
            f"by seq")


def state(procs: dict, run_dir: Path, t0: float) -> dict:
    """Now: time since the start [s], live figures, disk bytes, memory."""
    return {"t": time.monotonic() - t0, "live": read_live(run_dir), "disk": disk_bytes(run_dir),
            "rss": memory(procs)}


def lost(run_dir: Path) -> dict:
    """Each 1 kHz stream's messages sent (the sides' stats) against those the recorder holds (its summary)."""
    def load(path: Path) -> dict:
        try:
            return json.loads(path.read_text())
        except (OSError, ValueError):
            return {}
    rec = load(run_dir / "recorder" / "summary.json").get("streams", {})
    held = {k.rsplit("/", 2)[-2] + "/" + k.rsplit("/", 1)[-1]: v.get("count", 0) for k, v in rec.items()}
    sent = {"slave/estimate": load(run_dir / "slave_stats.json").get("estimates_sent"),
            "master/command": load(run_dir / "master_stats.json").get("commands_sent")}
    return {k: {"sent": s, "recorded": held.get(k, 0), "lost": None if s is None else s - held.get(k, 0)}
            for k, s in sent.items()}


def verdict(windows: list[dict], base: dict, end: dict, losses: dict, duration: float) -> tuple[dict, str]:
    """The criteria (module docstring) from the windows, the first-minute state ``base`` and the last ``end``."""
    growth = {k: (end["rss"].get(k) or 0) - v for k, v in base["rss"].items() if v and end["rss"].get(k)}
    p99 = [w["rtt_p99_ms"] for w in windows if w["rtt_p99_ms"] is not None and w["rtt_n"] > 100]
    drift = (p99[-1] / p99[0] - 1.0) if len(p99) >= 2 and p99[0] > 0 else math.nan
    n_lost = [v["lost"] for v in losses.values()]
    # an hour's disk: the files that grow, at their rate over the run, plus the journals' ring once (bounded)
    per_hour = end["disk"][1] / max(1e-9, duration) * 3600 + (end["disk"][0] - end["disk"][1])
    checks = {f"RSS growth after {BASELINE:g} s < {RSS_GROWTH / 1e6:g} MB per process": bool(growth) and all(
                  g < RSS_GROWTH for g in growth.values()),
              f"round-trip p99 of the last window within {100 * P99_DRIFT:g} % of the first": abs(drift) <= P99_DRIFT,
              "no message lost": all(x == 0 for x in n_lost) and sum(w["missing_by_seq"] for w in windows[-1:]) == 0,
              f"under {BYTES_PER_HOUR / 1e9:g} GB per hour on disk": per_hour < BYTES_PER_HOUR}
    figures = {"rss_growth_bytes": growth, "p99_drift": None if math.isnan(drift) else round(drift, 4),
               "lost": losses, "disk_bytes": end["disk"][0], "disk_bytes_per_hour": round(per_hour)}
    text = "verdict: " + "; ".join(f"[{'PASS' if ok else 'FAIL'}] {k}" for k, ok in checks.items())
    return {"checks": checks, **figures}, text


def _save(path: Path, data: dict) -> None:
    tmp = Path(str(path) + ".tmp")
    tmp.write_text(json.dumps(data, indent=1) + "\n")
    os.replace(tmp, path)


def _wait(procs: dict, until: float, t0: float) -> None:
    while time.monotonic() - t0 < until and any(p.poll() is None for k, p in procs.items() if k != "recorder"):
        time.sleep(0.5)


def run(args: argparse.Namespace) -> int:
    run_dir, cfg_file = prepare(args)
    out = Path(args.json or run_dir / "soak.json")
    data: dict = {"duration_s": args.duration, "window_s": args.window, "run_dir": str(run_dir), "windows": []}
    print(f"soak: {args.duration:g} s in windows of {args.window:g} s -> {run_dir} (figures: {out})", flush=True)
    procs = launch(run_dir, cfg_file, args.duration)
    if not procs:
        print(f"soak: a process did not start (see {run_dir}/*.log)", flush=True)
        return 2
    t0 = time.monotonic()
    prev = state(procs, run_dir, t0)
    n_windows = int(math.ceil(args.duration / args.window))
    marks = sorted({min(BASELINE, args.duration)} | {min(args.duration, args.window * k)
                                                     for k in range(1, n_windows + 1)})
    base = prev
    for mark in marks:
        _wait(procs, mark - 0.5, t0)              # the figures of the last LIVE_EVERY before the mark
        cur = state(procs, run_dir, t0)
        if mark == min(BASELINE, args.duration):
            base = cur
            data["baseline"] = {"t_s": round(cur["t"], 1), "rss_bytes": cur["rss"]}
        if mark in (BASELINE,) and mark % args.window:
            continue                              # the baseline only, not a window of its own
        w = window(prev, cur, prev["t"], cur["t"])
        print(line(w), flush=True)
        data["windows"].append(w)
        _save(out, data)
        prev = cur
    for _name, p in procs.items():
        try:
            p.wait(120.0)
        except subprocess.TimeoutExpired:
            p.terminate()
    end = state({}, run_dir, t0)
    end["rss"] = prev["rss"]
    data["verdict"], text = verdict(data["windows"], base, end, lost(run_dir), args.duration)
    data["exit_codes"] = {k: p.returncode for k, p in procs.items()}
    data["files"] = {p.relative_to(run_dir).as_posix(): p.stat().st_size for p in sorted(run_dir.rglob("*"))
                     if p.is_file()}
    _save(out, data)
    print(f"lost: {data['verdict']['lost']}; disk {end['disk'][0] / 1e6:.1f} MB "
          f"({data['verdict']['disk_bytes_per_hour'] / 1e9:.3f} GB per hour)\n{text}", flush=True)
    return 0


def main(argv: list[str] | None = None) -> int:
    return run(parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
