"""Slave + ``teleop bridge`` + master as three OS processes over Zenoh on 127.0.0.1 (``rig.type: zenoh``):
the paper protocol completes with the in-process demo's error bounds.

Deadlines only bound how long the test waits; nothing passes or fails on how fast it happened."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from live.demo.main import PAPER_BOUNDS

pytestmark = pytest.mark.integration
SIM = Path(__file__).resolve().parents[2] / "configs" / "sim.yaml"


def test_slave_bridge_and_master_as_three_processes_complete_the_paper_protocol(tmp_path):
    text = SIM.read_text()
    assert "  type: simulated" in text and "  id: sim0" in text and "  rerun: save" in text
    cfg = tmp_path / "zenoh_rig.yaml"
    cfg.write_text(text.replace("  type: simulated  ", "  type: zenoh      ", 1).replace("  id: sim0", "  id: itbridge")
                   .replace("  rerun: save", '  rerun: "off"'))
    run_dir = tmp_path / "run"
    proc = subprocess.run([sys.executable, "-m", "live.cli", "demo", "--config", str(cfg), "--run-dir", str(run_dir),
                           "--protocol", "paper", "--timeout", "60"], capture_output=True, text=True, timeout=120)
    logs = {n: (run_dir / f"{n}.log").read_text() for n in ("slave", "master", "bridge")}
    assert all("Traceback" not in v for v in logs.values()), logs
    assert "bridge: simulated rig of itbridge" in logs["bridge"]             # the third process served the rig
    summary = json.loads((run_dir / "summary.json").read_text())
    failed = [name for name, ok in summary["checks"].items() if not ok]
    operator = [line for line in logs["master"].splitlines() if "operator" in line]
    assert summary["problems"] == [] and summary["ok"] and proc.returncode == 0, (
        summary["problems"], failed, summary.get("experiments"), operator, proc.stdout[-2000:])
    head = (run_dir / "slave.csv").read_text(encoding="utf-8").split("\n", 12)
    assert any(line.startswith("# rig: zenoh") for line in head)
    p = summary["experiments"]["paper"]["profile_memory"]
    assert p["force_error_max_fs"] <= PAPER_BOUNDS["force_error_max_fs"]
    assert p["elongation_error_max_fs"] <= PAPER_BOUNDS["elongation_error_max_fs"]
    assert abs(summary["calibration"]["K_error_rel"]) < 0.05 and summary["master"]["finished"]
