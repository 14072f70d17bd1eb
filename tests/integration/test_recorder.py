"""`teleop record` loses nothing: recorder, slave and master as three processes, one of them SIGKILLed.

The three are started bare (no --listen/--connect) on a config whose listen port is a free one: the
recorder gets the port, the sides find it taken and connect, and all three agree one run id. Each
side logs every message it publishes (TELEOP_PUBLISH_LOG, teleop/recording/publish_log.py: a line with the
payload's CRC before the put, one after it returns, written straight to the OS, so the kill loses
none of its lines); the test compares those with what the recorder wrote, strictly: every message
whose put returned is recorded, every recorded message was published with that very payload, none
twice. The recorder gets what the kill caught in the side's zenoh queue from the side's journal
(teleop/recording/journal.py); the oracle never reads the journal. The MCAP file (live/record/mcap_file.py) holds the
same messages as messages.bin and the CSVs and passes `rerun mcap check`; after a SIGKILL of the recorder
itself, `teleop record --repair RUN` completes it from messages.bin and the journals, and it then holds
every message the sides published. Deadlines only bound waits.
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
import zlib
from pathlib import Path

import numpy as np
import pytest

from live.record.mcap_read import read_session
from live.record.recorder import read_messages
from teleop.recording.measured_csv import read_measured_csv
from teleop.recording.publish_log import read_publish_attempts, read_publish_log
from teleop.session.transport import free_tcp_port
from teleop.wire.codec import decode
from tests.integration.processes import co_located, start, stop_all, wait_for

pytestmark = pytest.mark.integration

CONFIG = """\
instrument:
  id: {ident}
calibration:
  speed: 0.02
  dir: "{runs}-calibration"
recording:
  rerun: "off"
  dir: "{runs}"
  csv: all
  mcap_every: 1
transport:
  listen: ["tcp/127.0.0.1:{port}"]
"""


def recorded(rec_dir: Path) -> dict[str, list[tuple[int, int]]]:
    """key -> [(seq, CRC-32 of the payload), ...] in the recorder's messages.bin."""
    out: dict[str, list[tuple[int, int]]] = {}
    for _, key, payload in read_messages(rec_dir / "messages.bin"):
        out.setdefault(key, []).append((decode(payload).seq, zlib.crc32(payload)))
    return out


def mcap_seqs(rec_dir: Path) -> dict[str, list[int]]:
    """key -> [seq, ...] of the JSON channels of the recorder's session.mcap (read whole: not torn)."""
    s = read_session(rec_dir / "session.mcap")
    assert not s.torn
    return {k: [m["seq"] for _, _, m in v] for k, v in s.messages.items()}


def rerun_check_ok(path: Path) -> None:
    """`rerun mcap check` finds no problem on any topic."""
    rerun = Path(sys.executable).parent / "rerun"
    chk = subprocess.run([str(rerun), "mcap", "check", str(path)], capture_output=True, text=True, timeout=120,
                         env=dict(os.environ, RERUN_ANALYTICS="off"))
    rows = [r for r in (ln.split() for ln in chk.stdout.splitlines()) if len(r) >= 4 and r[3].startswith("/")]
    assert chk.returncode == 0 and rows and all(r[0] == "ok" for r in rows), chk.stdout + chk.stderr


def _state_seen(rec_dir: Path, side: str, state: int) -> bool:
    path = rec_dir / "state_changes.csv"
    return path.is_file() and f",{side},{state}," in path.read_text()


