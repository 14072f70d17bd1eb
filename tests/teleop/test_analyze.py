"""`teleop analyze`: single-tendon CSV and KAIST modes, JSON summaries, errors."""
from __future__ import annotations

import argparse
import json
import math

import numpy as np
import pytest

from estimator.fit import predict
from estimator.pair import play
from teleop import analyze
from teleop.errors import ConfigError, DataError
from teleop.kaist import CONFIGS_DEG, default_kaist_dir

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


def test_single_csv_table_and_json(tmp_path, capsys):
    out = tmp_path / "summary.json"
    assert run([str(write_csv(tmp_path / "run.csv")), "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "profile memory" in text and "phase formulas" in text and "T_out RMSE [N]" in text
    s = json.loads(out.read_text())
    assert s["mode"] == "single" and s["signals"] == ["T_out", "x_out"]
    assert s["split_time"] == pytest.approx(0.6 * 3.999, abs=2e-3)
    assert s["n_train"] + s["n_heldout"] == 4000
    for name in ("profile", "phase"):
        f = s["estimators"][name]
        assert set(f) == {"K", "compliance", "cost", "train", "heldout"}
        for sig in ("T_out", "x_out"):
            assert set(f["heldout"][sig]) == {"rmse", "max_abs", "full_scale", "rmse_fs", "max_fs"}
    prof = s["estimators"]["profile"]
    assert prof["K"] == pytest.approx(0.5, rel=0.02) and prof["compliance"] == pytest.approx(1e-4, rel=0.02)
    assert prof["heldout"]["T_out"]["max_fs"] < 1e-3


def test_single_csv_with_T_out_only(tmp_path, capsys):
    out = tmp_path / "s.json"
    assert run([str(write_csv(tmp_path / "r.csv", distal=("T_out",))), "--json", str(out)]) == 0
    s = json.loads(out.read_text())
    assert s["signals"] == ["T_out"] and s["estimators"]["profile"]["compliance"] is None
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
    with pytest.raises(DataError, match="KAIST data not found at"):
        run(["--kaist", str(tmp_path / "nowhere")])
    bad = tmp_path / "bad.csv"
    bad.write_text("time,x_in,T_in,T_out\n0,0,1,1\n0.001,0,x,1\n0.002,0,1,1\n")
    with pytest.raises(DataError, match=r"bad\.csv:3"):
        run([str(bad)])


def test_cli_turns_a_missing_file_into_one_line_and_exit_2(tmp_path, capsys):
    cli = pytest.importorskip("teleop.cli")
    assert cli.main(["analyze", str(tmp_path / "missing.csv")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "missing.csv: no such file" in err[0]


def write_kaist_dir(d):
    """Five synthetic configurations: a backlash whose width grows with N, tensions that follow."""
    d.mkdir()
    for N in CONFIGS_DEG:
        t = np.arange(0, 12.85, 0.025)
        cmd = 60 * np.sin(t - 0.025)
        cmd[0] = 0.0
        ang = np.degrees(play(np.radians(0.7 * cmd), np.radians(10 + N / 10)))
        Ta, Tb = 5 + cmd / 15, 5 - cmd / 15
        rows = np.column_stack([t, cmd, np.gradient(cmd), ang, Ta, Tb, 0 * t, 0 * t])
        rows = np.repeat(rows, 3, axis=0)                    # each time stamp three times
        (d / f"sine_config_{N}.txt").write_text("".join(", ".join(f"{v:.6f}" for v in r) + ", \n" for r in rows))
    return d


def test_kaist_mode_on_synthetic_files(tmp_path, capsys):
    d = write_kaist_dir(tmp_path / "kaist")
    out = tmp_path / "k.json"
    assert run(["--kaist", str(d), "--json", str(out), "--figures", str(tmp_path / "fig")]) == 0
    text = capsys.readouterr().out
    assert "seed pair" in text and "lin+play" in text
    s = json.loads(out.read_text())
    assert [c["config_deg"] for c in s["configurations"]] == list(CONFIGS_DEG)
    for c in s["configurations"]:
        assert set(c["models"]) == {"seed pair model", "force path", "linear map", "linear map + play"}
        assert c["cycle1"][1] == c["cycle2"][0] == pytest.approx(2 * math.pi, abs=0.05)
        m = c["models"]
        assert m["linear map + play"]["rmse_test_deg"] < 0.2                 # the data is a backlash
        assert m["linear map"]["rmse_test_deg"] > 2.0
        w = math.degrees(m["linear map + play"]["params"]["w"])
        assert w == pytest.approx(10 + c["config_deg"] / 10, rel=0.03)
    assert len(out.read_text()) < 40_000                       # summary numbers, no per-sample arrays
    assert sorted(p.name for p in (tmp_path / "fig").iterdir()) == [
        "kaist_loops.png", "kaist_residuals.png", "kaist_rmse.png"]
    # a KAIST file name given as FILE runs every configuration of its directory
    assert run([str(d / "sine_config_60.txt"), "--json", str(out)]) == 0
    assert len(json.loads(out.read_text())["configurations"]) == 5


@pytest.mark.kaist
@pytest.mark.skipif(not KAIST_DIR.is_dir(), reason=f"KAIST data not found at {KAIST_DIR}: these tests need "
                                                   "the unlicensed measurements, see docs/findings.md")
def test_kaist_findings_hold_on_the_real_data(tmp_path, capsys):
    out = tmp_path / "k.json"
    assert run(["--kaist", str(KAIST_DIR), "--json", str(out)]) == 0
    s = json.loads(out.read_text())
    rm = {c["config_deg"]: {k: v["rmse_test_deg"] for k, v in c["models"].items()} for c in s["configurations"]}
    for N, r in rm.items():
        assert r["seed pair model"] < 0.6 * r["linear map"], N          # docs/findings.md, table 1
        assert r["linear map + play"] < 0.6 * r["seed pair model"], N
    zones = [np.mean([z["command_travel_deg"] for z in c["dead_zones"] if z["command_travel_deg"]])
             for c in s["configurations"]]
    assert all(a < b for a, b in zip(zones, zones[1:]))                 # dead zone grows with N
    assert 0.1 < s["trend"]["K_release_per_rad"] < 0.25                # mu of the added bends
    seed_K = [max(c["models"]["seed pair model"]["params"][k] for k in ("K_a", "K_b"))
              for c in s["configurations"]]
    assert max(seed_K) < 0.3                                           # the kinematic path finds ~no friction
