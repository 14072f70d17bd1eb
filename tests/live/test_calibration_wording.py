"""The messages that announce and report a calibration name the routine of the instrument's kind: a tendon
is pulled into its joint limit, a spindle is stroked over its jaw (it has a stroke, no joint limit, no knee)."""
from __future__ import annotations

from pathlib import Path

from live.calibrate import calibration_report
from slave.kinds import axis_kind
from slave.rigs import RIG_TYPES
from teleop.config.load import load_config

CONFIGS = Path(__file__).resolve().parents[2] / "configs"


def test_each_kind_announces_its_own_routine() -> None:
    texts = {name: axis_kind(load_config(CONFIGS / name)).routine_text
             for name in ("sim.yaml", "instrument-3dof.yaml", "instrument-spindle.yaml")}
    assert "joint limit" in texts["sim.yaml"] and "both directions" in texts["instrument-3dof.yaml"]
    assert texts["instrument-spindle.yaml"] == "every spindle stroked over the open side of its jaw and back"


def test_the_spindle_report_has_no_knee(tmp_path, monkeypatch, capsys) -> None:
    from live.cli import main
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path))
    assert main(["calibrate", "--config", str(CONFIGS / "instrument-spindle.yaml")]) == 0
    out = capsys.readouterr().out
    assert "joint limit" not in out and "spindle stroke over the open jaw" in out
    from slave.calibration_file import calibration_path, load_calibration
    cfg = load_config(CONFIGS / "instrument-spindle.yaml")
    rows = calibration_report(load_calibration(calibration_path(cfg), cfg), RIG_TYPES["simulated"](cfg, None))
    jaw = [line.split() for line in rows.splitlines() if line.startswith("jaw")]
    assert [r[4:6] for r in jaw] == [["-", "-"], ["-", "-"]]
