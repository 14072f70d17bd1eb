"""`teleop analyze`: single-tendon CSV and KAIST modes, JSON summaries, errors."""
from __future__ import annotations

import argparse
import json
import math

import numpy as np
import pytest

from estimator.errors import DataError
from estimator.offline.fit import predict
from recorded.folders import KAIST, skip_reason
from recorded.kaist import CONFIGS_DEG
from recorded.kaist_files import default_kaist_dir, find_configs
from study import analyze
from teleop.errors import ConfigError

KAIST_DIR = default_kaist_dir()


def run(argv: list[str]) -> int:
    p = argparse.ArgumentParser()
    analyze.add_arguments(p)
    return analyze.main_analyze(p.parse_args(argv))


def write_csv(path, n=4000, distal=("x_out", "T_out"), K=0.5, c=1e-4):
    t = np.arange(n) * 1e-3
    T_in = 6 + 4 * np.sin(2 * np.pi * 0.5 * t) + 1.2 * np.sin(2 * np.pi * 2.3 * t)
    x_in = 1e-3 * np.sin(2 * np.pi * 0.5 * t)
    T_out, x_out = predict("profile", T_in, x_in, K, c)
    cols = {"time": t, "x_in": x_in, "T_in": T_in, "x_out": x_out, "T_out": T_out}
    names = ["time", "x_in", "T_in", *distal]
    with open(path, "w") as fh:
        fh.write("# rig: synthetic\n" + ",".join(names) + "\n")
        np.savetxt(fh, np.column_stack([cols[k] for k in names]), delimiter=",", fmt="%.12g")
    return path


@pytest.fixture(scope="module")
def offset_csv(tmp_path_factory):
    """A simulated bench recording (study.scenarios) with tension-independent friction hidden in it."""
    from study.scenarios import record
    from teleop.recording.measured import write_measured_csv
    rec = record("friction_offset", seed=3, level=1.0, duration=45.0)
    path = tmp_path_factory.mktemp("scenario") / "offset.csv"
    write_measured_csv(path, rec.data)
    return path, rec


def test_csv_diagnosis_json_and_report(offset_csv, tmp_path, capsys):
    path, rec = offset_csv
    out, rep = tmp_path / "d.json", tmp_path / "report"
    assert run([str(path), "--json", str(out), "--report", str(rep)]) == 0
    text = capsys.readouterr().out
    assert "cause: friction_offset" in text and "held-out rmse T_out: base" in text and "parameters: K = " in text
    s = json.loads(out.read_text())
    assert {"cause", "causes", "base", "extended", "gain", "parameters", "candidates"} <= set(s)
    for key in ("base", "extended"):
        assert set(s[key]) == {"rmse_T_out_N", "rmse_x_out_m"}
        assert all(v > 0 for v in s[key].values())
    assert s["cause"] == "friction_offset" and s["causes"][0] == "friction_offset"
    assert s["gain"] > 0.5 and s["extended"]["rmse_T_out_N"] < 0.5 * s["base"]["rmse_T_out_N"]
    assert s["parameters"]["a"]["unit"] == "N"
    assert s["parameters"]["a"]["value"] == pytest.approx(rec.truth["parameters"]["tension_offset"], rel=0.2)
    # every candidate is fitted or screened at the base (listed with its share), the cause fitted
    assert "friction_offset" in s["candidates"]
    assert set(s["candidates"]) | set(s["screened"]) >= {"friction_offset", "sensor_offset:T_in", "pretension"}
    te = s["split"]["test"]      # the held-out duration is printed as such (not the run time)
    assert f"({te['time_s'][1] - te['time_s'][0]:.1f} s), used once" in text
    assert te["index"][1] == len(rec.data) and s["split"]["train"]["index"][1] == te["index"][0]
    assert s["n_samples"] == len(rec.data) and len(out.read_text()) < 40_000     # no per-sample arrays
    names = sorted(p.name for p in rep.iterdir())
    assert "report.md" in names and sum(n.endswith(".png") for n in names) >= 4
    md = (rep / "report.md").read_text()
    assert "friction_offset" in md and all(f"({n})" in md for n in names if n.endswith(".png"))


