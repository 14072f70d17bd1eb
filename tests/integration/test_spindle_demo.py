"""The spindle-driven forceps jaw as two OS processes over Zenoh on 127.0.0.1 (``teleop demo --config
configs/instrument-spindle.yaml``): calibration from the spindle alone, saved and reloaded, the jaw's
torque and angle estimated live and scored against the simulator's truth.

Deadlines only bound how long a test waits; nothing passes or fails on how fast it happened."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

CONFIG = Path(__file__).resolve().parents[2] / "configs" / "instrument-spindle.yaml"


def quiet_config(tmp_path: Path, ident: str) -> Path:
    """The forceps with its own id, no Rerun recording and the calibration file under tmp_path."""
    text = CONFIG.read_text().replace("id: forceps1", f"id: {ident}").replace("rerun: save", "rerun: off")
    text = text.replace("dir: configs/calibration", f"dir: {tmp_path / 'calibration'}")
    path = tmp_path / "forceps.yaml"
    path.write_text(text)
    return path


@pytest.mark.integration
def test_spindle_demo_end_to_end_over_zenoh(tmp_path):
    cfg = quiet_config(tmp_path, "itspindle")
    run_dir = tmp_path / "run"
    proc = subprocess.run([sys.executable, "-m", "live.cli", "demo", "--config", str(cfg), "--run-dir", str(run_dir),
                           "--timeout", "50"], capture_output=True, text=True, timeout=90)
    logs = proc.stderr + (run_dir / "slave.log").read_text() + (run_dir / "master.log").read_text()
    assert "Traceback" not in logs, logs[-3000:]
    summary = json.loads((run_dir / "summary.json").read_text())
    failed = [k for k, ok in summary["checks"].items() if not ok]
    assert summary["problems"] == [] and proc.returncode == 0, (failed, summary["problems"], summary.get("haptic_loop"),
                                                                logs[-4000:])
    assert "calibration loaded from" in (run_dir / "slave.log").read_text()       # the slave reloaded the file
    assert summary["slave"]["drive"] == "spindle" and summary["axes"] == ["jaw"]
    jaw = summary["joints"]["jaw"]
    assert jaw["torque_error_max_fs"] <= 0.05 and set(jaw) >= {"a", "b"}
    assert jaw["a"]["torque_full_scale_Nm"] > 0.01 and jaw["b"]["torque_full_scale_Nm"] > 0.01   # the object grasped
    assert abs(summary["calibration"]["jaw"]["a"]["K_error_rel"]) <= 0.05
    assert "jaw        worst" in proc.stdout and "slave  loop:" in proc.stdout
    assert summary["master"]["finished"] and summary["slave"]["commands_applied"] > 1000
    rows = [ln for ln in (run_dir / "master.csv").read_text().splitlines() if not ln.startswith("#")]
    assert "jaw.force" in rows[0].split(",") and len(rows) > 1000      # the master rendered the jaw, a row per cycle
