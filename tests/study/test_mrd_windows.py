"""A folder whose runs stroke over separate spindle-angle windows is analysed window by window by
``teleop analyze --mrd`` (study.mrd.windows), on synthetic runs of the pair simulator."""
from __future__ import annotations

import argparse
import json

import numpy as np

from recorded.mrd import load_mrd_dir, stroke_groups
from study.mrd.report import main_mrd
from tests.study.test_mrd import simulate, write_txt

OFFSET = 1.5          # [rad] spindle-angle shift of the second window, beyond the stroke (0.8 rad)


def _two_windows(tmp_path):
    tmp_path.mkdir()
    for z, shift in (("0", 0.0), ("1", OFFSET)):
        for y, (k, load) in enumerate(((5.0, 0.1), (8.0, 0.2))):
            t, c, tp, th, td = simulate(freq=0.25, k=k, duration=7.0)
            write_txt(tmp_path / f"{z}0{y}.TXT", t, c + shift, tp, th, td, load_cmd=load)
    return tmp_path


def test_a_folder_of_two_stroke_windows_gets_a_table_per_window_and_a_summary(tmp_path, capsys):
    d = _two_windows(tmp_path / "runs")
    runs, _ = load_mrd_dir(d)
    assert stroke_groups(runs) == [["000", "001"], ["100", "101"]]
    out = tmp_path / "windows.json"
    args = argparse.Namespace(mrd=str(d), json=str(out), runs=None, calibration=None, tool=None, figures=None,
                              report=None)
    assert main_mrd(args) == 0
    printed = capsys.readouterr().out
    assert "window 1 of 2" in printed and "window 2 of 2" in printed and "across 2 stroke windows" in printed
    s = json.loads(out.read_text())         # what the command analysed (study.mrd.windows.analyze_windows)
    assert s["mode"] == "mrd-windows" and len(s["windows"]) == 2
    for w, names in zip(s["windows"], (("000", "001"), ("100", "101")), strict=False):
        assert w["runs"] == list(names)
        assert set(w["summary"]["runs"]) | {w["summary"]["calibration"]["run"]} == set(names)
    lo0, hi0 = s["windows"][0]["spindle_window_deg"]
    lo1, _ = s["windows"][1]["spindle_window_deg"]
    assert hi0 < lo1
    a = s["across"]
    assert a["scored_runs"] == 2 and a["windows"] == 2
    t = [r["torque_rmse_fs"] for w in s["windows"] for r in w["summary"]["runs"].values()]
    assert a["median_torque_rmse_fs"] == float(np.median(t)) and a["max_torque_rmse_fs"] == max(t)
