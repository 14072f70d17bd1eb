"""The spindle-driven jaw: its simulator, the online spindle pair model, the stroke calibration and the axis."""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from estimator.errors import CalibrationError
from estimator.online.spindle import SpindleParams
from estimator.online.spindle_estimator import SpindleEstimator
from estimator.phase import Phase
from slave.calibration_file import load_calibration, save_calibration
from slave.kinds import axis_kind
from slave.rig import RigInputError
from slave.rigs import make_rig
from slave.spindle_axis import SpindleAxis
from slave.spindle_calibrate import SpindleCalibration, band_to_K, pull_slip_M_e
from slave.spindle_rig import SpindleInstrument
from teleop.config.load import load_config
from teleop.errors import ConfigError

CONFIG = Path(__file__).resolve().parents[2] / "configs" / "instrument-spindle.yaml"
DT = 1e-3


@pytest.fixture(scope="module")
def cfg():
    return load_config(CONFIG)


def calibrate(cfg, rig):
    routine = SpindleCalibration(cfg, rig)
    st = rig.state
    for _ in range(20000):
        if routine.done:
            break
        st = rig.step(routine.command(st, DT), DT)
    assert routine.done
    return routine, st


def test_config_selects_the_spindle_axis_and_rig(cfg):
    assert axis_kind(cfg) is SpindleAxis
    assert isinstance(make_rig(cfg), SpindleInstrument)


def test_rig_turns_the_spindle_and_reads_its_torque_from_the_cables(cfg):
    rig = SpindleInstrument.from_config(cfg)
    j = cfg.instrument.joints[0]
    for k in range(400):
        st = rig.step([0.2 * min(1.0, k / 200)], DT)
    assert st.x_in.shape == (1,) and st.T_in.shape == (1,)
    assert abs(st.x_in[0] - 0.2) < 2 * rig.angle_resolution          # the drive reached the command
    tr = st.truth
    torque = j.spindle_radius * (tr.T_in[0, 0] - tr.T_in[0, 1])
    assert abs(st.T_in[0] - torque) < 6 * j.spindle_radius * cfg.rig.simulated.sensors.load_cell_noise + 1e-9
    assert tr.T_in[0, 0] > j.pretension > tr.T_in[0, 1]                # cable a wound on, b paid out
    assert tr.theta[0] > 0.0                                             # the jaw turned toward +


def test_rig_refuses_bad_commands_and_configs(cfg):
    rig = SpindleInstrument.from_config(cfg)
    with pytest.raises(RigInputError, match="angle_cmd"):
        rig.step([math.nan], DT)
    with pytest.raises(RigInputError, match="angle_cmd"):
        rig.step([0.0, 0.0], DT)
    j = dataclasses.replace(cfg.instrument.joints[0], pretension=0.0)
    with pytest.raises(ConfigError, match=r"pretension"):
        SpindleInstrument([j], cfg.rig.simulated)
    j = dataclasses.replace(cfg.instrument.joints[0], spindle_radius=0.0)
    with pytest.raises(ConfigError, match=r"spindle_radius"):
        SpindleInstrument([j], cfg.rig.simulated)


def test_estimator_reaches_the_capstan_slip_branches():
    """A slow ramp of spindle torque up, then down: in full slip the distal tensions are the capstan
    law's, T_a,d = t_a e^-K (pull), T_b,d = t_b e^+K (release), and the reverse after the turn."""
    K, Q, rp = 0.3, 0.2, 0.005
    p = SpindleParams(rho=0.8, Q=Q, K_a=K, K_b=K, n_k=1.25)
    est = SpindleEstimator(p, rp, (2e-5, 2e-5), n_nodes=16)
    u = np.concatenate([np.linspace(0.0, 0.08, 400), np.linspace(0.08, -0.08, 800)])
    samples = [est.step(float(v), 0.001 * k, 0.001 * k) for k, v in enumerate(u)]
    for s, v, sign in ((samples[399], 0.08, 1), (samples[-1], -0.08, -1)):
        ta, tb = 0.5 * (Q + v) / rp, 0.5 * (Q - v) / rp
        want = (ta * math.exp(-sign * K), tb * math.exp(sign * K))
        assert s.T_out == pytest.approx(want, rel=1e-9)
        assert s.torque == pytest.approx(0.8 * rp * (want[0] - want[1]), rel=1e-9)
    assert samples[399].phase == (Phase.PULL, Phase.RELEASE)
    assert samples[-1].phase == (Phase.RELEASE, Phase.PULL)


def test_estimator_refuses_bad_parameters():
    with pytest.raises(ValueError, match="Q must be > 0"):
        SpindleEstimator(SpindleParams(Q=0.0), 0.005, (1e-5, 1e-5))
    with pytest.raises(ValueError, match="r_p"):
        SpindleEstimator(SpindleParams(Q=0.1), 0.0, (1e-5, 1e-5))
    with pytest.raises(ValueError, match="wrap shape"):
        SpindleEstimator(SpindleParams(Q=0.1), 0.005, (1e-5, 1e-5), n_nodes=4, shapes=(np.zeros(3), None))


def test_band_to_K_inverts_the_band_and_refuses_a_slack_cable():
    assert band_to_K(0.3 * math.tanh(0.4), 0.3) == pytest.approx(0.4)
    with pytest.raises(CalibrationError, match="slack"):
        band_to_K(0.31, 0.3)
    with pytest.raises(CalibrationError, match="no friction"):
        band_to_K(0.0, 0.3)


