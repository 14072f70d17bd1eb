"""The spindle-driven forceps jaw as two OS processes over Zenoh on 127.0.0.1 (``teleop demo --config
configs/instrument-spindle.yaml``): calibration from the spindle alone, saved and reloaded, the jaw's
torque and angle estimated live and scored against the simulator's truth.

Deadlines only bound how long a test waits; nothing passes or fails on how fast it happened."""
from __future__ import annotations

from pathlib import Path

import pytest

from tests.integration.processes import quiet_instrument, run_demo

CONFIG = Path(__file__).resolve().parents[2] / "configs" / "instrument-spindle.yaml"


@pytest.mark.integration
def test_spindle_demo_end_to_end_over_zenoh(tmp_path):
    cfg = quiet_instrument(CONFIG, tmp_path, "forceps1", "itspindle", "forceps.yaml")
    run_dir = tmp_path / "run"
    proc, summary = run_demo(cfg, run_dir)
    assert summary["slave"]["drive"] == "spindle" and summary["axes"] == ["jaw"]
    jaw = summary["joints"]["jaw"]
    assert jaw["torque_error_max_fs"] <= 0.05 and set(jaw) >= {"a", "b"}
    assert jaw["a"]["torque_full_scale_Nm"] > 0.01 and jaw["b"]["torque_full_scale_Nm"] > 0.01   # the object grasped
    assert abs(summary["calibration"]["jaw"]["a"]["K_error_rel"]) <= 0.05
    assert "jaw        worst" in proc.stdout and "slave  loop:" in proc.stdout
    assert summary["master"]["finished"] and summary["slave"]["commands_applied"] > 1000
    rows = [ln for ln in (run_dir / "master.csv").read_text().splitlines() if not ln.startswith("#")]
    assert "jaw.force" in rows[0].split(",") and len(rows) > 1000      # the master rendered the jaw, a row per cycle
