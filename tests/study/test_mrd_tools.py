"""The tool files on the MRD folders (the MRD data of TSM_TELEOP_DATA, docs/how-to/get-the-data.md; MRD Lab data
repository, University of Minnesota, ODbL 1.0 / DbCL 1.0): one calibration run of each folder plus the tool's load gain,
``teleop analyze --mrd DIR
--tool NAME``, meet the line of docs/how-to/tools.md: jaw-torque RMSE median <= 0.03 and worst run <= 0.10 of
full scale, every scored run better than the linear baseline; the roll folder window by window.

Each folder is scored with a tool measured on another folder (the left jaw of tool 5 with the constants of tool
4 and the reverse; the rolled wrist with those of the unrolled one), except the right jaw: the data hold one
right-jaw folder, so its tool's gain comes from the folder it is scored on (the calibration is still one run).
A line the data do not meet is marked xfail (strict) with the figure it reaches.
"""
from __future__ import annotations

import io
from contextlib import redirect_stdout

import pytest

from recorded.folders import MRD, skip_reason
from recorded.mrd import load_mrd_dir, stroke_groups
from recorded.mrd_files import default_mrd_dir, mrd_folder
from study.mrd.report import analyze_mrd
from study.mrd.windows import analyze_windows
from teleop.config.tools import load_tool

pytestmark = pytest.mark.mrd
ROOT = default_mrd_dir()
MEDIAN, WORST = 0.03, 0.10

#: folder under ROOT (the project's layout; a clone's data/<name> is found by its name) -> the tool it is scored
#: with (measured on the folder named in the tool file).
CASES = {
    "more/Tool_5_Maryland_L_2": "davinci-maryland-left",         # constants of Tool_4_Maryland_L_2
    "more/Tool_4_Maryland_R_5": "davinci-maryland-right",        # constants of this folder (the only right jaw)
    "more/Tool_4_Maryland_L_Roll_1": "davinci-maryland-left",    # constants of Tool_4_Maryland_L_2 (unrolled)
    "Tool_4_Maryland_L_2": "davinci-maryland-left-tool5",        # constants of Tool_5_Maryland_L_2
}
#: (folder, line) the data do not meet, and the figure they reach.
SHORT = {
    ("more/Tool_5_Maryland_L_2", "linear"): "4 of 19 runs at the calibration run's load level (01, 11, 21, 41): "
                                            "0.018-0.035 against the linear baseline's 0.015-0.017 FS; the error is "
                                            "one offset per run (without it 0.008-0.016 FS): the spindle band's high "
                                            "edge scatters 3.8-4.6 mN m between runs at one jaw load and run 31 "
                                            "reads 1.3 mN m high (docs/results/mrd.md)",
    ("more/Tool_4_Maryland_L_Roll_1", "median"): "window -30..30 deg (runs 20*) median 0.035 FS; the other four "
                                                 "0.015-0.029, pooled 0.026: a jaw-side torque ripple fixed in the jaw "
                                                 "angle (2.9 % of the jaw torque) that the spindle-angle shape cannot "
                                                 "follow, and a bent centre-to-jaw line (docs/results/mrd.md)",
}


def _windows(folder: str) -> list[dict]:
    """The summary of each stroke window of ``folder`` scored with its tool (one window for most folders)."""
    d = mrd_folder(folder.split("/")[-1], ROOT)
    if not d.is_dir():
        pytest.skip(skip_reason(MRD, d))
    runs, _ = load_mrd_dir(d)
    tool = load_tool(CASES[folder])
    assert tool.load_gain.measured_on != d.name or folder.endswith("R_5")

    def analyze(sub, cal, progress=False, tool=tool):
        return analyze_mrd(sub, cal, progress=progress, tool=tool, folder=False)
    if len(stroke_groups(runs)) == 1:
        return [analyze(runs, None)[0]]
    with redirect_stdout(io.StringIO()):
        out = analyze_windows(analyze, runs, None, tool, False)
    return [w["summary"] for w in out["windows"]]


_CACHE: dict[str, list[dict]] = {}


def _scored(folder: str) -> list[dict]:
    if folder not in _CACHE:
        _CACHE[folder] = _windows(folder)
    return _CACHE[folder]


def _case(folder: str, line: str):
    reason = SHORT.get((folder, line))
    marks = [pytest.mark.xfail(strict=True, reason=reason)] if reason else []
    return pytest.param(folder, line, marks=marks, id=f"{folder.split('/')[-1]}-{line}")


@pytest.mark.parametrize("folder,line", [_case(f, ln) for f in CASES for ln in ("median", "worst", "linear")])
def test_one_run_and_the_tool_meet_the_line(folder, line):
    windows = _scored(folder)
    assert windows and all(s["calibration"]["design_load_gain"]["tool"] == CASES[folder] for s in windows)
    assert all(len(s["calibration"]["runs"]) == 1 for s in windows)
    for s in windows:
        m = s["summary"]["model"]
        if line == "median":
            assert m["median_torque_rmse_fs"] <= MEDIAN
        elif line == "worst":
            assert m["max_torque_rmse_fs"] <= WORST
        else:
            assert s["summary"]["better_than_linear_every_run"]


def test_the_roll_folder_is_analysed_window_by_window():
    windows = _scored("more/Tool_4_Maryland_L_Roll_1")
    assert len(windows) == 5
    scored = [set(s["runs"]) for s in windows]
    assert all(len({n[0] for n in names}) == 1 for names in scored)     # one jaw stopping position per window
