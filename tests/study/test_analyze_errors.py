"""`teleop analyze` on input that is wrong: every error is one line on stderr naming the file (and the line and
column where there is one), exit status 2."""
from __future__ import annotations

import json

import numpy as np
import pytest

from live.cli import main

ROWS = 50


def csv_text(n: int = ROWS) -> str:
    t = np.arange(n) * 1e-3
    rows = "".join(f"{t[i]:.3f},{1e-4 * i:.6g},{5 + 0.01 * i:.6g},{1e-4 * i:.6g},{4 + 0.01 * i:.6g}\n"
                   for i in range(n))
    return "# rig: synthetic\ntime,x_in,T_in,x_out,T_out\n" + rows


def refused(argv: list[str], capsys) -> str:
    """The one line ``teleop analyze ARGV`` prints on stderr before it exits with status 2 (nothing on stdout)."""
    assert main(["analyze", *argv]) == 2
    cap = capsys.readouterr()
    lines = cap.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("teleop: error: ") and cap.out == "", cap.err
    return lines[0].removeprefix("teleop: error: ")


def test_a_directory_says_it_is_a_directory(tmp_path, capsys):
    from estimator.errors import DataError
    from recorded.kaist_files import find_kaist_dir
    from recorded.mrd import load_mrd_dir
    from study.analyze import configured_route
    from teleop.errors import ConfigError
    msg = refused([str(tmp_path)], capsys)             # the CLI's own check of its path arguments may come first
    assert str(tmp_path) in msg and "is a directory" in msg
    assert refused([str(tmp_path / "none.csv")], capsys).endswith(f"{tmp_path / 'none.csv'}: no such file")
    f = tmp_path / "r.csv"
    f.write_text(csv_text())
    with pytest.raises(DataError, match=r"r\.csv: a file, not a folder: --kaist takes the folder"):
        find_kaist_dir(f)
    with pytest.raises(DataError, match=r"r\.csv: a file, not an MRD folder: give the folder that holds the \*\.TXT "
                                        r"runs \(--runs r picks this one\)$"):
        load_mrd_dir(f)
    with pytest.raises(ConfigError, match=rf"^--route {tmp_path}: is a directory, not a file$"):
        configured_route(tmp_path)


@pytest.mark.parametrize("encode, what", [
    (lambda s: s.encode("utf-16"), "looks like UTF-16 text, byte-order mark at byte 0); save it as UTF-8"),
    (lambda s: s.encode("utf-16-le"), "looks like UTF-16 text, NUL bytes at every other byte from byte 1); save it"),
    (lambda s: bytes(range(256)) * 4, "looks like binary data, byte 0x00 at byte 0); the reader takes text"),
])
def test_utf16_and_binary_files_are_named_as_such(tmp_path, capsys, encode, what):
    f = tmp_path / "sine_config_60.txt"
    f.write_bytes(encode(csv_text()))
    assert refused([str(f.with_name("r.csv"))], capsys).endswith("no such file")
    f.with_name("r.csv").write_bytes(f.read_bytes())
    expected = f"{f.with_name('r.csv')}: not a UTF-8 text file ({what}"
    assert refused([str(f.with_name("r.csv"))], capsys).startswith(expected)
    assert refused([str(f.with_name("r.csv")), "--route", str(f.with_name("r.csv"))], capsys).startswith(
        f"--route {expected}")
    assert refused([str(f.with_name("r.csv")), "--bend", "60"], capsys).startswith(expected)
    assert refused(["--kaist", str(tmp_path)], capsys).startswith(
        f"no readable KAIST recording: {f}: not a UTF-8 text file ({what}")


def test_a_byte_of_another_encoding_names_its_line(tmp_path, capsys):
    f = tmp_path / "r.csv"
    lines = csv_text().encode().splitlines(keepends=True)
    lines[7] = lines[7].replace(b"\n", b"\xb0\n")
    f.write_bytes(b"".join(lines))
    assert refused([str(f)], capsys) == (
        f"{f}:8: not a UTF-8 text file (byte 0xb0 at byte {sum(map(len, lines[:8])) - 2} is not UTF-8: text in "
        "another encoding such as Latin-1?); save it as UTF-8")
    f.write_bytes(b"\xef\xbb\xbf" + csv_text(3000).encode())      # a UTF-8 byte-order mark is read past
    assert main(["analyze", str(f)]) == 0 and capsys.readouterr().out.startswith(f"{f}: 3000 samples")