def test_csv_with_T_out_only(tmp_path, capsys):
    out = tmp_path / "s.json"
    assert run([str(write_csv(tmp_path / "r.csv", distal=("T_out",))), "--json", str(out)]) == 0
    s = json.loads(out.read_text())
    assert s["base"]["rmse_x_out_m"] is None and s["extended"]["rmse_x_out_m"] is None
    # the profile memory from a uniform 6 N profile (the first T_in): the base model starts from zero
    assert s["cause"] == "pretension" and s["parameters"]["T0"]["value"] == pytest.approx(6.0, rel=0.05)
    assert s["extended"]["rmse_T_out_N"] < 0.01 < s["base"]["rmse_T_out_N"]
    assert s["parameters"]["K"]["value"] == pytest.approx(0.5, rel=0.05)
    assert "x_out" not in capsys.readouterr().out


def test_errors(tmp_path):
    with pytest.raises(DataError, match=r"nope\.csv: no such file"):
        run([str(tmp_path / "nope.csv")])
    with pytest.raises(ConfigError, match="needs FILE or --kaist"):
        run([])
    with pytest.raises(DataError, match="needs a distal column"):
        run([str(write_csv(tmp_path / "prox.csv", distal=()))])
    with pytest.raises(ConfigError, match="--json .*does not exist"):
        run([str(write_csv(tmp_path / "r.csv")), "--json", str(tmp_path / "no" / "dir" / "s.json")])
    with pytest.raises(ConfigError, match="--report .*not a directory"):
        run([str(tmp_path / "r.csv"), "--report", str(tmp_path / "r.csv")])
    with pytest.raises(ConfigError, match=r"--train-fraction must be in \[0.3, 0.9\]"):
        run([str(tmp_path / "r.csv"), "--train-fraction", "0.95"])
    with pytest.raises(DataError, match="no KAIST recordings found under"):
        run(["--kaist", str(tmp_path / "nowhere")])
    bad = tmp_path / "bad.csv"
    bad.write_text("time,x_in,T_in,T_out\n0,0,1,1\n0.001,0,x,1\n0.002,0,1,1\n")
    with pytest.raises(DataError, match=r"bad\.csv:3"):
        run([str(bad)])
    with pytest.raises(DataError, match=r"short\.csv: .*too few to diagnose"):
        run([str(write_csv(tmp_path / "short.csv", n=300))])


