"""A second side of the same role, started bare by mistake, is refused in one line naming the run and the
process already playing it (exit status 2, no traceback); the first side goes on. Loopback only."""
from __future__ import annotations

import os
import subprocess
import sys

import pytest

from teleop.session.transport import free_tcp_port
from tests.integration.processes import stop_all, wait_for, write_bare_config

pytestmark = pytest.mark.integration



@pytest.mark.parametrize("role", ["slave", "master"])
def test_a_second_side_of_the_same_role_is_refused_naming_the_run_and_the_first(tmp_path, role):
    runs = tmp_path / "runs"
    cfg = tmp_path / "c.yaml"
    write_bare_config(cfg, "itsecond", runs, free_tcp_port())
    env = dict(os.environ, PYTHONUNBUFFERED="1", XDG_DATA_HOME=str(tmp_path / "data"))
    cmd = [sys.executable, "-m", "live.cli", role, "--config", str(cfg), "--max-duration", "120"]
    with open(tmp_path / "first.log", "w") as log:
        first = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=env)
    try:
        # the run directory exists once the first side has claimed its role
        wait_for(lambda: any(runs.glob("*")) or first.poll() is not None, 90, f"the first {role}'s run directory")
        assert first.poll() is None, (tmp_path / "first.log").read_text()[-2000:]
        (run,) = [p.name for p in runs.iterdir()]
        second = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=120)
        assert first.poll() is None                      # the first side is not disturbed
    finally:
        stop_all([first])
    assert second.returncode == 2, second.stderr[-2000:]
    assert "Traceback" not in second.stderr
    errors = [line for line in second.stderr.splitlines() if "error" in line.lower()]
    assert errors == [f"teleop: error: run {run} already has a {role} of instrument 'itsecond': process {first.pid} "
                      f"on {os.uname().nodename} (run {run}); stop it first, or give this {role} another "
                      f"instrument.id or endpoint"]
