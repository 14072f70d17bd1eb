"""`teleop record` that hears nothing exits non-zero with one line saying so and why."""
from __future__ import annotations

import subprocess
import sys

from live.record.beside_demo import nothing_received_reason
from teleop.session.transport import free_tcp_port, loopback_endpoint


def test_a_recorder_that_received_nothing_exits_1_with_one_line(tmp_path):
    cfg = tmp_path / "c.yaml"
    cfg.write_text(f"instrument: {{id: recnone}}\nrecording: {{rerun: 'off', dir: '{tmp_path / 'runs'}'}}\n",
                   encoding="utf-8")
    r = subprocess.run([sys.executable, "-m", "live.cli", "record", "--config", str(cfg), "--listen",
                        loopback_endpoint(free_tcp_port()), "--max-duration", "0.5"],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 1, r.stderr
    lines = [line for line in r.stderr.splitlines() if line.startswith("teleop record:")]
    assert len(lines) == 1 and lines[0].startswith("teleop record: nothing received: no side of instrument "
                                                   "'recnone' appeared (no liveliness token)")
    assert "Traceback" not in r.stderr


def test_the_reason_names_the_sides_that_appeared_but_sent_nothing():
    assert nothing_received_reason("x", {"slave"}).startswith("slave appeared but published nothing on teleop/x/")