def test_cli_turns_a_missing_file_into_one_line_and_exit_2(tmp_path, capsys):
    cli = pytest.importorskip("live.cli")
    assert cli.main(["analyze", str(tmp_path / "missing.csv")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "missing.csv: no such file" in err[0]


def test_cli_csv_without_T_out_and_x_out_is_one_line_and_exit_2(tmp_path, capsys):
    cli = pytest.importorskip("live.cli")
    path = write_csv(tmp_path / "proximal.csv", distal=())
    assert cli.main(["analyze", str(path), "--json", str(tmp_path / "d.json")]) == 2
    cap = capsys.readouterr()
    err = cap.err.strip().splitlines()
    assert len(err) == 1 and "proximal.csv: needs a distal column 'x_out' or 'T_out'" in err[0]
    assert not (tmp_path / "d.json").exists() and cap.out == ""


def write_kaist_dir(d, noise_deg=0.05, configs=CONFIGS_DEG):
    """Synthetic configurations (default the five shipped bends) made by the capstan-joint pair model
    with K = 0.5 + 0.15 N (N the configuration angle [rad]) and tracker / load-cell noise, in the
    KAIST file layout."""
    from estimator.pair_kernels import simulate_pair
    d.mkdir()
    rng = np.random.default_rng(0)
    for N in configs:
        t = np.arange(0, 12.85, 0.025)
        cmd = 60 * np.sin(t - 0.025)
        cmd[0] = 0.0
        K = 0.5 + 0.15 * math.radians(N)
        th, T = simulate_pair(np.radians(cmd), (5.0, 5.0), 1.4, (0.4, 0.4), (K, K), 4.0)
        ang = np.degrees(th) + noise_deg * rng.standard_normal(t.size)
        T = T + 0.02 * rng.standard_normal(T.shape)
        T[0] = 5.0
        rows = np.column_stack([t, cmd, np.gradient(cmd), ang, T[:, 0], T[:, 1], 0 * t, 0 * t])
        rows = np.repeat(rows, 3, axis=0)                    # each time stamp three times
        (d / f"sine_config_{N}.txt").write_text("".join(", ".join(f"{v:.6f}" for v in r) + ", \n" for r in rows))
    return d


def longest_list(obj) -> int:
    """Length of the longest list anywhere in a JSON value (per-sample data would be ~500)."""
    if isinstance(obj, dict):
        return max((longest_list(v) for v in obj.values()), default=0)
    if isinstance(obj, list):
        return max([len(obj)] + [longest_list(v) for v in obj])
    return 0


def test_kaist_mode_on_synthetic_files(tmp_path, capsys):
    from study.kaist.report import FIGURES
    d = write_kaist_dir(tmp_path / "kaist", configs=(0, 120, 240))
    out = tmp_path / "k.json"
    assert run(["--kaist", str(d), "--json", str(out), "--report", str(tmp_path / "rep"), "--bootstrap", "5"]) == 0
    text = capsys.readouterr().out
    assert "seed" in text and "extended" in text and "lin+play" in text and "E6 (K grows with the bend)" in text
    s = json.loads(out.read_text())
    assert [c["config_deg"] for c in s["configurations"]] == [0, 120, 240]
    for c in s["configurations"]:
        assert set(c["models"]) == {"seed pair model", "force path", "linear map", "linear map + play"}
        assert c["cycle1"][1] == c["cycle2"][0] == pytest.approx(2 * math.pi, abs=0.05)
        g = c["diagnosis"]
        assert g["causes"] == ["capstan_joint"] and g["extended"]["model"] == "capstan"
        assert g["extended"]["rmse_test_deg"] < 0.08 < g["seed"]["rmse_test_deg"]       # at the 0.05 deg noise
        K = 0.5 + 0.15 * math.radians(c["config_deg"])
        assert c["shared"]["K_a"] == pytest.approx(K, rel=0.05) and c["shared"]["K_b"] == pytest.approx(K, rel=0.05)
        assert c["shared"]["rmse_test_deg"] < 0.08 and c["shared"]["leave_one_out_rmse_test_deg"] < 0.2
    sh = s["shared"]
    assert sh["mu"] == pytest.approx(0.15, rel=0.05) and sh["E6"]["accepted"]
    assert sh["chosen"] in sh["choice"]["candidates"] and sh["params"]["model"]["name"] == sh["chosen"]
    vals = sh["params"]["values"]
    assert vals["mu"]["value"] == pytest.approx(0.15, rel=0.05) and vals["mu"]["std"] < 0.02
    assert all(v["ci95"][0] <= v["value"] + 1e-9 and v["std"] >= 0 for v in vals.values())
    corr = np.array(sh["uncertainty"]["bootstrap"]["correlation"]["matrix"])
    assert corr.shape == (len(vals), len(vals)) and np.allclose(np.diag(corr), 1.0, atol=1e-3)
    # fit once, predict new bends: configurations never seen, nothing refitted
    d2 = write_kaist_dir(tmp_path / "new", configs=(90, 300))
    out2 = tmp_path / "p.json"
    assert run(["--kaist", str(d2), "--shared-params", str(out), "--json", str(out2)]) == 0
    pred = json.loads(out2.read_text())["shared_prediction"]
    assert set(pred) == {"90", "300"}
    assert all(r["rmse_deg"] < 0.2 for r in pred.values())              # 0.05 deg noise, K from the bend alone
    assert pred["300"]["K_a"] == pytest.approx(0.5 + 0.15 * math.radians(300), rel=0.05)
    assert "shared parameter set" in capsys.readouterr().out
    assert sh["models"]["capstan, mu = 0"]["rmse_test_deg"] > 5 * sh["models"]["capstan"]["rmse_test_deg"]
    zones = [np.nanmean([z["command_travel_deg"] or np.nan for z in c["dead_zones"]]) for c in s["configurations"]]
    # model-free: dead zone grows with N
    assert all(a < b for a, b in zip(zones, zones[1:], strict=False))
    assert longest_list(s) < 50                                         # summary numbers, no per-sample arrays
    names = {p.name for p in (tmp_path / "rep").iterdir()}
    assert names == set(FIGURES) | {"report.md"}
    md = (tmp_path / "rep" / "report.md").read_text()
    assert "capstan_joint" in md and all(f"({f})" in md for f in FIGURES)


def test_a_kaist_file_name_runs_its_whole_directory(tmp_path, monkeypatch, capsys):
    d = write_kaist_dir(tmp_path / "kaist")
    seen = []

    def fake(recs, progress=False, **kw):
        seen.extend(r.config_deg for r in recs)
        return {"mode": "kaist", "configurations": []}, []
    monkeypatch.setattr(analyze, "analyze_kaist", fake)
    assert run([str(d / "sine_config_60.txt")]) == 0
    assert seen == list(CONFIGS_DEG)


def test_kaist_bend_option_columns_and_shared_params_errors(tmp_path, monkeypatch, capsys):
    d = write_kaist_dir(tmp_path / "kaist", configs=(60,))
    other = d / "run_a.txt"
    other.write_text((d / "sine_config_60.txt").read_text())
    seen = []

    def fake(recs, progress=False, **kw):
        seen.extend((r.config_deg, r.notes[0]) for r in recs)
        return {"mode": "kaist", "configurations": []}, []
    monkeypatch.setattr(analyze, "analyze_kaist", fake)
    assert run([str(other), "--bend", "75", "--columns", "time=0,command=1,angle=3,T_a=4,T_b=5"]) == 0
    assert seen == [(75, "columns used: time=0,command=1,angle=3,T_a=4,T_b=5")]
    with pytest.raises(DataError, match=r"run_a\.txt: not named sine_config_<N>\.txt: give its bend with --bend"):
        run([str(other), "--columns", "time=0,command=1,angle=3,T_a=4,T_b=5"])
    with pytest.raises(ConfigError, match="--columns: missing T_b"):
        run(["--kaist", str(d), "--columns", "time=0,command=1,angle=3,T_a=4"])
    with pytest.raises(DataError, match=r"nope\.json: no such file"):
        run(["--kaist", str(d), "--shared-params", str(tmp_path / "nope.json")])
    (tmp_path / "bad.json").write_text("{}")
    with pytest.raises(DataError, match=r"bad\.json: not a teleop analyze --kaist JSON with shared\.params"):
        run(["--kaist", str(d), "--shared-params", str(tmp_path / "bad.json")])
    (d / "sine_config_90.txt").write_text("1, 2\n")                    # malformed: one line, left out
    seen.clear()
    assert run(["--kaist", str(d)]) == 0
    assert [n for n, _ in seen] == [60]
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("skipped ") and "sine_config_90.txt" in err[0]


@pytest.mark.kaist
@pytest.mark.skipif(not find_configs(KAIST_DIR), reason=skip_reason(KAIST, KAIST_DIR))
def test_kaist_findings_hold_on_the_real_data(tmp_path, capsys):
    out = tmp_path / "k.json"
    five = ",".join(str(n) for n in CONFIGS_DEG)                       # a clone holds five more
    assert run(["--kaist", str(KAIST_DIR), "--configs", five, "--json", str(out), "--bootstrap", "5"]) == 0
    s = json.loads(out.read_text())
    rm = {c["config_deg"]: {k: v["rmse_test_deg"] for k, v in c["models"].items()} for c in s["configurations"]}
    for N, r in rm.items():
        assert r["seed pair model"] < 0.6 * r["linear map"], N          # docs/results/kaist.md
        assert r["linear map + play"] < 0.6 * r["seed pair model"], N
    zones = [np.mean([z["command_travel_deg"] for z in c["dead_zones"] if z["command_travel_deg"]])
             for c in s["configurations"]]
    assert all(a < b for a, b in zip(zones, zones[1:], strict=False))                 # dead zone grows with N
    assert 0.1 < s["trend"]["K_release_per_rad"] < 0.25                # mu of the added bends
    seed_K = [max(c["models"]["seed pair model"]["params"][k] for k in ("K_a", "K_b"))
              for c in s["configurations"]]
    assert max(seed_K) < 0.3                                           # the kinematic path finds ~no friction
    # docs/results/kaist.md: the capstan-joint model beats the seed model on every configuration; K grows with N
    for c in s["configurations"]:
        g = c["diagnosis"]
        assert g["causes"][0] == "capstan_joint" and g["extended"]["rmse_test_deg"] < 0.5 * g["seed"]["rmse_test_deg"]
        assert g["extended"]["rmse_test_deg"] < 1.5 and "test" not in str(g["candidates"])   # choice: training only
        assert g["samples"]["fit"][1] <= g["samples"]["test"][0]
        r = g["candidates"][g["extended"]["model"]]["tension_peak_ratio"]      # the tension check
        assert g["tension_check"]["ratio"] == 1.5 and all(1 / 1.5 <= x <= 1.5 for x in r)
    assert s["shared"]["E6"]["accepted"] and 0.05 < s["shared"]["mu"] < 0.3
    ms = s["shared"]["models"]
    assert ms["capstan"]["rmse_test_deg"] < 0.5 * ms["capstan, mu = 0"]["rmse_test_deg"]      # K grows with N
    # docs/results/kaist.md: one set for all five, chosen by leave-one-out on the training cycles, with uncertainties
    sh = s["shared"]
    vals = sh["params"]["values"]
    assert 0.05 < vals["mu"]["value"] < 0.3 and vals["mu"]["std"] < 0.5 * vals["mu"]["value"]
    assert all(r["rmse_test_deg"] < 5.0 for r in sh["leave_one_out"][sh["chosen"]])
    # every reported figure with its bootstrap uncertainty (docs/results/kaist.md)
    for r in sh["leave_one_out"][sh["chosen"]]:
        b = r["rmse_test_bootstrap"]
        assert b["n_draws"] == 5 and 0.0 < b["std_deg"] < r["rmse_test_deg"] and b["ci95_deg"][0] <= b["ci95_deg"][1]
    for c in s["configurations"]:
        b = c["diagnosis"]["extended"]["rmse_test_bootstrap"]
        assert b["n_draws"] == 5 and 0.0 < b["std_deg"] < 0.5 * c["diagnosis"]["extended"]["rmse_test_deg"]
    assert "+- " in capsys.readouterr().out.split("leave one out, ")[1].splitlines()[0]


def test_route_option_holds_the_configured_route(tmp_path, capsys):
    # an instrument whose route is known (CONFIG's sheath.runs) is diagnosed with that route held instead of
    # fitted: on this recording of the independent simulator (seed 1909112, a distal load-cell offset of
    # -0.84 N; its arcs are where the fitted route can hide the offset) the held route names it
    from study.lumped.scenarios import record
    from teleop.recording.measured import write_measured_csv
    rec = record("sensor_offset:T_out", seed=1909112, level=0.8, duration=60.0)
    path = tmp_path / "r.csv"
    write_measured_csv(path, rec.data)
    runs = "\n".join(f"    - {{length: {length!r}" + ("" if math.isinf(r) else f", radius: {r!r}") + "}"
                     for length, r in rec.truth["route"])
    cfg = tmp_path / "route.yaml"
    cfg.write_text(f"sheath:\n  EA: {rec.truth['EA']!r}\n  runs:\n{runs}\n")
    out = tmp_path / "s.json"
    assert run([str(path), "--route", str(cfg), "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert f"route held from {cfg}: {len(rec.truth['route'])} runs" in text
    s = json.loads(out.read_text())
    assert s["cause"] == "sensor_offset:T_out" and s["route"].startswith("route held from")
    assert s["parameters"]["b_T_out"]["value"] == pytest.approx(rec.truth["parameters"]["offset"], rel=0.25)
    assert not any(k.startswith("r_") for k in s["parameters"])          # no route share was fitted
    assert len(s["settings"]["wrap_shape"]) == 257
    straight = tmp_path / "straight.yaml"
    straight.write_text("sheath:\n  runs:\n    - {length: 1.0}\n")
    with pytest.raises(ConfigError, match=r"--route .*straight\.yaml: the sheath's route \(1 runs\) has no bend"):
        run([str(path), "--route", str(straight)])
    with pytest.raises(ConfigError, match=r"--route .*nope\.yaml: no such file"):
        run([str(path), "--route", str(tmp_path / "nope.yaml")])
    with pytest.raises(ConfigError, match="--route is for a single-tendon CSV"):
        run(["--kaist", str(tmp_path), "--route", str(cfg)])


def test_cli_refuses_a_tool_outside_the_spindle_analysis(tmp_path, capsys):
    from live.cli import main

    path = write_csv(tmp_path / "rec.csv")
    assert main(["analyze", str(path), "--tool", "davinci-maryland-left"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--tool davinci-maryland-left" in err[0] and "--mrd" in err[0]
