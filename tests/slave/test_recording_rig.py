"""rig.type recording: the rig plays a recording sample by sample, refuses bad input in one line, and its live
estimate on an MRD run agrees with the offline analysis of the same run and calibration."""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from estimator.errors import CalibrationError, DataError
from estimator.online.spindle import SpindleParams
from live.demo.recording_score import play_run, score_run
from recorded.detect import check_recording, recording_format
from recorded.folders import KAIST, MRD, skip_reason
from recorded.kaist_files import default_kaist_dir, kaist_path
from recorded.mrd import MrdRun, read_mrd
from recorded.mrd_files import DEFAULT_FOLDER, mrd_folder
from slave.recording.rig import RecordedSpindle
from slave.recording.spindle import CENTRE, RecordedModel, load_model, save_model
from slave.rig import RigInputError
from slave.rigs import RIG_TYPES, make_rig
from teleop.config.load import load_config
from teleop.errors import ConfigError

ROOT = Path(__file__).resolve().parents[2]
FOLDER = mrd_folder(DEFAULT_FOLDER)
needs_mrd = pytest.mark.skipif(not FOLDER.is_dir(), reason=skip_reason(MRD, FOLDER))


def synthetic_run(n: int = 50, dt: float = 1e-3) -> MrdRun:
    t = np.arange(n) * dt
    return MrdRun(name="00", time=t, theta_p=np.sin(t), tau_p=0.01 * t, theta_d=0.9 * np.sin(t), tau_d=0.02 * t,
                  frequency_hz=0.1, load_command=0.1, source="synthetic")


def head(run: MrdRun, n: int) -> MrdRun:
    """The first ``n`` samples of ``run``."""
    return MrdRun(**{**run.__dict__,
                     **{k: getattr(run, k)[:n] for k in ("time", "theta_p", "tau_p", "theta_d", "tau_d")}})


def mrd_config(tmp_path: Path, path: str, **rec):
    base = load_config(ROOT / "configs" / "recording-mrd.yaml")
    return dataclasses.replace(base, rig=dataclasses.replace(base.rig, recording=dataclasses.replace(
        base.rig.recording, path=path, **rec)), calibration=dataclasses.replace(base.calibration, dir=str(tmp_path)))


def test_the_rig_returns_each_recorded_sample_at_its_time_and_the_distal_signals_as_truth():
    run = synthetic_run()
    rig = RecordedSpindle(run)
    assert rig.state.t == 0.0 and rig.state.x_in[0] == run.theta_p[0]
    for k in range(1, 10):
        st = rig.step([0.3], 1e-3)
        assert st.t == pytest.approx(run.time[k])
        assert st.x_in[0] == run.theta_p[k] and st.T_in[0] == run.tau_p[k]
        assert st.truth.torque[0] == run.tau_d[k] and st.truth.theta[0] == run.theta_d[k]
        assert st.x_in_cmd[0] == 0.3


def test_at_end_stop_holds_the_last_sample_and_loop_starts_over():
    run = synthetic_run(5)
    stop, loop = RecordedSpindle(run, at_end="stop"), RecordedSpindle(run, at_end="loop")
    for _ in range(7):
        a, b = stop.step([0.0], 1e-3), loop.step([0.0], 1e-3)
    assert stop.finished and a.x_in[0] == run.theta_p[-1]
    assert not loop.finished and b.x_in[0] == run.theta_p[2] and b.t > run.time[-1]


def test_rate_slave_resamples_the_recording_at_the_rig_time():
    run = synthetic_run()
    rig = RecordedSpindle(run, rate="slave")
    st = rig.step([0.0], 2.5e-3)
    assert st.t == pytest.approx(2.5e-3)
    assert st.x_in[0] == pytest.approx(np.interp(2.5e-3, run.time, run.theta_p))


def test_bad_steps_are_refused():
    rig = RecordedSpindle(synthetic_run())
    with pytest.raises(RigInputError, match="dt"):
        rig.step([0.0], 0.0)
    with pytest.raises(RigInputError, match="x_in_cmd"):
        rig.step([math.nan], 1e-3)


def test_recording_is_a_registered_rig_type():
    assert "recording" in RIG_TYPES


