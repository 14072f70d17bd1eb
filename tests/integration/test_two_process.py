"""Slave and master as two OS processes talking Zenoh on a free 127.0.0.1 port.

Deadlines below only bound how long a test waits for something to happen; nothing passes or fails
on how fast it happened.
"""
from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from slave.tendon_axis import RELAX_BAND
from teleop.config.load import load_config
from teleop.recording.measured_csv import read_measured_csv
from teleop.session.transport import Session, free_tcp_port, loopback_endpoint, zenoh_config
from teleop.wire.keys import estimate_key, heartbeat_key
from teleop.wire.messages import Estimate, Heartbeat, SideState
from tests.integration.processes import co_located, start, stop_all, wait_for

pytestmark = pytest.mark.integration

# quick calibration pull, the slave's CSV at every cycle (the kill test reads the rows around the fault);
# everything else is the simulated demo's configuration
CONFIG = """\
instrument:
  id: {ident}
calibration:
  speed: 0.02
  dir: "{caldir}"
recording:
  rerun: "{rerun}"
  csv_every: 1
"""


def write_config(tmp_path: Path, ident: str, rerun: str = "off") -> Path:
    path = tmp_path / "test.yaml"
    text = CONFIG.format(ident=ident, rerun=rerun, caldir=tmp_path / "calibration")
    path.write_text(co_located(text), encoding="utf-8")
    return path


def test_demo_runs_both_processes_and_writes_the_summary(tmp_path):
    cfg = write_config(tmp_path, "itdemo", rerun="save")
    run_dir = tmp_path / "run"
    proc = subprocess.run([sys.executable, "-m", "live.cli", "demo", "--config", str(cfg), "--protocol", "short",
                           "--run-dir", str(run_dir), "--timeout", "40"], capture_output=True, text=True, timeout=60)
    assert proc.returncode in (0, 1), proc.stderr
    assert "Traceback" not in proc.stderr + (run_dir / "slave.log").read_text() + (run_dir / "master.log").read_text()
    for name in ("slave.csv", "slave.rrd", "summary.json", "calibration.json", "config.yaml"):
        assert (run_dir / name).is_file(), name
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["problems"] == [], summary["problems"]
    assert summary["master"]["commands_sent"] > 1000 and summary["slave"]["commands_applied"] > 1000
    assert summary["master"]["finished"] and summary["master"]["latency_rtt"]["n"] > 100
    paper = summary["experiments"]["paper"]["profile_memory"]
    assert all(np.isfinite(v) for v in paper.values())
    assert "minor" not in summary["experiments"]                      # the short protocol is marker 1 only
    data = read_measured_csv(run_dir / "slave.csv")
    assert set(np.unique(data.extra["marker"])) == {0.0, 1.0}
    assert "round trip" in proc.stdout and str(run_dir / "slave.rrd") in proc.stdout
    assert summary["model"] is None and "model: none (the base estimator)" in proc.stdout     # no --model given


def test_killing_the_master_makes_the_slave_go_safe(tmp_path):
    ident = "itkill"
    cfg_path = write_config(tmp_path, ident)
    cfg = load_config(cfg_path)
    port = free_tcp_port()
    ep = loopback_endpoint(port)
    run_dir = tmp_path / "run"
    slave = start(["slave", "--config", str(cfg_path), "--listen", ep, "--run-dir", str(run_dir),
                   "--max-duration", "60"], tmp_path / "slave.log")
    master = None
    try:
        with Session(zenoh_config(cfg.transport, listen=(), connect=(ep,), role="observer")) as session:
            beats = session.subscriber(heartbeat_key(ident, "slave"), Heartbeat)
            estimates = session.subscriber(estimate_key(ident), Estimate)

            def slave_state():
                rec = beats.latest()
                return None if rec is None else rec.message.state

            master = start(["master", "--config", str(cfg_path), "--connect", ep, "--run-dir", str(run_dir),
                            "--protocol", "paper", "--max-duration", "60"], tmp_path / "master.log")
            wait_for(lambda: slave_state() == SideState.ENGAGED, 40, "the slave to be ENGAGED")
            # let the operator pull the tendon well above pretension + RELAX_BAND, so that SAFE has to release
            pulled = cfg.sheath.pretension + RELAX_BAND + 1.0
            wait_for(lambda: (rec := estimates.latest()) is not None and rec.message.tendons[0].T_in > pulled, 20,
                     f"the operator to pull the tendon above {pulled:g} N")
            master.send_signal(signal.SIGKILL)
            master.wait()
            wait_for(lambda: slave_state() == SideState.SAFE, 10, "the slave to go SAFE")
            time.sleep(0.2)                                  # some SAFE cycles in the recording
        slave.send_signal(signal.SIGINT)                     # Ctrl-C: clean exit, recordings closed
        assert slave.wait(20) == 130
    finally:
        stop_all([slave] if master is None else [slave, master])
    log = (tmp_path / "slave.log").read_text()
    assert "Traceback" not in log and "ENGAGED -> SAFE" in log
    assert "master liveliness token gone" in log or "command stale" in log
    stats = json.loads((run_dir / "slave_stats.json").read_text())
    assert stats["commands_applied"] > 100 and stats["safe_events"] == 1
    data = read_measured_csv(run_dir / "slave.csv")
    state = data.extra["state"].astype(int)
    engaged = np.flatnonzero(state == SideState.ENGAGED)
    assert engaged.size > 100
    after = slice(engaged[-1] + 1, None)
    assert np.all(state[after] == SideState.SAFE) and state[after].size > 50
    hold = data.extra["x_in_cmd"][after]
    # held the last position, then released (never pulled) at <= slave.relax_speed toward the pretension
    assert hold[0] <= data.extra["x_in_cmd"][engaged[-1]] and np.all(np.diff(hold) <= 0)
    # at <= relax_speed: the node steps on its own clock's dt, the rows carry the rig's time stamps, so the
    # bound is on the whole release (plus 5 cycles of slack), not on each row's jitter
    t = data.time[after]
    assert hold[0] - hold[-1] <= cfg.slave.relax_speed * (t[-1] - t[0] + 5e-3) and hold[0] - hold[-1] > 0