def test_stroke_calibration_recovers_the_cables_K_and_M_e(cfg):
    rig = SpindleInstrument.from_config(cfg)
    routine, _ = calibrate(cfg, rig)
    cal = routine.calibration()
    (name, cables), = cal.joints
    assert name == "jaw"
    for k, t in enumerate("ab"):
        assert cables[t].K == pytest.approx(rig.K[0, k], rel=0.02)
        assert cables[t].M_e == pytest.approx(rig.M_e[0, k], rel=0.01)
    assert pull_slip_M_e(cfg.instrument.joints[0], "a", 0.0) == pytest.approx(
        cfg.instrument.joints[0].tendons.a.geometry().length / cfg.instrument.joints[0].tendons.a.EA)


def track(cfg, rig, ax, st, seconds=6.0):
    """Drive the jaw through a sine of jaw angle into the grasped object both ways; (true, estimated) torque."""
    tq, est = [], []
    for k in range(int(seconds / DT)):
        target = 0.45 * math.sin(2 * math.pi * 0.25 * k * DT)
        st = rig.step(SpindleAxis.rig_command([ax.motor(False, target, st, DT)]), DT)
        a, profile = ax.observe(st)
        assert profile == () and len(a.tendons) == 2
        tq.append(float(st.truth.torque[0]))
        est.append(a.effort_hat)
    return np.array(tq), np.array(est), st


def test_axis_life_cycle_estimates_the_jaw_torque_within_5_percent_of_full_scale(cfg, tmp_path):
    """Power-up calibration, tracking; the file saved, reloaded on a fresh rig, tracking again."""
    rig = SpindleInstrument.from_config(cfg)
    axes = SpindleAxis.build(cfg, rig)
    routine, st = calibrate(cfg, rig)
    cal, data = SpindleAxis.finish_routine(axes, routine, st)
    assert data["joints"][0]["name"] == "jaw"
    tq, est, st = track(cfg, rig, axes[0], st)
    assert np.ptp(tq) > 0.02 and np.abs(est - tq).max() <= 0.05 * np.ptp(tq)
    row = SpindleAxis.csv_row(st, (0, 1, 3, 0.0, 0.0), axes)
    assert len(row) == len(SpindleAxis.recording(cfg, rig)[1])
    path = save_calibration(cal, tmp_path / "forceps.yaml")
    loaded = load_calibration(path, cfg)
    assert loaded.joints[0][1]["a"].K == pytest.approx(cal.joints[0][1]["a"].K)
    rig2 = SpindleInstrument.from_config(cfg)
    axes2 = SpindleAxis.build(cfg, rig2)
    SpindleAxis.start_loaded(axes2, loaded, rig2.state)
    tq2, est2, _ = track(cfg, rig2, axes2[0], rig2.state)
    assert np.abs(est2 - tq2).max() <= 0.05 * np.ptp(tq2)


def test_axis_checks_targets_and_relaxes_to_rest(cfg):
    rig = SpindleInstrument.from_config(cfg)
    ax = SpindleAxis.build(cfg, rig)[0]
    ax.start((0.28, 0.28), [(0.0, np.zeros(1), np.zeros(1))])
    assert ax.out_of_range(0.3) is None and "outside" in ax.out_of_range(10.0)
    assert ax.too_far(0.0, rig.state) is None and "too far" in ax.too_far(3.0, rig.state)
    ax.motor(False, 0.0, rig.state, DT)
    phi = ax.motor(False, 0.2, rig.state, DT)
    assert phi == pytest.approx(0.2 / ax.n_k)                      # bumpless: relative to the take-over
    for _ in range(5000):
        phi = ax.motor(True, None, rig.state, DT)
    assert phi == pytest.approx(ax.rest) and ax.hold is None


def test_safe_starts_from_the_measured_spindle_angle_not_the_last_target(cfg):
    rig = SpindleInstrument.from_config(cfg)
    ax = SpindleAxis.build(cfg, rig)[0]
    ax.start((0.28, 0.28), [(0.0, np.zeros(1), np.zeros(1))])
    ax.motor(False, 0.0, rig.state, DT)
    assert ax.motor(False, 0.4, rig.state, DT) == pytest.approx(0.4 / ax.n_k)   # the spindle has not moved yet
    measured = float(rig.state.x_in[0])
    step = cfg.slave.relax_speed / ax.r_p * DT
    assert abs(ax.motor(True, None, rig.state, DT) - measured) <= step + 1e-12


def test_an_instrument_mixing_spindle_and_pair_joints_is_refused(cfg):
    pair = dataclasses.replace(cfg.instrument.joints[0], name="wrist", spindle_radius=0.0)
    mixed = dataclasses.replace(cfg, instrument=dataclasses.replace(cfg.instrument,
                                                                    joints=(cfg.instrument.joints[0], pair)))
    with pytest.raises(ConfigError, match="spindle_radius"):
        axis_kind(mixed)
    zenoh = dataclasses.replace(cfg, rig=dataclasses.replace(cfg.rig, type="zenoh"))
    with pytest.raises(ConfigError, match="spindle"):
        make_rig(zenoh, session=object())