def test_mrd_runs_that_are_not_text_or_not_finite_are_named_with_their_line(tmp_path):
    from estimator.errors import DataError
    from recorded.mrd import read_mrd
    f = tmp_path / "00.TXT"
    rows = [f"{0.001 * i:.3f},{i},0,0,{i},0,0.1,0,0,0" for i in range(2100)]
    f.write_text("%header\n" + "\n".join(rows) + "\n")
    f.write_bytes(f.read_text().encode("utf-16"))
    with pytest.raises(DataError, match=r"00\.TXT: not a UTF-8 text file \(looks like UTF-16 text"):
        read_mrd(f)
    rows[5] = rows[5].replace(",0.1,", ",inf,")
    f.write_text("%header\n" + "\n".join(rows) + "\n")
    with pytest.raises(DataError, match=r"00\.TXT:7: column 6: expected a finite number, got inf$"):
        read_mrd(f)
    rows[5], rows[9] = rows[5].replace(",inf,", ",0.1,"), "0.001" + rows[9][rows[9].index(","):]
    f.write_text("%header\n" + "\n".join(rows) + "\n")
    with pytest.raises(DataError, match=r"00\.TXT:11: column 0: time 0\.001 is not after the previous 0\.008"):
        read_mrd(f)


def with_value(text: str, row: int, col: int, value: str) -> str:
    """``text`` (a CSV made by csv_text) with data row ``row`` (0-based; line row + 3) column ``col`` set."""
    lines = text.splitlines()
    fields = lines[row + 2].split(",")
    fields[col] = value
    lines[row + 2] = ",".join(fields)
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("col, value, words", [
    (2, "1e308", "column 3 ('T_in'): 1e+308 N is beyond any tension (|T_in| <= 1e+06 N): a value in other units "
                 "or a corrupt row; fix or remove that row"),
    (4, "-1e200", "column 5 ('T_out'): -1e+200 N is beyond any tension (|T_out| <= 1e+06 N)"),
    (1, "100", "column 2 ('x_in'): 100.0 m is beyond any tendon position (|x_in| <= 10 m)"),
    (0, "1e308", "column 1 ('time'): 1e+308 s is beyond any time stamp (|time| <= 1e+10 s)"),
    (2, "inf", "column 3 ('T_in'): expected a finite number, got inf"),
    (3, "-Infinity", "column 4 ('x_out'): expected a finite number, got -inf"),
])
def test_a_value_out_of_range_names_its_line_and_column(tmp_path, capsys, col, value, words):
    f = tmp_path / "r.csv"
    f.write_text(with_value(csv_text(), 20, col, value))
    assert refused([str(f)], capsys).startswith(f"{f}:23: {words}")


def test_values_that_break_the_diagnosis_name_the_farthest_value(tmp_path, capsys, monkeypatch):
    """Values within range that still make the arithmetic fail (an overflow, a division by zero) are named by the
    value farthest out of its column."""
    from study import analyze
    f = tmp_path / "r.csv"
    f.write_text(with_value(csv_text(), 30, 4, "9e5"))
    for exc in (ZeroDivisionError("division by zero"), ValueError("array must not contain infs or NaNs"),
                OverflowError((34, "Numerical result out of range"))):
        def fail(*args, exc=exc, **kw):
            raise exc
        monkeypatch.setattr(analyze, "diagnose_recording", fail)
        msg = refused([str(f)], capsys)
        assert msg.startswith(f"{f}:33: column 5 ('T_out'): the diagnosis fails on this file's values "
                              f"({type(exc).__name__}: {' '.join(str(exc).split())}); T_out = 900000 N here stands ")
        assert msg.endswith("times the column's spread from its median: fix or remove that row")


def test_a_kaist_value_out_of_range_names_its_line_and_column(tmp_path, capsys):
    f = tmp_path / "pair.txt"
    rows = [f"{0.01 * i:.2f}, {i % 7}, 0, {i % 5}, 5, 5, 0, 0" for i in range(40)]
    rows[12] = rows[12].replace(", 5, 5,", ", 5, 1e300,")
    f.write_text("\n".join(rows) + "\n")
    assert refused([str(f), "--bend", "0"], capsys) == (
        f"{f}:13: column 5 (T_b): 1e+300 N is beyond any tension (|T_b| <= 1e+06 N): a corrupt row or another "
        "unit; fix or remove that row")
    f.write_text("\n".join(rows).replace(", 1e300,", ", 5,").replace("0.12, 5", "0.12, 2e4") + "\n")
    assert refused([str(f), "--bend", "0", "--columns", "time=0,command=1,angle=3,T_a=4,T_b=5,units=rad"],
                   capsys) == (f"{f}:13: column 1 (command): 20000.0 rad is beyond any joint angle (|command| <= "
                               "174.533 rad): a corrupt row or another unit; fix or remove that row")


