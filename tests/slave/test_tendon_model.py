"""A single-tendon model file from `teleop analyze FILE.csv --model-out` to the slave's tendon axis: written, loaded,
checked against the catalogue's per-cycle forms (refusals with their reason), run beside the base estimator with the
fallback counted and said once."""
from __future__ import annotations

import json
import logging
import math

import numpy as np
import pytest

from estimator.data import noise_level
from estimator.online.distal import DistalEstimator
from estimator.sheath import SheathModel
from live.cli import main
from slave.estimator_model import configured_model, with_model
from slave.rig import RigState
from slave.tendon_axis import TendonAxis
from slave.tendon_model import ModelRunner, live_average, tendon_model_estimator
from study.scenarios import record
from teleop.config.model_file import ModelExtension, ModelFile, ModelParameter, save_model
from teleop.config.schema import Config
from teleop.errors import ConfigError
from teleop.recording.measured import write_measured_csv


def tendon_file(extensions=(), **kw) -> ModelFile:
    m = dict(axis="tendon", instrument=Config().instrument.id, structure="profile_memory",
             base={"K": 0.6, "compliance": 1e-4, "n_nodes": 16.0, "T_min": 0.2, "rate_hz": 200.0},
             base_ranges={"K": ("-", 0.0, 5.0), "compliance": ("m/N", 0.0, 0.1)}, extensions=tuple(extensions),
             per_cycle="estimator.online.extended.ExtendedEstimator", gain={"base": 0.3, "extended": 0.05, "unit": "N"},
             provenance={"recording": "r.csv", "sha256": "ab" * 32, "span_s": [0.0, 30.0], "project_version": "0",
                         "written": "2026-11-27"})
    m.update(kw)
    return ModelFile(**m)


def ext(eid: str, **params: tuple[float, str, float, float]) -> ModelExtension:
    return ModelExtension(eid, tuple(ModelParameter(n, *v) for n, v in params.items()))


def test_analyze_writes_a_model_the_slave_runs_and_it_beats_the_base_estimator(tmp_path, capsys):
    rec = record("sensor_offset", seed=3, level=0.7, duration=30.0)
    csv, out, js = tmp_path / "s.csv", tmp_path / "s.model.yaml", tmp_path / "s.json"
    write_measured_csv(csv, rec.data)
    assert main(["analyze", str(csv), "--model-out", str(out), "--instrument", "tsm0", "--json", str(js)]) == 0
    assert f"wrote {out}" in capsys.readouterr().out
    mf = configured_model(with_model(Config(), str(out)))
    assert mf is not None and mf.model_id == "tsm0/tendon/profile_memory+sensor_offset:T_in"
    diag = json.loads(js.read_text())
    assert mf.gain == {"base": diag["base"]["rmse_T_out_N"], "extended": diag["extended"]["rmse_T_out_N"], "unit": "N"}
    b = mf.extensions[0].values()["b_T_in"]
    truth = rec.truth["parameters"]["offset"]                       # signed [N]
    assert abs(b - truth) < 0.1 * abs(truth)
    assert mf.provenance["recording"] == "s.csv"
    assert mf.provenance["span_s"][1] == pytest.approx(diag["split"]["time_s"], abs=0.01)
    d = rec.data
    sigma = noise_level(np.asarray(d.T_in))
    runner = ModelRunner(mf, tendon_model_estimator(mf, sigma, 0.02, 1000.0))
    assert runner.estimator.average == 5 == live_average(mf, 1000.0)
    fitted = SheathModel(K=diag["base_model"]["values"]["K"], compliance=diag["base_model"]["compliance"])
    base = DistalEstimator(fitted, n_nodes=32, tension_noise=sigma)
    est = np.array([(s.T_out, runner.step(T, x, t, s).T_out) for T, x, t in zip(d.T_in, d.x_in, d.time, strict=True)
                    for s in (base.step(T, x, t),)])
    test = d.time >= diag["split"]["time_s"]
    rmse = np.sqrt(np.mean((est[test] - d.T_out[test, None]) ** 2, axis=0))
    assert rmse[1] < 0.3 * rmse[0]                  # the offset corrected live
    assert runner.fallbacks == 0 and runner.cycles == len(d.time)


