"""teleop replay (live/replay/main.py): a synthetic run (truth from the estimator with K_TRUE, recorded estimate
with the run's calibration K_CAL) replayed with its own calibration, another one, and bad inputs."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from estimator.data import MeasuredData
from estimator.online.distal import estimate_batch
from estimator.sheath import SheathModel
from live.cli import main
from teleop.config.load import load_config, write_config
from teleop.recording.measured import write_measured_csv

K_TRUE, K_CAL, K_OTHER, COMPLIANCE = 0.62, 0.55, 0.80, 1.0e-4


def _calibration(path: Path, K: float) -> Path:
    path.write_text(json.dumps({"K": K, "compliance_m_per_N": COMPLIANCE, "use_route": False}), encoding="utf-8")
    return path


def _make_run(root: Path) -> Path:
    """runs/<id>/ with slave.csv (2 s at 1 kHz, two experiments by marker), config.yaml, calibration.json."""
    cfg = load_config(None)
    e = cfg.estimator
    t = np.arange(2000) * 1e-3
    T_in = 6.0 + 5.0 * np.sin(2 * np.pi * 1.5 * t) + 1.5 * np.sin(2 * np.pi * 7.0 * t)
    x_in = 1e-4 * T_in
    kw = dict(time=t, n_nodes=e.n_nodes, pretension=cfg.sheath.pretension, hold_rate=e.hold_rate,
              rate_time_constant=e.rate_time_constant)
    truth = estimate_batch(T_in, x_in, SheathModel(K=K_TRUE, compliance=COMPLIANCE), **kw)
    rec = estimate_batch(T_in, x_in, SheathModel(K=K_CAL, compliance=COMPLIANCE), **kw)
    marker = np.where(t < 1.0, 1.0, 2.0)
    run = root / "runs" / "20260101-000000"
    run.mkdir(parents=True)
    write_config(cfg, run / "config.yaml")
    _calibration(run / "calibration.json", K_CAL)
    data = MeasuredData(time=t, x_in=x_in, T_in=T_in, x_out=truth.x_out, T_out=truth.T_out,
                        extra={"elongation": truth.elongation, "T_out_hat": rec.T_out,
                               "elongation_hat": rec.elongation, "phase": rec.phase.astype(float),
                               "marker": marker},
                        metadata={"source": "test", "units": "time=s, x_in=m, T_in=N, x_out=m, T_out=N"},
                        source="test")
    write_measured_csv(run / "slave.csv", data)
    return run


def _replay(tmp_path: Path, *args: str) -> tuple[int, dict]:
    out = tmp_path / "replay.json"
    out.unlink(missing_ok=True)         # the previous call's: --json refuses an existing file
    rc = main(["replay", *args, "--json", str(out)])
    return rc, json.loads(out.read_text()) if rc == 0 else {}


def test_same_calibration_reproduces_the_recorded_estimate(tmp_path, capsys):
    run = _make_run(tmp_path)
    rc, res = _replay(tmp_path, str(run))
    assert rc == 0
    assert res["K"] == pytest.approx(K_CAL) and res["samples"] == 2000
    comp = res["comparison"]
    assert set(comp) == {"all", "paper", "minor"}
    for block in comp.values():
        rec = block["vs_recorded"]
        assert rec["force_error_max_fs"] < 1e-6 and rec["elongation_error_max_fs"] < 1e-6
    # the recorded (miscalibrated) estimate is off the truth by a measurable amount
    assert comp["all"]["vs_truth"]["force_error_max_fs"] > 1e-3
    out = capsys.readouterr().out
    assert "recorded" in out and "truth" in out and "samples/s" in out


def test_other_calibration_changes_the_estimate(tmp_path):
    run = _make_run(tmp_path)
    _, same = _replay(tmp_path, str(run))
    rc, other = _replay(tmp_path, str(run), "--calibration", str(_calibration(tmp_path / "other.json", K_OTHER)),
                        "--rrd", str(tmp_path / "other.rrd"))
    assert rc == 0 and other["K"] == pytest.approx(K_OTHER)
    assert other["comparison"]["all"]["vs_recorded"]["force_error_max_fs"] > 0.01
    # the true K reproduces the truth; K_OTHER is further from it than the run's own K_CAL
    rc, true = _replay(tmp_path, str(run), "--calibration", str(_calibration(tmp_path / "true.json", K_TRUE)),
                       "--rrd", str(tmp_path / "true.rrd"))
    assert true["comparison"]["all"]["vs_truth"]["force_error_max_fs"] < 1e-6
    assert (other["comparison"]["all"]["vs_truth"]["force_error_max_fs"]
            > same["comparison"]["all"]["vs_truth"]["force_error_max_fs"])
    rc, paper = _replay(tmp_path, str(run), "--estimator", "paper", "--rrd", str(tmp_path / "paper.rrd"))
    assert rc == 0 and paper["comparison"]["all"]["vs_recorded"]["force_error_max_fs"] > 1e-3


def test_rrd_is_written_and_readable(tmp_path):
    pytest.importorskip("rerun")
    from rerun.chunk import RrdReader

    run = _make_run(tmp_path)
    rc, res = _replay(tmp_path, str(run / "slave.csv"), "--speed", "20")   # the run's calibration
    assert rc == 0 and res["rrd"] == str(run / "replay.rrd")
    assert res["log_s"] >= 2.0 / 20 * 0.9          # paced at 20 x real time
    entities = {c.entity_path for c in RrdReader(run / "replay.rrd").stream().to_chunks()}
    for e in ("/tension/T_out_hat", "/tension/T_out_recorded", "/tension/T_out_true", "/profile/T_hat"):
        assert e in entities, (e, sorted(entities))


@pytest.mark.parametrize("case, needle", [
    ("missing run", "no such run directory"),
    ("missing column", "missing column 'T_in'"),
    ("bad calibration", "compliance_m_per_N"),
    ("bare csv", "--calibration"),
    ("bad speed", "--speed"),
])
def test_bad_input_exits_2_naming_the_problem(tmp_path, capsys, case, needle):
    run = _make_run(tmp_path)
    args = {"missing run": [str(tmp_path / "nope")],
            "bad calibration": [str(run), "--calibration", str(tmp_path / "bad.json")],
            "bare csv": [str(tmp_path / "bare.csv")],
            "bad speed": [str(run), "--speed", "fast"]}.get(case)
    if case == "missing column":
        lines = (run / "slave.csv").read_text().splitlines()
        i = next(k for k, ln in enumerate(lines) if ln.startswith("time,"))
        cols = lines[i].split(",")
        j = cols.index("T_in")
        lines[i:] = [",".join(v for k, v in enumerate(ln.split(",")) if k != j) for ln in lines[i:]]
        (run / "slave.csv").write_text("\n".join(lines) + "\n")
        args = [str(run)]
    if case == "bare csv":
        (tmp_path / "bare.csv").write_text((run / "slave.csv").read_text())
    if case == "bad calibration":
        (tmp_path / "bad.json").write_text('{"K": 0.5}')
    assert main(["replay", *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle in err[0], err


def test_the_calibrations_noise_band_is_replayed(tmp_path):
    """A run whose calibration measured the load cell's noise (``tension_noise_N``) was estimated with the noise band:
    the replay uses it and reproduces the recorded estimate; a config with ``estimator.tension_noise: 0`` turns it off,
    and a bad value is refused naming the key."""
    run = _make_run(tmp_path)
    cfg = load_config(None)
    e = cfg.estimator
    d = json.loads((run / "calibration.json").read_text())
    (run / "calibration.json").write_text(json.dumps({**d, "tension_noise_N": 0.05}), encoding="utf-8")
    from teleop.recording.measured_csv import read_measured_csv
    data = read_measured_csv(run / "slave.csv")
    banded = estimate_batch(data.T_in, data.x_in, SheathModel(K=K_CAL, compliance=COMPLIANCE), time=data.time,
                            n_nodes=e.n_nodes, pretension=cfg.sheath.pretension, hold_rate=e.hold_rate,
                            rate_time_constant=e.rate_time_constant, tension_noise=0.05)
    data.extra["T_out_hat"], data.extra["elongation_hat"] = banded.T_out, banded.elongation
    write_measured_csv(run / "slave.csv", data, overwrite=True)
    rc, res = _replay(tmp_path, str(run))
    assert rc == 0 and res["tension_noise_N"] == 0.05
    assert res["comparison"]["all"]["vs_recorded"]["force_error_max_fs"] < 1e-6
    off = tmp_path / "off.yaml"
    write_config(load_config(None, {"estimator.tension_noise": 0.0}), off)
    rc, res0 = _replay(tmp_path, str(run), "--config", str(off), "--rrd", str(tmp_path / "off.rrd"))
    assert rc == 0 and res0["tension_noise_N"] == 0.0
    assert res0["comparison"]["all"]["vs_recorded"]["force_error_max_fs"] > 1e-6
    (run / "calibration.json").write_text(json.dumps({**d, "tension_noise_N": -1}), encoding="utf-8")
    assert main(["replay", str(run), "--rrd", str(tmp_path / "bad.rrd")]) == 2


def test_an_existing_output_is_refused_unless_force(tmp_path, capsys):
    run = _make_run(tmp_path)
    rrd, js = run / "replay.rrd", tmp_path / "out.json"
    assert main(["replay", str(run), "--json", str(js)]) == 0
    before = rrd.read_bytes()
    capsys.readouterr()
    for args, named in (([str(run)], f"{rrd} (the default --rrd"), ([str(run), "--rrd", str(rrd)], f"--rrd {rrd}:"),
                        ([str(run), "--rrd", str(tmp_path / "new.rrd"), "--json", str(js)], f"--json {js}:")):
        assert main(["replay", *args]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and named in err[0] and "already exists" in err[0] and "--force" in err[0], err
    assert rrd.read_bytes() == before and not (tmp_path / "new.rrd").exists()
    assert main(["replay", str(run), "--json", str(js), "--force"]) == 0
    assert json.loads(js.read_text())["rrd"] == str(rrd)


def test_the_recorded_figure_names_its_samples_and_the_recordings_rate(tmp_path, capsys):
    run = _make_run(tmp_path)
    rc, full = _replay(tmp_path, str(run), "--rrd", str(tmp_path / "full.rrd"))
    assert rc == 0 and full["rate_hz"] == pytest.approx(1000.0)
    assert full["comparison"]["all"]["vs_recorded"]["samples"] == 2000
    assert full["comparison"]["paper"]["vs_recorded"]["samples"] == 1000
    row = next(ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("all     recorded"))
    assert row.endswith(" 2000 at 1000 Hz")
    lines = (run / "slave.csv").read_text().splitlines()          # every 10th row: a 100 Hz recording
    head = next(k for k, ln in enumerate(lines) if ln.startswith("time,")) + 1
    (run / "slave.csv").write_text("\n".join(lines[:head] + lines[head::10]) + "\n")
    rc, dec = _replay(tmp_path, str(run), "--rrd", str(tmp_path / "dec.rrd"))
    assert rc == 0 and dec["rate_hz"] == pytest.approx(100.0) and dec["samples"] == 200
    row = next(ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("all     recorded"))
    assert row.endswith("  200 at 100 Hz")
    # the re-estimate sees only the decimated samples: it no longer reproduces the live 1 kHz estimate
    assert dec["comparison"]["all"]["vs_recorded"]["force_error_max_fs"] > 1e-3 > \
        full["comparison"]["all"]["vs_recorded"]["force_error_max_fs"]
