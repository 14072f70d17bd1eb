"""Two terminals: `teleop master` and `teleop slave` started bare (no --listen/--connect), master first.

The master gets the configured port, the slave finds it taken and connects; both write one run
directory. Deadlines only bound waits.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from teleop.session.transport import accepts_connections, free_tcp_port
from tests.integration.processes import wait_for, write_bare_config

pytestmark = pytest.mark.integration



def test_bare_master_then_bare_slave_find_each_other_and_share_one_run(tmp_path):
    runs = tmp_path / "runs"
    cfg = tmp_path / "c.yaml"
    port = free_tcp_port()
    write_bare_config(cfg, "itbare", runs, port)
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    cmd = [sys.executable, "-m", "live.cli"]
    with open(tmp_path / "master.log", "w") as mlog, open(tmp_path / "slave.log", "w") as slog:
        master = subprocess.Popen(cmd + ["master", "--config", str(cfg), "--protocol", "short", "--max-duration", "60"],
                                  stdout=mlog, stderr=subprocess.STDOUT, env=env)
        # the master is first (a person opening two terminals): the slave starts once the port is taken
        wait_for(lambda: accepts_connections(port) or master.poll() is not None, 60, "the master to listen")
        slave = subprocess.Popen(cmd + ["slave", "--config", str(cfg), "--exit-on-master-stop", "--max-duration", "60"],
                                 stdout=slog, stderr=subprocess.STDOUT, env=env)
        try:
            assert master.wait(80) == 0, (tmp_path / "master.log").read_text()[-3000:]
            assert slave.wait(20) == 0, (tmp_path / "slave.log").read_text()[-3000:]
        finally:
            for p in (master, slave):
                if p.poll() is None:
                    p.kill()
                    p.wait()
    assert "in use: connecting to it" in (tmp_path / "slave.log").read_text()
    dirs = [p for p in runs.glob("*") if p.is_dir()]
    assert len(dirs) == 1, dirs
    stats = json.loads((dirs[0] / "master_stats.json").read_text())
    assert stats["finished"] and stats["latency_rtt"]["n"] > 100
    assert (dirs[0] / "slave.csv").is_file() and (dirs[0] / "master.csv").is_file()