@pytest.mark.parametrize("victim", ["slave", "master"])
def test_sigkill_of_a_side_loses_no_published_message(tmp_path, victim):
    ident = f"rk{victim}"
    runs = tmp_path / "runs"
    cfg = tmp_path / "c.yaml"
    cfg.write_text(co_located(CONFIG.format(ident=ident, runs=runs, port=free_tcp_port())), encoding="utf-8")
    logs = {side: tmp_path / f"{side}.pub" for side in ("slave", "master")}
    procs: dict[str, subprocess.Popen] = {}
    try:
        procs["recorder"] = start(["record", "--config", str(cfg), "--max-duration", "90"], tmp_path / "record.log")
        wait_for(lambda: "(ready)" in (tmp_path / "record.log").read_text(), 20, "the recorder to be ready")
        procs["slave"] = start(["slave", "--config", str(cfg), "--max-duration", "90"], tmp_path / "slave.log",
                               {"TELEOP_PUBLISH_LOG": str(logs["slave"])})
        procs["master"] = start(["master", "--config", str(cfg), "--protocol", "paper", "--max-duration", "90"],
                                tmp_path / "master.log", {"TELEOP_PUBLISH_LOG": str(logs["master"])})
        run_dirs = lambda: sorted(p for p in runs.glob("*") if p.is_dir())
        wait_for(lambda: len(run_dirs()) == 1 and (run_dirs()[0] / "recorder").is_dir(), 10, "the run directory")
        rec_dir = run_dirs()[0] / "recorder"
        try:
            wait_for(lambda: _state_seen(rec_dir, "slave", 3), 40, "the slave to be ENGAGED")
        except AssertionError as e:
            tails = {n: (tmp_path / f"{n}.log").read_text()[-1500:] for n in ("slave", "master", "record")}
            raise AssertionError(f"{e}; logs: {tails}") from None
        time.sleep(0.5)                                         # teleoperation under way
        procs[victim].send_signal(signal.SIGKILL)
        procs[victim].wait(10)
        survivor = "master" if victim == "slave" else "slave"
        time.sleep(0.5)                                         # the survivor goes safe, still publishing
        procs[survivor].send_signal(signal.SIGINT)              # Ctrl-C: clean exit
        assert procs[survivor].wait(20) in (0, 1, 130)
        procs["recorder"].send_signal(signal.SIGINT)
        assert procs["recorder"].wait(30) == 130
    finally:
        stop_all(procs.values())
    assert run_dirs() == [rec_dir.parent], "the three processes must share one run directory"
    assert (rec_dir.parent / "slave.csv").is_file() and (rec_dir.parent / "master.csv").is_file()
    got = recorded(rec_dir)
    summary = json.loads((rec_dir / "summary.json").read_text())
    recovered = {}
    for side, path in logs.items():
        published, begun = read_publish_log(path), read_publish_attempts(path)
        assert set(published) == {k for k in got if f"/{side}/" in k}, (side, sorted(published), sorted(got))
        for key, seqs in published.items():
            assert len(seqs) > 100 if not key.endswith("heartbeat") else len(seqs) > 10
            seqs_got = [q for q, _ in got[key]]
            lost = sorted(set(seqs) - set(seqs_got))        # put returned, not recorded: none, killed or not
            assert not lost, f"{key}: {len(lost)} of {len(seqs)} published messages not recorded: {lost[:20]}"
            invented = [(q, c) for q, c in got[key] if begun[key].get(q) != c]    # never published, or altered
            assert not invented, (key, invented[:10])
            assert len(seqs_got) == len(set(seqs_got)), key      # nothing recorded twice
            st = summary["streams"][key]
            assert st["count"] == len(seqs_got) == st["received"] + st["recovered"]
            recovered[key] = st["recovered"]
    assert sum(recovered.values()) == sum(summary["recovered_from_journals"]["recovered"].values())
    assert set(summary["recovered_from_journals"]["journals"]) == {"slave", "master"}
    print(f"\n{victim} SIGKILLed: recovered from journals {recovered}")
    assert all(s["missing"] == 0 and s["decode_errors"] == 0 for s in summary["streams"].values())
    states = [(c["side"], c["state"]) for c in summary["state_changes"]]
    assert ("slave", "ENGAGED") in states
    if victim == "master":                                      # the slave went safe: the recorder saw it
        assert states.index(("slave", "SAFE"), states.index(("slave", "ENGAGED"))) > 0
    est = read_measured_csv(rec_dir / "slave_estimate.csv")     # the measured-data format
    assert est.time.size == len(got[f"teleop/{ident}/slave/estimate"])
    assert (np.all(np.isfinite(est.T_in)) and "T_out_hat" in est.extra
            and any(c.startswith("profile") for c in est.extra))
    assert (rec_dir / "streams.png").is_file()
    in_mcap = mcap_seqs(rec_dir)                                # the MCAP file holds what the CSVs hold
    assert {k: sorted(v) for k, v in in_mcap.items()} == {k: sorted(q for q, _ in v) for k, v in got.items()}
    assert summary["mcap"]["messages"] > sum(len(v) for v in got.values())    # with the ROS 2 channels
    rerun_check_ok(rec_dir / "session.mcap")


def test_sigkill_of_the_recorder_then_repair_gives_an_mcap_file_with_every_published_message(tmp_path):
    ident = "rkrec"
    runs = tmp_path / "runs"
    cfg = tmp_path / "c.yaml"
    cfg.write_text(co_located(CONFIG.format(ident=ident, runs=runs, port=free_tcp_port())), encoding="utf-8")
    logs = {side: tmp_path / f"{side}.pub" for side in ("slave", "master")}
    procs: dict[str, subprocess.Popen] = {}
    try:
        procs["recorder"] = start(["record", "--config", str(cfg), "--max-duration", "90"], tmp_path / "record.log")
        wait_for(lambda: "(ready)" in (tmp_path / "record.log").read_text(), 20, "the recorder to be ready")
        for side in ("slave", "master"):
            extra = ["--protocol", "paper"] if side == "master" else []
            procs[side] = start([side, "--config", str(cfg), "--max-duration", "90", *extra], tmp_path / f"{side}.log",
                                {"TELEOP_PUBLISH_LOG": str(logs[side])})
        run_dirs = lambda: sorted(p for p in runs.glob("*") if p.is_dir())
        wait_for(lambda: len(run_dirs()) == 1 and (run_dirs()[0] / "recorder").is_dir(), 10, "the run directory")
        rec_dir = run_dirs()[0] / "recorder"
        wait_for(lambda: _state_seen(rec_dir, "slave", 3), 40, "the slave to be ENGAGED")
        time.sleep(1.5)                                         # more than one MCAP chunk written
        procs["recorder"].send_signal(signal.SIGKILL)
        procs["recorder"].wait(10)
        time.sleep(0.5)                                         # the sides publish on, recorded by no one
        for side in ("slave", "master"):
            procs[side].send_signal(signal.SIGINT)
            assert procs[side].wait(20) in (0, 1, 130)
    finally:
        stop_all(procs.values())
    torn = read_session(rec_dir / "session.mcap")
    assert torn.torn and torn.messages                          # readable up to its last chunk
    rep = subprocess.run([sys.executable, "-m", "live.cli", "record", "--repair", str(rec_dir.parent)],
                         capture_output=True, text=True, timeout=120)
    assert rep.returncode == 0 and "from the journals" in rep.stdout, rep.stdout + rep.stderr
    in_mcap = mcap_seqs(rec_dir)
    for path in logs.values():
        for key, seqs in read_publish_log(path).items():
            assert len(seqs) > 10
            assert sorted(in_mcap.get(key, [])) == sorted(seqs), (key, len(seqs), len(in_mcap.get(key, [])))
    bin_keys = {k for _, k, _ in read_messages(rec_dir / "messages.bin")}
    assert bin_keys <= set(in_mcap)
    rerun_check_ok(rec_dir / "session.mcap")
