"""A recorder whose disk fills mid-session: recorder, slave and master as three processes, the recorder
under a file-size limit (RLIMIT_FSIZE, with SIGXFSZ ignored, so a write past it fails with EFBIG as a
write to a full disk fails with ENOSPC).

What the recorder handed to the OS before the limit stays readable (every record of messages.bin
decodes, each stream's seqs without a gap), both sides run on and end cleanly, and summary.json names
the files that stopped and counts what they did not get; the recorder's last line counts the messages not
written per stream as summary.json does. Deadlines only bound waits.
"""
from __future__ import annotations

import json
import os
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from live.record.recorder import read_messages
from teleop.session.transport import free_tcp_port
from teleop.wire.codec import decode
from tests.integration.processes import start, stop_all, wait_for, wait_text, write_bare_config

pytestmark = pytest.mark.integration

LIMIT = 150_000     # [B] largest file the recorder may write



def _limited() -> None:
    """In the recorder's process, before exec: files up to LIMIT bytes, a write past it fails (EFBIG)."""
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (LIMIT, LIMIT))


def _data_rows(path: Path) -> int:
    return sum(1 for ln in path.read_text().splitlines()[1:] if ln and not ln.startswith("#"))


def test_a_full_disk_under_the_recorder_keeps_what_it_wrote_and_both_loops_running(tmp_path):
    runs = tmp_path / "runs"
    cfg = tmp_path / "c.yaml"
    write_bare_config(cfg, "dfull", runs, free_tcp_port())
    procs: dict[str, subprocess.Popen] = {}
    try:
        with open(tmp_path / "record.log", "w") as fh:
            procs["recorder"] = subprocess.Popen(
                [sys.executable, "-m", "live.cli", "record", "--config", str(cfg), "--max-duration", "90"],
                stdout=fh, stderr=subprocess.STDOUT, env=dict(os.environ, PYTHONUNBUFFERED="1"), preexec_fn=_limited)
        wait_text(tmp_path / "record.log", "(ready)", 20)
        procs["slave"] = start(["slave", "--config", str(cfg), "--max-duration", "90"], tmp_path / "slave.log")
        procs["master"] = start(["master", "--config", str(cfg), "--protocol", "paper", "--max-duration", "90"],
                                tmp_path / "master.log")
        wait_text(tmp_path / "record.log", "messages.bin is no longer written", 60)
        time.sleep(1.0)                                         # the sides run on past the recorder's full disk
        for side in ("master", "slave"):
            procs[side].send_signal(signal.SIGINT)
            assert procs[side].wait(20) in (0, 130), (tmp_path / f"{side}.log").read_text()[-1500:]
        procs["recorder"].send_signal(signal.SIGINT)
        assert procs["recorder"].wait(30) == 130
    finally:
        stop_all(procs.values())
    run = next(p for p in runs.glob("*") if p.is_dir())
    rec = run / "recorder"
    summary = json.loads((rec / "summary.json").read_text())
    disk = summary["disk"]
    assert "File too large" in disk["write_errors"]["messages.bin"] and disk["not_written"]["messages.bin"] > 0
    assert (rec / "messages.bin").stat().st_size <= LIMIT
    kept: dict[str, list[int]] = {}
    for _, key, payload in read_messages(rec / "messages.bin"):
        kept.setdefault(key, []).append(decode(payload).seq)     # every record written decodes
    est = "teleop/dfull/slave/estimate"
    for key, seqs in kept.items():                              # what was written has no hole
        assert seqs == list(range(seqs[0], seqs[0] + len(seqs))), key
    assert summary["streams"][est]["count"] > len(kept[est])    # counted past the limit, not written
    assert summary["streams"][est]["missing"] == 0
    *_, last, interrupted = (tmp_path / "record.log").read_text().strip().splitlines()
    assert interrupted == "teleop: interrupted"                 # Ctrl-C: the counts are the last line before it
    for key, v in summary["streams"].items():                   # the last line and summary.json count alike
        side, stream = key.split("/")[-2:]
        assert f"{side}/{stream} {v['count']} (missing {v['missing']}, not written {v['not_written']})" in last
        assert v["count"] - v["not_written"] <= len(kept.get(key, ()))     # what counts as written reads back
    assert summary["streams"][est]["not_written"] >= summary["streams"][est]["count"] - len(kept[est]) > 0
    assert last.startswith("teleop record: ") and "stopped by a write error: messages.bin (" in last
    assert _data_rows(run / "slave.csv") > len(kept[est])       # the slave's loop and recording went on
    wait_for(lambda: (run / "slave_stats.json").is_file(), 5, "the slave's stats")