@pytest.mark.parametrize("extensions, message", [
    ((ext("sensor_lag:T_in", tau_T_in=(0.02, "s", 0.0, 0.2)),), "'sensor_lag:T_in' has no per-cycle form: undoing"),
    ((ext("sensor_offset:T_out", b_T_out=(0.1, "N", -10.0, 10.0)),), "a reading model of the distal load cell"),
    ((ext("presliding", x_p=(60e-6, "m", 0.0, 1e-3), presliding_form=(1.0, "-", 0.0, 1.0)),),
     "the per-node form drives the distal end by the measured x_out"),
    ((ext("stiction", r_s=(2.0, "-", 0.0, 2.5)),), None),
    ((ext("stiction", r_s=(2.2, "-", 0.0, 2.5)),), "2.2 - is outside the catalogue's range [0, 2]"),
    ((ext("stiction", wobble=(1.0, "-", 0.0, 2.0)),), "parameters.wobble: no parameter of stiction"),
])
def test_the_slave_checks_a_tendon_model_against_the_catalogue(tmp_path, extensions, message):
    path = save_model(tendon_file(extensions), tmp_path / "m.model.yaml")
    cfg = with_model(Config(), str(path))
    if message is None:
        assert configured_model(cfg) is not None
        return
    with pytest.raises(ConfigError) as e:
        configured_model(cfg)
    assert message in str(e.value) and str(path) in str(e.value) and "\n" not in str(e.value)


def test_another_instrument_or_a_missing_base_parameter_is_refused(tmp_path):
    for model, message in ((tendon_file(instrument="other"), "the model is for 'other'"),
                           (tendon_file(base={"K": 0.6}, base_ranges={}), "missing parameter 'compliance'")):
        path = save_model(model, tmp_path / "m.model.yaml")
        with pytest.raises(ConfigError, match=message):
            configured_model(with_model(Config(), str(path)))


def test_the_tendon_axis_runs_the_model_and_counts_a_fallback_once(tmp_path, caplog):
    path = save_model(tendon_file((ext("friction_offset", a=(0.5, "N", 0.0, 20.0)),)), tmp_path / "m.model.yaml")
    cfg = with_model(Config(), str(path))
    state = RigState(t=0.0, x_in=0.0, T_in=1.0, x_in_cmd=0.0)
    ax = TendonAxis(cfg, state)
    with caplog.at_level(logging.INFO, logger="teleop.slave"):
        ax.start(SheathModel(K=0.6, compliance=1e-4), state)
        for k in range(1, 200):
            x = 1e-4 * math.sin(0.05 * k)
            ax.observe(RigState(t=1e-3 * k, x_in=x, T_in=1.0 + 5e3 * max(x, 0.0), x_in_cmd=x))
        ax.runner.estimator.out_of_range = lambda s: "forced"          # the physical range left twice
        base_T = [ax.observe(RigState(t=0.2 + 1e-3 * k, x_in=0.0, T_in=1.0, x_in_cmd=0.0))[0].effort_hat
                  for k in range(2)]
    stats = TendonAxis.stats([ax])["model"]
    assert stats["id"] == "tsm0/tendon/profile_memory+friction_offset" and stats["cycles"] == 202
    assert stats["fallbacks"] == 2 and base_T[-1] == ax.estimator.T_out
    said = [r for r in caplog.records if "leaves the physical range" in r.getMessage()]
    assert len(said) == 1
    assert any("estimator model tsm0/tendon/profile_memory+friction_offset" in r.getMessage() for r in caplog.records)


def test_a_model_with_a_friction_step_tracks_the_friction_and_the_stats_say_so(tmp_path):
    step = ext("friction_step", t_s=(30.0, "s", 0.0, 1e6), dK=(-0.2, "-", -2.0, 2.0))
    mf = configured_model(with_model(Config(), str(save_model(tendon_file((step,)), tmp_path / "m.model.yaml"))))
    assert mf is not None
    est = tendon_model_estimator(mf, 0.01, 0.02, 1000.0)
    replayed = tendon_model_estimator(mf, 0.01, 0.02, 1000.0, track_friction=False)
    assert est.track_friction and not replayed.track_friction
    runner = ModelRunner(mf, est, "t")
    base = DistalEstimator(SheathModel(K=0.6, compliance=1e-4), n_nodes=16)
    for i in range(16000):                    # capstan loops on a spring, the sheath reshaped at 6 s, not at 30 s
        t = 1e-3 * i
        K = 0.6 if t < 6.0 else 0.45
        x_out = 1e-3 + 2e-3 * (1.0 - math.cos(2.0 * math.pi * t / 1.2))
        s = 1.0 if math.sin(2.0 * math.pi * t / 1.2) >= 0.0 else -1.0
        T_out = 2000.0 * x_out
        T_in = T_out * math.exp(s * K)
        x_in = x_out + 1e-4 * T_out * math.expm1(s * K) / (s * K)      # + L/EA times the mean of the profile
        runner.step(T_in, x_in, t, base.step(T_in, x_in, t))
    friction = runner.stats()["friction"]
    assert friction["tracked"] and friction["estimates"] >= 10 and friction["K_fitted"] == 0.6
    assert friction["K"] == pytest.approx(0.45, abs=0.01)
