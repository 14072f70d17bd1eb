"""The 3-joint instrument as two OS processes over Zenoh on 127.0.0.1 (``teleop demo --config
configs/instrument-3dof.yaml``: the demo of every instrument), and ``teleop calibrate`` on the command line.

Deadlines only bound how long a test waits; nothing passes or fails on how fast it happened."""
from __future__ import annotations

from pathlib import Path

import pytest

from estimator.errors import CalibrationError
from live.cli import main
from slave.calibration_file import load_calibration
from teleop.config.load import load_config
from tests.integration.processes import quiet_instrument, run_demo

CONFIG = Path(__file__).resolve().parents[2] / "configs" / "instrument-3dof.yaml"
# why a side leaves ENGAGED when a link, not the instrument, is at fault: the master's watchdog (master/node_base.py)
# and the slave's (slave/node_base.py), whose SAFE the master then reads as "slave SAFE"
WATCHDOG_REASONS = ("estimate stale", "slave heartbeat missing", "command echo stale", "slave SAFE", "command stale")


def quiet_config(tmp_path: Path, ident: str) -> Path:
    """The 3-joint instrument with its own id, no Rerun recording and calibration files under tmp_path."""
    return quiet_instrument(CONFIG, tmp_path, "flex3", ident)


@pytest.mark.integration
def test_three_joint_demo_end_to_end_over_zenoh(tmp_path):
    cfg = quiet_config(tmp_path, "itjoints")
    run_dir = tmp_path / "run"
    proc, summary = run_demo(cfg, run_dir)
    for name in ("bend_ud", "bend_lr", "grasp"):
        j = summary["joints"][name]
        assert j["torque_error_max_fs"] <= 0.05 and set(j) >= {"a", "b"}
        # the paper's 20 N both ways (the operator stops its intention early, anticipating its hand's lag)
        assert j["a"]["T_in_max_N"] > 19.0 and j["b"]["T_in_max_N"] > 19.0
        assert abs(summary["calibration"][name]["a"]["K_error_rel"]) <= 0.05
        assert f"{name:10s} worst" in proc.stdout
    assert summary["master"]["finished"] and summary["slave"]["commands_applied"] > 1000
    assert summary["master"]["latency_rtt"]["n"] > 1000
    m = summary["master"]                                    # the joint master has the whole console
    # one engagement for the whole run; only the watchdog (a link stale while the shared machine stalls a side)
    # may end it, rarely, and then each new engagement is an alignment or the scripted hand's clutch, one per SAFE
    safe = {side: [ln for ln in (run_dir / f"{side}.log").read_text().splitlines() if "ENGAGED -> SAFE" in ln]
            for side in ("master", "slave")}
    late = {side: summary[side]["pacer"]["max_lateness"] for side in ("master", "slave")}
    assert all(ln.endswith(WATCHDOG_REASONS) for lines in safe.values() for ln in lines), safe
    n_safe = len(safe["master"])
    assert n_safe <= 2, (safe, late)
    assert 1 <= m["engage_count"] <= 1 + n_safe and "console" in m, (m["engage_count"], safe)
    assert m["clutches"] <= n_safe and m["align_refusals"] <= n_safe, (m["clutches"], m["align_refusals"], safe)
    assert m["max_abs_force"] <= m["force_limit"] and m["axes"] == ["bend_ud", "bend_lr", "grasp"]
    assert m["recording"].endswith("master.csv") and "master console: engaged" in proc.stdout
    header = [ln for ln in (run_dir / "master.csv").read_text().splitlines() if not ln.startswith("#")]
    assert "grasp.force" in header[0].split(",") and len(header) > 1000      # a row per cycle, complete


def test_calibrate_writes_the_file_the_slave_reloads(tmp_path, capsys):
    cfg_path = quiet_config(tmp_path, "itcal")
    assert main(["calibrate", "--config", str(cfg_path)]) == 0
    out = capsys.readouterr().out
    assert "bend_ud    a" in out and "grasp      b" in out and "vs sim" in out
    cal = load_calibration(tmp_path / "calibration" / "itcal.yaml", load_config(cfg_path))
    assert [n for n, _ in cal.joints] == ["bend_ud", "bend_lr", "grasp"]


def test_calibrate_a_single_tendon_writes_the_file_its_slave_reloads(tmp_path, capsys):
    """One calibration life cycle: a single tendon (a one-axis instrument) is calibrated by the same
    command into the same kind of file; a joint instrument refuses it."""
    cfg = tmp_path / "one.yaml"
    cfg.write_text(f"instrument:\n  id: one\ncalibration:\n  dir: {tmp_path / 'calibration'}\n")
    assert main(["calibrate", "--config", str(cfg)]) == 0
    out = capsys.readouterr().out
    assert "tendon" in out and "K vs sim" in out and "wrote" in out
    cal = load_calibration(tmp_path / "calibration" / "one.yaml", load_config(cfg))
    from slave.simulated import SimulatedRig
    rig = SimulatedRig.from_config(load_config(cfg))
    assert cal.tendon is not None and cal.joints == () and abs(cal.tendon.K / rig.K - 1) < 0.05
    joint_cfg = quiet_config(tmp_path, "itone")
    (tmp_path / "calibration" / "itone.yaml").write_text(
        (tmp_path / "calibration" / "one.yaml").read_text().replace("instrument: one", "instrument: itone"))
    with pytest.raises(CalibrationError, match="tendon: this is the calibration of a single-tendon instrument"):
        load_calibration(tmp_path / "calibration" / "itone.yaml", load_config(joint_cfg))


def test_slave_refuses_a_calibration_of_another_instrument(tmp_path, capsys):
    cfg_path = quiet_config(tmp_path, "itother")
    (tmp_path / "calibration").mkdir()
    (tmp_path / "calibration" / "itother.yaml").write_text(
        "instrument: flex3\ndate: 2026-01-01T00:00:00+00:00\nmethod: x\ntarget_tension: 20.0\nuse_route: true\n"
        "joints: []\n")
    assert main(["slave", "--config", str(cfg_path), "--run-dir", str(tmp_path / "run"), "--max-duration", "1"]) == 2
    err = capsys.readouterr().err
    assert "itother.yaml" in err and "another instrument" in err
