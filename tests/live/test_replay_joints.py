"""teleop replay of a joint instrument's run (live/replay/joints.py): a synthetic 3-joint run whose
recorded estimate used the run's calibration (K_CAL) and whose truth follows K_TRUE, replayed with its own
calibration (it must reproduce the recorded estimate), with the true one (it must move onto the truth) and
with bad inputs."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from estimator.online.pair import PairEstimator
from estimator.sheath import SheathModel
from live.cli import main
from slave.calibration_file import InstrumentCalibration, TendonCalibration, save_calibration
from slave.pair_axis import joint_csv_columns
from teleop.config.load import load_config, write_config

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / "configs" / "instrument-3dof.yaml"
K_TRUE, K_CAL, COMPLIANCE, N = 0.60, 0.45, 1.0e-4, 1500


def _calibration(cfg, path: Path, K: float) -> Path:
    tc = TendonCalibration(K=K, M_e=float(COMPLIANCE * (1 - np.exp(-K)) / K), compliance=COMPLIANCE, knee_x_in=0.005,
                           knee_T_in=4.0, residual_rms=1e-6, n_samples=300)
    cal = InstrumentCalibration(instrument=cfg.instrument.id, date="2026-01-01T00:00:00+00:00", target_tension=20.0,
                                use_route=False,
                                joints=tuple((j.name, {"a": tc, "b": tc}) for j in cfg.instrument.joints))
    return save_calibration(cal, path)


def _estimate(cfg, joint, K, Ta, xa, Tb, xb, t):
    m = SheathModel(K=K, compliance=COMPLIANCE)
    e = cfg.estimator
    est = PairEstimator(m, m, joint.pulley_radius, n_nodes=e.n_nodes, pretension=joint.pretension,
                         hold_rate=e.hold_rate, rate_time_constant=e.rate_time_constant)
    return np.array([(s.torque, s.angle, s.T_out[0], s.elongation[0], s.T_out[1], s.elongation[1])
                     for s in (est.step(Ta[k], xa[k], Tb[k], xb[k], t[k]) for k in range(t.size))])


def _make_run(root: Path) -> tuple[Path, object]:
    """runs/<id>/ with slave_joints.csv (1.5 s at 1 kHz, tendon a pulled then b), config.yaml, calibration."""
    cfg = load_config(CONFIG)
    run = root / "runs" / "20260101-000000"
    (run / "calibration").mkdir(parents=True)
    write_config(cfg, run / "config.yaml")
    _calibration(cfg, run / "calibration" / f"{cfg.instrument.id}.yaml", K_CAL)
    t = np.arange(N) * 1e-3
    marker = np.where(t < 0.75, 1, 2)
    marker = sum(marker << (4 * j) for j in range(len(cfg.instrument.joints)))
    cols: dict[str, np.ndarray] = {"time": t, "marker": marker.astype(float), "cmd_seq": np.arange(N, dtype=float),
                                   "state": np.full(N, 3.0), "t_node": t, "t_cmd_recv": t}
    for j, joint in enumerate(cfg.instrument.joints):
        n, phase = joint.name, 0.7 * j
        Ta = 3.0 + 2.5 * np.sin(2 * np.pi * 2.0 * t + phase) + 0.8 * np.sin(2 * np.pi * 9.0 * t)
        Tb = 3.0 - 2.5 * np.sin(2 * np.pi * 2.0 * t + phase)
        xa, xb = 1e-4 * Ta + 1e-3 * np.sin(2 * np.pi * 1.0 * t), 1e-4 * Tb - 1e-3 * np.sin(2 * np.pi * 1.0 * t)
        rec = _estimate(cfg, joint, K_CAL, Ta, xa, Tb, xb, t)
        tru = _estimate(cfg, joint, K_TRUE, Ta, xa, Tb, xb, t)
        cols.update({f"{n}.cmd": np.zeros(N), f"{n}.mode": np.zeros(N), f"{n}.torque_hat": rec[:, 0],
                     f"{n}.angle_hat": rec[:, 1], f"{n}.torque": tru[:, 0], f"{n}.angle": tru[:, 1]})
        for k, (T, x) in enumerate(((Ta, xa), (Tb, xb))):
            s = "ab"[k]
            cols.update({f"{n}.{s}.x_in": x, f"{n}.{s}.T_in": T, f"{n}.{s}.x_in_cmd": x,
                         f"{n}.{s}.T_out_hat": rec[:, 2 + 2 * k], f"{n}.{s}.elongation_hat": rec[:, 3 + 2 * k],
                         f"{n}.{s}.phase": np.zeros(N), f"{n}.{s}.T_out": tru[:, 2 + 2 * k],
                         f"{n}.{s}.elongation": tru[:, 3 + 2 * k]})
    names = joint_csv_columns([j.name for j in cfg.instrument.joints], True)
    assert set(names) == set(cols)
    with open(run / "slave_joints.csv", "w", encoding="utf-8") as fh:
        fh.write("# source: test\n# units: time=s\n" + ",".join(names) + "\n")
        np.savetxt(fh, np.column_stack([cols[c] for c in names]), delimiter=",", fmt="%.10g")
    return run, cfg


def _replay(tmp_path: Path, *args: str) -> tuple[int, dict]:
    out = tmp_path / "replay.json"
    out.unlink(missing_ok=True)         # the previous call's: --json refuses an existing file
    rc = main(["replay", *args, "--json", str(out)])
    return rc, json.loads(out.read_text()) if rc == 0 else {}


def test_own_calibration_reproduces_the_recorded_estimate_and_true_one_the_truth(tmp_path, capsys):
    run, cfg = _make_run(tmp_path)
    rc, res = _replay(tmp_path, str(run))
    assert rc == 0 and res["kind"] == "joints" and res["joints"] == [j.name for j in cfg.instrument.joints]
    printed = capsys.readouterr().out
    for joint in res["joints"]:
        c = res["comparison"][joint]
        assert set(c) == {"all", "paper_a", "paper_b"}
        assert c["all"]["vs_recorded"]["torque_error_max_fs"] < 1e-6
        assert c["all"]["vs_recorded"]["angle_error_max_rad"] < 1e-6
        assert c["all"]["vs_truth"]["torque_error_max_fs"] > 0.02      # K_CAL != K_TRUE shows against the truth
        assert joint in printed
    assert Path(res["rrd"]).is_file() and Path(res["rrd"]).stat().st_size > 0
    true_cal = _calibration(cfg, tmp_path / "true.yaml", K_TRUE)
    rc, res2 = _replay(tmp_path, str(run), "--calibration", str(true_cal), "--rrd", str(tmp_path / "r2.rrd"))
    assert rc == 0
    for joint in res2["joints"]:
        c2, c = res2["comparison"][joint]["all"], res["comparison"][joint]["all"]
        assert c2["vs_truth"]["torque_error_max_fs"] < 1e-6
        assert c2["vs_recorded"]["torque_error_max_fs"] > 0.02     # and away from the recorded estimate
        assert c2["vs_truth"]["angle_error_rms_rad"] < c["vs_truth"]["angle_error_rms_rad"]


@pytest.mark.parametrize("case, needle", [("column", "bend_lr.b.T_in"), ("calibration", "no calibration/")])
def test_bad_joint_run_exits_2_naming_the_problem(tmp_path, capsys, case, needle):
    run, cfg = _make_run(tmp_path)
    if case == "column":
        text = (run / "slave_joints.csv").read_text().replace("bend_lr.b.T_in,", "bend_lr.b.T_in_x,")
        (run / "slave_joints.csv").write_text(text)
    else:
        (run / "calibration" / f"{cfg.instrument.id}.yaml").unlink()
    rc = main(["replay", str(run)])
    assert rc == 2
    assert needle in capsys.readouterr().err


def test_a_spindle_run_is_refused_naming_its_joints(tmp_path, capsys):
    """A spindle instrument's per-cable T_in columns are estimates: replaying them as load cells would be wrong."""
    run, _ = _make_run(tmp_path)
    spindle_cfg = load_config(ROOT / "configs" / "instrument-spindle.yaml")
    write_config(spindle_cfg, run / "config.yaml")
    rc = main(["replay", str(run)])
    err = capsys.readouterr().err
    assert rc == 2 and "spindle-driven" in err and spindle_cfg.instrument.joints[0].name in err


def test_a_joint_replay_refuses_an_existing_rrd_and_prints_its_samples_and_rate(tmp_path, capsys):
    run, cfg = _make_run(tmp_path)
    rc, res = _replay(tmp_path, str(run))
    assert rc == 0 and res["rate_hz"] > 0
    joint = cfg.instrument.joints[0].name
    row = next(ln for ln in capsys.readouterr().out.splitlines() if ln.startswith(f"{joint:<9} all      recorded"))
    assert row.endswith(f" {res['comparison'][joint]['all']['vs_recorded']['samples']:8d} at {res['rate_hz']:.4g} Hz")
    before = (run / "replay.rrd").read_bytes()
    assert main(["replay", str(run)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "replay.rrd (the default --rrd" in err[0] and "--force" in err[0]
    assert (run / "replay.rrd").read_bytes() == before
    assert main(["replay", str(run), "--force"]) == 0
