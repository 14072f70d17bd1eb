"""What a demo asks of ``teleop record`` (start it beside the sides, one line on what it wrote) and the last line
``teleop record`` prints."""
from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

__all__ = ["final_line", "nothing_received_reason", "print_last_line", "start_recorder", "summary_line"]


def start_recorder(base: list[str], common: list[str], run_dir: Path, env: dict, deadline: float):
    """Start ``teleop record`` for a demo beside the sides: listening on a free loopback port, exiting
    once both sides have gone. Returns ``(process, ["--connect", endpoint])`` once it is ready (the
    sides connect to it, so it hears every message from their first one), or ``(process, None)`` when
    it did not become ready before ``deadline`` [s, monotonic] (see ``<run_dir>/recorder.log``)."""
    import subprocess

    from teleop.session.transport import free_tcp_port, loopback_endpoint
    ep = loopback_endpoint(free_tcp_port())
    log_path = run_dir / "recorder.log"
    with open(log_path, "w") as fh:
        # niceness +5: on a busy machine the two control loops get the CPU first (the recorder is buffered)
        proc = subprocess.Popen(base + ["record", "--listen", ep, "--exit-when-done"] + common, stdout=fh,
                                stderr=subprocess.STDOUT, env=env, preexec_fn=lambda: os.nice(5))
    while time.monotonic() < deadline and proc.poll() is None:
        if "(ready)" in log_path.read_text(encoding="utf-8", errors="replace"):
            return proc, ["--connect", ep]
        time.sleep(0.05)
    return proc, None


def final_line(s: dict, out_dir: str | Path) -> str:
    """The last line of ``teleop record``, from its summary ``s`` (what it writes as ``summary.json``): per stream
    the messages counted, the seqs missing and the messages not written (``not_written``: a write error, the disk
    budget), the files a write error stopped, and where the summary is."""
    counts = ", ".join(f"{k.rsplit('/', 2)[-2]}/{k.rsplit('/', 1)[-1]} {v['count']} (missing {v['missing']}, "
                       f"not written {v['not_written']})" for k, v in s["streams"].items())
    failed = (s.get("disk") or {}).get("write_errors") or {}
    stopped = f"; stopped by a write error: {', '.join(f'{n} ({e})' for n, e in failed.items())}" if failed else ""
    return f"teleop record: {counts}{stopped}; {Path(out_dir) / 'summary.json'}"


def print_last_line(s: dict, out_dir: str | Path, instrument: str, sides_seen) -> int:
    """Print the last line of ``teleop record`` for its summary ``s``: :func:`final_line` on stdout, or why
    nothing was received on stderr (:func:`nothing_received_reason`). Returns the exit code (0, or 1: nothing
    received) of a recording that ended by itself."""
    if not s["streams"]:
        print(f"teleop record: nothing received: {nothing_received_reason(instrument, sides_seen)}; "
              f"{Path(out_dir) / 'summary.json'}", file=sys.stderr, flush=True)
        return 1
    print(final_line(s, out_dir), flush=True)
    return 0


def summary_line(out_dir: str | Path) -> str:
    """One line on a finished recording: messages, streams, seqs missing, messages not written (summary.json's
    streams, as :func:`final_line`), the session's bytes per second
    (``disk.bytes_per_second``), what the disk limits or errors kept out, where the files are."""
    path = Path(out_dir) / "summary.json"
    try:
        s = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return f"recorder: no summary in {out_dir}"
    streams = s.get("streams", {}).values()
    disk = s.get("disk") or {}
    rate = sum((disk.get("bytes_per_second") or {}).values())
    extra = f", the session writes {rate / 1e3:.0f} kB/s ({rate * 3600 / 1e9:.2f} GB per hour)" if rate > 0 else ""
    if disk.get("reached"):
        extra += f"; {disk['reached']['reason']}: high-rate streams not written from t={disk['reached']['time']:.1f} s"
    if disk.get("not_written"):
        extra += "; not written (disk): " + ", ".join(f"{k} {n}" for k, n in disk["not_written"].items())
    return (f"recorder: {sum(v['count'] for v in streams)} messages on {len(s.get('streams', {}))} streams, "
            f"{sum(v['missing'] for v in streams)} missing by seq, {sum(v.get('not_written', 0) for v in streams)} "
            f"not written{extra} -> {out_dir}")


def nothing_received_reason(instrument: str, sides_seen) -> str:
    """Why a recorder heard no message: no side of ``instrument`` ever appeared, or sides did but sent nothing."""
    if not sides_seen:
        return (f"no side of instrument {instrument!r} appeared (no liveliness token): none was running, it uses "
                f"another instrument.id, or the link to it was refused (password, certificate, endpoint)")
    return (f"{' and '.join(sorted(sides_seen))} appeared but published nothing on teleop/{instrument}/...: it "
            f"stopped before its loop started")