def test_a_missing_file_is_one_line_naming_it(tmp_path):
    cfg = mrd_config(tmp_path, str(tmp_path / "nowhere" / "00.TXT"))
    with pytest.raises(DataError, match=r"rig.recording.path: .*nowhere.*no such file"):
        make_rig(cfg)


def test_an_unreadable_format_is_one_line_naming_the_file(tmp_path):
    f = tmp_path / "run.dat"
    f.write_text("1,2,3\n4,5,6\n")
    with pytest.raises(DataError, match=r"run.dat: not a recording of a known format \(its first data rows hold 3 "
                                        r"comma-separated numbers\); tried csv .*kaist .*mrd "):
        recording_format(f)


def test_a_recording_without_the_columns_the_axis_needs_is_refused(tmp_path):
    f = tmp_path / "00.TXT"
    f.write_text("\n".join("0.001,1,2,3,4,5,6,7" for _ in range(10)) + "\n")
    cfg = mrd_config(tmp_path, str(f))
    with pytest.raises(DataError, match=r"00.TXT:1: expected 10 comma-separated numbers, got 8"):
        make_rig(cfg)


def test_a_recording_of_another_axis_than_the_instrument_is_refused(tmp_path):
    f = tmp_path / "00.TXT"
    f.write_text("0,0,0,0,0,0,0,0,0,0\n")
    single = load_config(ROOT / "configs" / "sim.yaml")
    recording = dataclasses.replace(single.rig.recording, path=str(f))
    cfg = dataclasses.replace(single, rig=dataclasses.replace(single.rig, type="recording", recording=recording))
    with pytest.raises(ConfigError, match=r"00.TXT is a MRD recording of a spindle axis; the config's instrument is "
                                          r"a single tendon axis"):
        check_recording(cfg)


def test_a_kaist_recording_on_a_spindle_instrument_is_refused(tmp_path):
    f = tmp_path / "sine_config_0.txt"
    f.write_text("0,0,0,0,5,5,0,0,\n")
    with pytest.raises(ConfigError, match=r"sine_config_0.txt is a KAIST recording of a pair axis"):
        check_recording(mrd_config(tmp_path, str(f), format="auto"))


def test_the_model_file_round_trips_and_a_missing_one_is_one_line(tmp_path):
    m = RecordedModel("pair", "pair", SpindleParams(Q=0.4, K_a=0.1), None, 0.2, "31.TXT", "t", 0.01)
    back = load_model(save_model(m, tmp_path / "m.json"))
    assert back == m
    with pytest.raises(CalibrationError, match=r"gone.json: the recorded axis's model file is missing"):
        load_model(tmp_path / "gone.json")


@needs_mrd
def test_the_live_estimate_agrees_with_the_offline_analysis_on_one_run(tmp_path):
    """The centre map fitted on run 31 (its first 8 s) with the tool's load gain (as ``teleop analyze --mrd
    --tool``), played online over the first 7 s of run 13: its RMSE is the batch model's to within 0.005 of
    full scale."""
    from recorded.mrd_calibration import run_data
    from recorded.mrd_centre import centre_one_run
    cfg = mrd_config(tmp_path, str(FOLDER / "13.TXT"))
    fs = 0.0519
    cmap, _ = centre_one_run([run_data(head(read_mrd(FOLDER / "31.TXT"), 8000))], fs, 0.9427)
    model = RecordedModel(CENTRE, "pair", SpindleParams(), cmap, 0.5, str(FOLDER / "31.TXT"))
    run = head(read_mrd(FOLDER / "13.TXT"), 7000)
    s = score_run(cfg, model, run, fs, play_run(cfg, model, run))
    assert s["scored_from_s"] < 6.0
    assert s["live_rmse_fs"] < 0.1
    assert abs(s["difference_fs"]) <= 0.005


def test_a_kaist_recording_plays_as_a_tendon_pair_in_units_of_the_pulley_radius():
    from recorded.kaist import KaistRecording
    from slave.recording.pair import RecordedPair
    t = np.arange(6) * 0.025
    rec = KaistRecording(config_deg=0, time=t, command=np.linspace(0, 0.5, 6), velocity_cmd=t, angle=0.8 * t,
                         T_a=5 + t, T_b=5 - t, motor_a=t, motor_b=t, source="synthetic")
    rig = RecordedPair(rec, G=2.0)
    st = rig.step(np.zeros((1, 2)), 0.025)
    assert st.t == pytest.approx(t[1])
    assert (st.x_in[0, 0] == pytest.approx(2.0 * rec.command[1])
            and st.x_in[0, 1] == pytest.approx(-2.0 * rec.command[1]))
    assert st.T_in[0, 1] == rec.T_b[1] and st.truth.theta[0] == rec.angle[1]