def test_an_mrd_folder_of_one_run_says_why_a_run_calibration_cannot_score_it(tmp_path, capsys):
    """One usable run: the run calibration (default) has nothing left to score, said in one line; the segment
    calibration analyses the run (no folder-wide fit, which needs two runs)."""
    from tests.study.test_mrd import simulate, write_txt
    d = tmp_path / "Tool_X"
    d.mkdir()
    t, c, tp, th, td = simulate(freq=0.5, duration=6.0)
    write_txt(d / "00.TXT", t, c, tp, th, td)
    assert refused(["--mrd", str(d)], capsys) == (
        f"{d}: one run to analyse (00), and a run calibration scores the other runs: give a folder of two runs or "
        "more, or calibrate on the run's first seconds and score the rest with --calibration segment:SECONDS (e.g. "
        "segment:2)")
    assert refused(["--mrd", str(d), "--calibration", "kinematic:00"], capsys).startswith(
        f"{d}: one run to analyse (00)")
    out = tmp_path / "one.json"
    assert main(["analyze", "--mrd", str(d), "--calibration", "segment:2", "--json", str(out)]) == 0
    cap = capsys.readouterr()
    assert "found 1 runs" in cap.out and "calibrated on the first 2 s of each run" in cap.out and cap.err == ""
    summary = json.loads(out.read_text())
    assert set(summary["runs"]) == {"00"} and "shared" not in summary and "loro" not in summary


def test_the_windows_summary_of_a_segment_calibration_says_what_it_calibrated_on():
    from study.mrd.windows import format_across
    across = {"windows": 2, "scored_runs": 4, "median_torque_rmse_fs": 0.02, "max_torque_rmse_fs": 0.05,
              "max_torque_max_fs": 0.2, "better_than_linear_every_run": True, "window_medians": [0.02, 0.03],
              "window_worst": [0.04, 0.05]}
    windows = [{"label": "0..60 deg (--runs '1*')", "summary": {"calibration": {"mode": "segment", "seconds": 5.0}}},
               {"label": "30..90 deg (--runs '0*')", "summary": {"calibration": {"mode": "run", "run": "00"}}}]
    lines = format_across({"across": across, "windows": windows}).splitlines()
    assert "calibrated on the first 5 s of each run RMSE median 0.020 worst 0.040" in lines[1]
    assert "calibrated on 00     RMSE median 0.030 worst 0.050" in lines[2]


def test_an_mrd_value_out_of_range_and_a_fit_it_spoils_are_named(tmp_path, capsys, monkeypatch):
    """A value beyond anything the rig reads is refused with its line and column; a fit that fails on values
    within range names the value farthest out of its column."""
    from study.mrd import report as mrd_report
    from tests.study.test_mrd import simulate, write_txt
    d = tmp_path / "Tool_X"
    d.mkdir()
    t, c, tp, th, td = simulate(freq=0.5, duration=3.0)
    write_txt(d / "00.TXT", t, c, tp, th, td)
    lines = write_txt(d / "01.TXT", t, c, tp, th, td).read_text().splitlines()
    fields = lines[701].split(",")                      # line 702: data row 700 after the two header lines
    fields[2] = "2e7"
    (d / "01.TXT").write_text("\n".join(lines[:701] + [",".join(fields)] + lines[702:]) + "\n")
    from estimator.errors import DataError
    from recorded.mrd import read_mrd
    with pytest.raises(DataError, match=r"01\.TXT:702: column 2: 20000000\.0 counts is beyond anything the rig "
                                        r"reads \(\|value\| <= 1e\+07 counts\): a corrupt row; "
                                        r"fix or remove that row$"):
        read_mrd(d / "01.TXT")
    fields[2] = "9e6"
    (d / "01.TXT").write_text("\n".join(lines[:701] + [",".join(fields)] + lines[702:]) + "\n")

    def spoiled(args):
        raise ValueError("Each lower bound must be strictly less than each upper bound.")
    monkeypatch.setattr(mrd_report, "main_mrd", spoiled)
    msg = refused(["--mrd", str(d)], capsys)
    assert msg.startswith(f"{d}: the analysis fails on the runs' values (ValueError: Each lower bound must be "
                          f"strictly less than each upper bound.); the value farthest out is at {d / '01.TXT'}:702: "
                          "column 2 = 9e+06 counts, ")
    assert msg.endswith(" times the column's spread from its median: fix or remove that row")


def test_the_physical_bounds_are_the_analysis_not_every_readers(tmp_path, capsys):
    from teleop.recording.measured_csv import MAX_MAGNITUDE, read_measured_csv
    f = tmp_path / "r.csv"
    f.write_text(with_value(csv_text(), 20, 1, "100"))
    assert read_measured_csv(f).x_in[20] == 100.0                      # a synthetic or replayed CSV reads
    with pytest.raises(ValueError, match=r"r\.csv:23: column 2 \('x_in'\): 100\.0 m is beyond any tendon position"):
        read_measured_csv(f, limits=MAX_MAGNITUDE)
    assert refused([str(f)], capsys).startswith(f"{f}:23: column 2 ('x_in'): 100.0 m is beyond")
