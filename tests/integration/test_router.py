"""Router deployment: `teleop router` + slave + master + recorder as four processes on 127.0.0.1.

The three clients differ from the loopback default by their config only (``transport: {mode: client,
connect: [router], listen: []}``), as they would on three machines. Every message goes through the
router. Deadlines only bound waits.
"""
from __future__ import annotations

import json
import signal
import subprocess

import pytest

from teleop.recording.publish_log import read_publish_log
from teleop.session.transport import free_tcp_port
from tests.integration.processes import co_located, stalled_past_watchdog, start, stop_all, wait_text

pytestmark = pytest.mark.integration

CLIENT = """\
instrument:
  id: itrouter
calibration:
  speed: 0.02
  dir: "{runs}-calibration"
recording:
  rerun: "off"
  dir: "{runs}"
transport:
  mode: client
  listen: []
  connect: ["tcp/127.0.0.1:{port}"]
  run_id_timeout: 1.5
"""


def test_router_slave_master_recorder_as_four_processes(tmp_path):
    port = free_tcp_port()
    runs = tmp_path / "runs"
    cfg = tmp_path / "client.yaml"
    cfg.write_text(co_located(CLIENT.format(runs=runs, port=port)), encoding="utf-8")
    procs: list[subprocess.Popen] = []
    try:
        procs.append(start(["router", "--config", str(cfg), "--listen", f"tcp/127.0.0.1:{port}",
                            "--max-duration", "90"],
                           tmp_path / "router.log"))
        wait_text(tmp_path / "router.log", "(ready)", 20)
        recorder = start(["record", "--config", str(cfg), "--exit-when-done", "--max-duration", "90"],
                         tmp_path / "record.log")
        procs.append(recorder)
        wait_text(tmp_path / "record.log", "(ready)", 20)
        slave = start(["slave", "--config", str(cfg), "--exit-on-master-stop", "--max-duration", "60"],
                      tmp_path / "slave.log", {"TELEOP_PUBLISH_LOG": str(tmp_path / "slave.pub")})
        procs.append(slave)
        master = start(["master", "--config", str(cfg), "--protocol", "short", "--max-duration", "60"],
                       tmp_path / "master.log", {"TELEOP_PUBLISH_LOG": str(tmp_path / "master.pub")})
        procs.append(master)
        assert master.wait(80) == 0, (tmp_path / "master.log").read_text()[-3000:]
        assert slave.wait(20) == 0, (tmp_path / "slave.log").read_text()[-3000:]
        assert recorder.wait(20) == 0, (tmp_path / "record.log").read_text()[-3000:]
        procs[0].send_signal(signal.SIGINT)
        assert procs[0].wait(20) == 130
    finally:
        stop_all(procs)
    dirs = [p for p in runs.glob("*") if p.is_dir()]
    assert len(dirs) == 1, f"one shared run directory expected, got {dirs}"
    run = dirs[0]
    master_stats = json.loads((run / "master_stats.json").read_text())
    slave_stats = json.loads((run / "slave_stats.json").read_text())
    assert master_stats["finished"] and master_stats["latency_rtt"]["n"] > 100
    # no SAFE event, unless the virtual machine was stopped longer than the watchdog (CPU steal of a few hundred
    # ms gives one "command stale" right after engaging, then the sides re-engage)
    assert slave_stats["commands_applied"] > 100
    assert slave_stats["safe_events"] == 0 or stalled_past_watchdog([slave_stats, master_stats]), \
        (slave_stats["safe_events"], slave_stats["pacer"], master_stats["pacer"])
    summary = json.loads((run / "recorder" / "summary.json").read_text())
    for side in ("slave", "master"):
        for key, seqs in read_publish_log(tmp_path / f"{side}.pub").items():
            s = summary["streams"][key]
            assert s["count"] == len(seqs) and s["missing"] == 0, (key, s, len(seqs))
    assert summary["command_to_echo_at_recorder"]["n"] > 100