KAIST_FILE = kaist_path(default_kaist_dir(), 0)


@pytest.mark.skipif(not KAIST_FILE.is_file(), reason=skip_reason(KAIST, KAIST_FILE))
def test_the_pair_axis_estimate_on_kaist_is_the_batch_joint_model_and_near_the_offline_seed_model():
    from recorded.kaist import read_kaist
    from slave.recording.pair import kaist_live
    r = kaist_live(read_kaist(KAIST_FILE), extended_deg=1.0)
    assert r["live_rmse_deg"] == pytest.approx(r["live_batch_rmse_deg"], abs=1e-6)
    assert abs(r["live_rmse_deg"] - r["seed_offline_rmse_deg"]) < 0.5
    assert r["left_out_cost_deg"] == pytest.approx(r["live_rmse_deg"] - 1.0)


def test_a_tendon_csv_without_a_distal_channel_is_refused_naming_the_file(tmp_path):
    f = tmp_path / "bench.csv"
    f.write_text("time,x_in,T_in\n0,0,0\n0.001,0,0\n")
    base = load_config(ROOT / "configs" / "sim.yaml")
    cfg = dataclasses.replace(base, rig=dataclasses.replace(base.rig, type="recording", recording=dataclasses.replace(
        base.rig.recording, path=str(f))))
    with pytest.raises(DataError, match=r"bench.csv: .*T_out"):
        make_rig(cfg)


def synthetic_kaist(path: Path) -> Path:
    """A KAIST-style file of two command cycles (40 Hz, 8 columns): a sine command [deg], tensions that rise with
    it on tendon a and fall on b, an angle that follows with hysteresis."""
    t = np.arange(0, 12.0, 0.025)
    c = 60.0 * np.sin(2 * np.pi * t / 6.0)
    ta, tb = 5.0 + 0.05 * c, 5.0 - 0.04 * c
    ang = 0.9 * c - 4.0 * np.sign(np.cos(2 * np.pi * t / 6.0))
    rows = [f"{a:.4f},{b:.4f},0,{d:.4f},{e:.4f},{f:.4f},0,0," for a, b, d, e, f in zip(t, c, ang, ta, tb, strict=False)]
    path.write_text("\n".join(rows) + "\n")
    return path


def pair_node(cfg, calibration=None, calibration_file=None):
    from slave.node import SlaveNode
    from slave.node_base import SlaveLinks
    from teleop.timing.clock import FakeClock
    from tests.fakes import Topic
    clock = FakeClock(10.0)
    rig = make_rig(cfg)
    links = SlaveLinks(*(Topic(clock) for _ in range(4)))
    return SlaveNode(cfg, rig, links, calibration=calibration, calibration_file=calibration_file), clock


def test_the_pair_axis_calibrates_on_the_recording_saves_it_and_the_reload_gives_the_same_estimates(tmp_path):
    from slave.calibration_file import calibration_path, load_calibration
    f = synthetic_kaist(tmp_path / "sine_config_0.txt")
    base = load_config(ROOT / "configs" / "recording-kaist.yaml")
    cfg = dataclasses.replace(base, rig=dataclasses.replace(base.rig, recording=dataclasses.replace(
        base.rig.recording, path=str(f), rate="recording")), calibration=dataclasses.replace(base.calibration,
                                                                                        dir=str(tmp_path / "cal")))
    path = calibration_path(cfg)
    first, clock = pair_node(cfg, calibration_file=path)
    angles = []
    for _ in range(40):
        clock.advance(0.001)
        first.step(clock.now())
        angles.append(first.axes[0].sample.angle)
    assert first.calibrated and path.is_file() and path.with_suffix(".recording.json").is_file()
    again, clock = pair_node(cfg, calibration=load_calibration(path, cfg), calibration_file=path)
    for k in range(1, 40):
        clock.advance(0.001)
        again.step(clock.now())
        assert again.axes[0].sample.angle == pytest.approx(angles[k], abs=1e-9)
    path.with_suffix(".recording.json").unlink()
    with pytest.raises(CalibrationError, match=r"recording.json: the recorded axis's model file is missing"):
        pair_node(cfg, calibration=load_calibration(path, cfg), calibration_file=path)


