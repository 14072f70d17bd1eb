"""``teleop calibrate --diagnose``: the single tendon calibrated, excited through the slave's checks, diagnosed, its
model file written; refusals in one line; the instrument left SAFE and the recording closed on every exit path."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import live.excitation as excitation
from live.cli import main
from live.excitation import SPEED_FRACTION, ExcitationMotion, Loopback, leave_safe, run_excitation
from slave.bench import SimulatedBench
from slave.node import SlaveNode
from slave.node_base import SlaveLinks
from slave.simulated import SimulatedRig
from teleop.config.model_file import load_model
from teleop.config.schema import Config
from teleop.recording.measured_csv import read_measured_csv
from teleop.timing.clock import FakeClock
from teleop.wire.messages import SideState

CONFIGS = Path(__file__).resolve().parents[2] / "configs"
#: a clear hidden effect: friction growing with sliding speed, twice the default
VISCOUS = 30.0


def hidden(tmp_path: Path, extra: str = "") -> Path:
    cfg = tmp_path / "bench.yaml"
    cfg.write_text(f"""instrument:
  id: bench1
rig:
  type: simulated
  simulated:
    effects:
      velocity_friction:
        enabled: true
        viscous: {VISCOUS}
calibration:
  dir: {tmp_path / 'cal'}
{extra}""")
    return cfg


def one_error_line(capsys) -> str:
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("teleop: error: ") and "Traceback" not in err, err
    return lines[0]


@pytest.mark.parametrize("shipped", ["instrument-3dof.yaml", "instrument-spindle.yaml"])
def test_another_instrument_is_refused_in_one_line_naming_the_single_tendon(shipped, capsys):
    assert main(["calibrate", "--diagnose", "--config", str(CONFIGS / shipped)]) == 2
    line = one_error_line(capsys)
    assert shipped in line and "supports the single tendon" in line


def test_a_recording_rig_a_bad_duration_and_diagnose_flags_alone_are_refused(tmp_path, capsys):
    cfg = hidden(tmp_path)
    rec = tmp_path / "rec.yaml"
    rec.write_text(cfg.read_text().replace("type: simulated", "type: recording"))
    assert main(["calibrate", "--diagnose", "--config", str(rec)]) == 2
    assert "rig.type recording" in one_error_line(capsys)
    assert main(["calibrate", "--diagnose", "--config", str(cfg), "--duration", "3"]) == 2
    assert "--duration 3.0" in one_error_line(capsys)
    assert main(["calibrate", "--config", str(cfg), "--model-out", str(tmp_path / "m.yaml")]) == 2
    assert "--model-out: for --diagnose" in one_error_line(capsys)
    assert not (tmp_path / "cal").exists()          # nothing moved, nothing written


def test_diagnose_names_the_hidden_effect_and_writes_the_model_the_slave_runs(tmp_path, capsys):
    cfg = hidden(tmp_path)
    assert main(["calibrate", "--diagnose", "--config", str(cfg), "--duration", "20"]) == 0
    out = capsys.readouterr().out
    cal, model, csv = (tmp_path / "cal" / n for n in ("bench1.yaml", "bench1.model.yaml", "bench1.excitation.csv"))
    assert cal.is_file() and f"wrote {cal}" in out
    assert "cause: velocity_friction" in out
    mf = load_model(model)
    assert [e.id for e in mf.extensions] == ["velocity_friction"] and mf.instrument == "bench1"
    c_v = dict(mf.extensions[0].values())["c_v"]
    assert abs(c_v / VISCOUS - 1.0) < 0.25, c_v
    assert mf.gain["extended"] < 0.5 * mf.gain["base"]
    assert mf.provenance["recording"] == csv.name
    assert f"teleop slave --config {cfg} --model {model}" in out
    # what a bench gives: the proximal readings and the bench's distal sensors, nothing else of the simulator
    data = read_measured_csv(csv)
    assert set(data.columns()) == {"time", "x_in", "T_in", "x_out", "T_out"} and data.extra == {}
    assert "bench" in data.metadata["distal"]


def _node(cfg: Config, clock: FakeClock) -> SlaveNode:
    rig = SimulatedRig.from_config(cfg)
    links = SlaveLinks(estimate=Loopback(clock), heartbeat=Loopback(clock), command=Loopback(clock),
                       master_heartbeat=Loopback(clock))
    return SlaveNode(cfg, rig, links)


def _tick(clock: FakeClock, dt: float):
    return lambda: clock.advance(dt)


def _calibrated(cfg: Config):
    clock = FakeClock()
    node = _node(cfg, clock)
    tick = _tick(clock, 1.0 / cfg.rig.rate_hz)
    while node.state == SideState.CALIBRATING:
        node.step(tick())
    return node, tick


def test_the_excitation_stays_within_the_slaves_limits_and_nothing_is_refused():
    cfg = Config()
    node, tick = _calibrated(cfg)
    motion = ExcitationMotion(cfg, float(node.rig_state.x_in), 12.0, seed=1)
    states = []
    run_excitation(node, motion, tick, states.append)
    x_cmd = np.array([s.x_in_cmd for s in states])
    T_in = np.array([s.T_in for s in states])
    s = cfg.slave
    assert motion.stage == "done" and len(states) >= 11_000
    assert np.max(np.abs(np.diff(x_cmd))) <= SPEED_FRACTION * s.max_speed / cfg.rig.rate_hz + 1e-12
    assert s.x_in_min < x_cmd.min() and x_cmd.max() < s.x_in_max
    assert T_in.max() < 0.6 * s.max_tension and T_in.max() > 0.8 * excitation.top_tension(cfg)
    c = node.counts
    assert c["commands_step_refused"] == c["commands_rejected_range"] == c["commands_speed_limited"] == 0
    assert c["tension_trips"] == 0 and node.state == SideState.ENGAGED
    leave_safe(node, tick, 10.0)
    assert node.state == SideState.SAFE and node.rig_state.T_in <= node.axes[0].relax_to


def test_a_tension_trip_stops_the_excitation_with_the_slaves_reason(tmp_path, capsys, monkeypatch):
    # an excitation asked to pull past slave.max_tension: the slave's limit trips, the command says why
    monkeypatch.setattr(excitation, "top_tension", lambda cfg: 1.5 * cfg.slave.max_tension)
    cfg = hidden(tmp_path, "slave:\n  max_tension: 25.0\n")
    assert main(["calibrate", "--diagnose", "--config", str(cfg), "--duration", "10"]) == 2
    line = one_error_line(capsys)
    assert "excitation stopped" in line and "beyond slave.max_tension 25" in line
    assert not (tmp_path / "cal" / "bench1.model.yaml").exists()


def test_ctrl_c_leaves_the_instrument_safe_and_the_recording_closed(tmp_path, capsys, monkeypatch):
    seen: dict = {}
    real_run, real_leave = excitation.run_excitation, excitation.leave_safe

    def interrupted(node, motion, tick, row):
        def row_then_stop(state):
            row(state)
            if motion.t > 3.0:
                raise KeyboardInterrupt
        return real_run(node, motion, tick, row_then_stop)

    def leave(node, tick, limit_s):
        real_leave(node, tick, limit_s)
        seen.update(state=node.state, T_in=float(node.rig_state.T_in), relax_to=node.axes[0].relax_to)

    monkeypatch.setattr(excitation, "run_excitation", interrupted)
    monkeypatch.setattr(excitation, "leave_safe", leave)
    cfg = hidden(tmp_path)
    assert main(["calibrate", "--diagnose", "--config", str(cfg), "--duration", "20"]) == 130
    assert seen["state"] == SideState.SAFE and seen["T_in"] <= seen["relax_to"]
    data = read_measured_csv(tmp_path / "cal" / "bench1.excitation.csv")     # closed at a row boundary
    assert 2.5 < data.time[-1] < 3.5
    assert not (tmp_path / "cal" / "bench1.model.yaml").exists()


def test_the_simulated_bench_reads_the_tip_through_its_sensors_only():
    rig = SimulatedRig.from_config(Config())
    for k in range(300):
        st = rig.step(2e-5 * k, 1e-3)
    bench = SimulatedBench(0)
    reads = np.array([bench.read(st) for _ in range(400)])
    assert 0.02 < np.std(reads[:, 0]) < 0.04                              # a load cell's noise
    assert np.allclose(reads[:, 1] / 1e-6, np.round(reads[:, 1] / 1e-6))  # a position sensor's resolution
    assert abs(np.mean(reads[:, 0]) - st.truth.T_out) < 0.01