@pytest.mark.parametrize("case", ["missing", "columns", "axis"])
def test_the_demo_refuses_a_bad_recording_in_one_line_before_any_process_starts(tmp_path, capsys, monkeypatch, case):
    from live.cli import main
    monkeypatch.chdir(tmp_path)
    if case == "missing":
        args, words = ["--recording", str(tmp_path / "00.TXT")], "no such file"
    elif case == "columns":                      # named like an MRD run, 8 numbers a row: a KAIST recording
        f = tmp_path / "00.TXT"
        f.write_text("0,1,2,3,4,5,6,7\n")
        args, words = ["--config", str(ROOT / "configs" / "recording-mrd.yaml"), "--recording", str(f)], \
            "00.TXT is a KAIST recording of a pair axis; the config's instrument is a spindle axis"
    else:
        f = synthetic_kaist(tmp_path / "sine_config_0.txt")
        args, words = ["--config", str(ROOT / "configs" / "recording-mrd.yaml"), "--recording", str(f)], \
            "is a KAIST recording of a pair axis; the config's instrument is a spindle axis"
    rc = main(["demo", *args])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc != 0
    assert len(err) == 1 and words in err[0], err
    assert not (tmp_path / "runs").exists()


def synthetic_tendon_csv(path: Path) -> Path:
    """A measured-data CSV of a tendon pulled and released twice (2 s at 150 Hz): the distal tension a capstan
    band below (pull) or above (release) the proximal one."""
    from estimator.data import MeasuredData
    from teleop.recording.measured import write_measured_csv
    t = np.arange(1, 301) / 150.0
    x = 0.002 * (1 - np.cos(2 * np.pi * t))
    T_in = 2000.0 * x
    T_out = T_in * np.where(np.sin(2 * np.pi * t) >= 0, 0.7, 1.2)
    write_measured_csv(path, MeasuredData(time=t, x_in=x, T_in=T_in, x_out=x - 1e-4 * T_in, T_out=T_out))
    return path


def test_a_tendon_csv_plays_on_the_single_tendon_axis_and_its_calibration_reloads(tmp_path):
    from slave.calibration_file import calibration_path, load_calibration
    f = synthetic_tendon_csv(tmp_path / "bench.csv")
    base = load_config(ROOT / "configs" / "sim.yaml")
    cfg = dataclasses.replace(base, rig=dataclasses.replace(base.rig, type="recording", recording=dataclasses.replace(
        base.rig.recording, path=str(f))), calibration=dataclasses.replace(base.calibration, dir=str(tmp_path / "cal")))
    path = calibration_path(cfg)
    first, clock = pair_node(cfg, calibration_file=path)
    est = []
    for _ in range(30):
        clock.advance(0.002)
        first.step(clock.now())
        est.append(first.axes[0].sample.T_out)
    assert first.rig.state.t == pytest.approx(30 / 150.0)     # the calibration cycle, then 29 recorded samples
    assert first.rig.state.T_in == pytest.approx(2000.0 * 0.002 * (1 - np.cos(2 * np.pi * 30 / 150.0)))
    assert first.rig.state.truth.T_out > 0
    again, clock = pair_node(cfg, calibration=load_calibration(path, cfg), calibration_file=path)
    for k in range(1, 30):
        clock.advance(0.002)
        again.step(clock.now())
        assert again.axes[0].sample.T_out == pytest.approx(est[k], abs=1e-9)


def test_at_end_loop_is_refused_on_a_recording_that_plays_once(tmp_path):
    f = synthetic_kaist(tmp_path / "sine_config_0.txt")
    base = load_config(ROOT / "configs" / "recording-kaist.yaml")
    cfg = dataclasses.replace(base, rig=dataclasses.replace(base.rig, recording=dataclasses.replace(
        base.rig.recording, path=str(f), at_end="loop")))
    with pytest.raises(ConfigError, match=r"rig.recording.at_end: loop replays MRD runs; a KAIST recording plays once"):
        check_recording(cfg)
