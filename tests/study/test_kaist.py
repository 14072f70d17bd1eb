"""KAIST importer: synthetic files in the KAIST layout, and the real data when it is present."""
from __future__ import annotations

import math

import numpy as np
import pytest

from estimator.errors import DataError
from recorded.folders import KAIST, skip_reason
from recorded.kaist import CONFIGS_DEG, cycles, load_all, read_kaist
from recorded.kaist_files import default_kaist_dir
from recorded.kaist_files import find_configs
from recorded.kaist_files import find_kaist_dir
from recorded.kaist_files import is_kaist_file

KAIST_DIR = default_kaist_dir()
needs_kaist = pytest.mark.skipif(not find_configs(KAIST_DIR), reason=skip_reason(KAIST, KAIST_DIR))


def _row(t, cmd, vel, ang, ta, tb, ma, mb):
    return f"{t:.6f}, {cmd:.6f}, {vel:.6f}, {ang:.6f}, {ta:.6f}, {tb:.6f}, {ma:.6f}, {mb:.6f} \n"


def write_sine(path, n_stamps=520, repeats=3, dt=0.025, amp_deg=60.0):
    """A KAIST-like file: 2+ sine cycles of period 2 pi s, each time stamp written ``repeats`` times."""
    lines = []
    for k in range(n_stamps):
        t = k * dt
        cmd = amp_deg * math.sin(t)
        for r in range(repeats):
            lines.append(_row(t, cmd, 1500.0, 0.5 * cmd + r, 5.0 + cmd / 20, 5.0 - cmd / 20, 100.0, -100.0))
    path.write_text("".join(lines))
    return path


def test_duplicates_dropped_first_row_kept_and_units_converted(tmp_path):
    p = tmp_path / "sine_config_60.txt"
    p.write_text(_row(0.0, 0.0, 0.0, -0.5, 4.98, 5.01, 256.0, 273.0)
                 + _row(0.025, 1.5, 1500.0, 2.0, 5.1, 4.9, 1.0, 2.0)
                 + _row(0.025, 1.5, 1500.0, 9.0, 5.2, 4.8, 1.0, 2.0)       # same time: dropped
                 + _row(0.05, 3.0, 1498.9, 4.0, 5.3, 4.7, 3.0, 4.0))
    rec = read_kaist(p)
    assert rec.config_deg == 60
    assert len(rec) == 3
    np.testing.assert_allclose(rec.time, [0.0, 0.025, 0.05])
    np.testing.assert_allclose(rec.command, np.radians([0.0, 1.5, 3.0]))
    np.testing.assert_allclose(rec.angle, np.radians([-0.5, 2.0, 4.0]))   # 9.0 came from a dropped row
    np.testing.assert_allclose(rec.T_a, [4.98, 5.1, 5.3])                  # N, unchanged
    np.testing.assert_allclose(rec.velocity_cmd, [0.0, 1500.0, 1498.9])    # raw
    assert rec.pretension == pytest.approx((4.98, 5.01))


def test_malformed_row_names_file_and_line(tmp_path):
    p = write_sine(tmp_path / "sine_config_0.txt", n_stamps=10, repeats=1)
    lines = p.read_text().splitlines(keepends=True)
    lines[4] = "0.100000, 1.0, abc, 0.0, 5.0, 5.0, 1.0, 1.0, \n"
    p.write_text("".join(lines))
    with pytest.raises(DataError, match=r"sine_config_0\.txt:5: column 2: expected a number, got 'abc'"):
        read_kaist(p)
    lines[4] = "0.100000, 1.0, 2.0, 0.0, 5.0, \n"
    p.write_text("".join(lines))
    with pytest.raises(DataError, match=r"sine_config_0\.txt:5: expected 8 comma-separated numbers"):
        read_kaist(p)
    lines[4] = "0.100000, nan, 2.0, 0.0, 5.0, 5.0, 1.0, 1.0, \n"
    p.write_text("".join(lines))
    with pytest.raises(DataError, match=r":5: column 1: expected a finite number"):
        read_kaist(p)
    lines[4] = "0.100000, 1.0, 2.0, 0.0, 5.0, 5.0, 1.0, 1.0, \n"
    p.write_text("".join(lines) + "0.250000, 1.0, 2.0, 0.0, 5.\n")                # logger stopped mid-line
    rec = read_kaist(p)
    assert len(rec) == 10 and any("the last line (11) is cut short" in n for n in rec.notes)


def test_time_reset_near_the_end_is_cut_and_one_in_the_middle_stitched(tmp_path):
    p = write_sine(tmp_path / "sine_config_0.txt", n_stamps=100, repeats=2)
    text = p.read_text().splitlines(keepends=True)
    tail = [_row(0.025 * k, 1.0, 0.0, 1.0, 5.0, 5.0, 1.0, 1.0) for k in range(10)]     # logger restarted
    p.write_text("".join(text + tail))
    rec = read_kaist(p)
    assert len(rec) == 100 and rec.time[-1] == pytest.approx(99 * 0.025)
    assert any(n.startswith("WARNING time reset at line 201") and "10 rows" in n for n in rec.notes)
    q = tmp_path / "sine_config_5.txt"                                       # reset half way: stitched
    rows = [_row(0.025 * (k % 50), 0.1 * k, 0.0, 0.05 * k, 5.0, 5.0, 0.0, 0.0) for k in range(100)]
    q.write_text("".join(rows))
    rec = read_kaist(q)
    assert len(rec) == 100 and np.all(np.diff(rec.time) > 0)
    np.testing.assert_allclose(np.diff(rec.time), 0.025)                    # continues at the median step
    np.testing.assert_allclose(np.degrees(rec.command), 0.1 * np.arange(100))
    assert any("stitched" in n for n in rec.notes)
    assert any("all-zero column(s) 2, 6, 7" in n for n in rec.notes)
    assert np.all(np.isnan(rec.motor_a))                                     # an all-zero optional column is left out


def write_long(path, rate=2000.0, seconds=13.0, reset_at=12.5, repeats=2, zero_cols=(8, 9)):
    """A 10-column long KAIST-like recording: rate Hz, each stamp written ``repeats`` times, two
    all-zero columns, the logger clock reset at ``reset_at`` s (the rest written from 0 again)."""
    t = np.arange(0.0, seconds, 1.0 / rate)
    cmd = 60.0 * np.sin(t)
    ang = 0.5 * cmd
    cols = [t, cmd, np.gradient(cmd), ang, 5 + cmd / 20, 5 - cmd / 20, 100 + 0 * t, -100 + 0 * t, 0 * t, 0 * t]
    a = np.column_stack(cols)
    cut = int(reset_at * rate)
    a[cut:, 0] -= a[cut, 0]                                                   # time reset near the end
    for j in zero_cols:
        a[:, j] = 0.0
    a = np.repeat(a, repeats, axis=0)
    path.write_text("".join(", ".join(f"{v:.6f}" for v in r) + ", \n" for r in a))
    return path


def test_long_10_column_recording_read_with_the_same_importer(tmp_path):
    from recorded.columns import parse_column_map
    p = write_long(tmp_path / "sine_config_90.txt")
    rec = read_kaist(p)                                       # no map: the 8-column KAIST map, a note says so
    assert rec.config_deg == 90
    notes = " | ".join(rec.notes)
    assert "10 columns, no column map given" in notes and "columns 8, 9 not used" in notes
    assert "repeat the previous time stamp" in notes and "WARNING time reset" in notes and "cut off" in notes
    assert "all-zero column(s) 8, 9" in notes and "resampled from 2000 Hz to 40 Hz" in notes
    assert rec.rate_hz == pytest.approx(40.0, rel=0.01) and rec.time[-1] < 12.5
    np.testing.assert_allclose(np.degrees(rec.angle), 0.5 * np.degrees(rec.command), atol=1e-6)
    assert len(cycles(rec)) == 1                              # 12.5 s of a 2 pi s sine after the cut
    full = read_kaist(p, rate_hz=None)
    assert full.rate_hz == pytest.approx(2000.0, rel=0.01)
    m = parse_column_map("time=0,command=1,angle=3,T_a=4,T_b=5")
    rec2 = read_kaist(p, column_map=m)
    assert rec2.notes[0] == "columns used: time=0,command=1,angle=3,T_a=4,T_b=5"
    assert np.all(np.isnan(rec2.motor_a))
    with pytest.raises(DataError, match=r"angle \(column 8\) all zero: wrong column map"):
        read_kaist(p, column_map=parse_column_map("time=0,command=1,angle=8,T_a=4,T_b=5"))
    with pytest.raises(DataError, match="the column map asks for angle=12"):
        read_kaist(p, column_map=parse_column_map("time=0,command=1,angle=12,T_a=4,T_b=5"))


def test_generic_csv_with_header_and_column_map(tmp_path):
    from recorded.columns import parse_column_map
    p = tmp_path / "lab.csv"
    t = np.arange(0, 2.0, 0.01)
    p.write_text("t;T_A;T_B;cmd_rad;tip_rad\n" + "".join(
        f"{a:.3f};{d:.3f};{e:.3f};{b:.5f};{c:.5f}\n"
        for a, b, c, d, e in zip(t, np.sin(t), 0.4 * np.sin(t), 5 + t, 5 - t, strict=False)))
    rec = read_kaist(p, 30, parse_column_map("time=0,T_a=1,T_b=2,command=3,angle=4,units=rad"), rate_hz=None)
    assert rec.config_deg == 30 and len(rec) == t.size
    np.testing.assert_allclose(rec.command, np.sin(t), atol=1e-5)
    np.testing.assert_allclose(rec.T_b, 5 - t, atol=1e-3)
    assert "line 1 read as a header and skipped" in rec.notes
    assert len(read_kaist(p, 30, parse_column_map("time=0,T_a=1,T_b=2,command=3,angle=4,units=rad"))) == 80  # 40 Hz
    from teleop.errors import ConfigError
    for bad, msg in (("time=0,command=1", "missing angle, T_a, T_b"), ("time=0,x=1", "unknown field 'x'"),
                     ("time=a", "0-based integer"), ("time=0,command=0", "mapped twice"),
                     ("time=0,command=1,angle=2,T_a=3,T_b=4,units=grad", "units must be deg or rad"),
                     ("time0", "not name=column")):
        with pytest.raises(ConfigError, match=msg):
            parse_column_map(bad)


def test_missing_file_and_directory_are_named(tmp_path):
    from recorded.kaist import load_dir
    from recorded.kaist_files import find_configs
    with pytest.raises(DataError, match=r"sine_config_0\.txt: no such file"):
        read_kaist(tmp_path / "sine_config_0.txt")
    with pytest.raises(DataError, match=r"no KAIST recordings found under .*nowhere \(no such folder\): expected "
                                        r"optimization/selected/<N>\.txt .*see docs/how-to/get-the-data\.md"):
        find_kaist_dir(tmp_path / "nowhere")
    write_sine(tmp_path / "sine_config_0.txt", n_stamps=10)
    write_sine(tmp_path / "sine_config_120.txt", n_stamps=10)
    with pytest.raises(DataError, match=r"missing KAIST file\(s\) sine_config_60\.txt, sine_config_180\.txt, "
                                        r"sine_config_240\.txt"):
        load_all(tmp_path)
    with pytest.raises(DataError, match=r"not sine_config_<N>.txt and no bend was given \(--bend DEG\)"):
        read_kaist(write_sine(tmp_path / "other.txt", n_stamps=10))
    assert read_kaist(tmp_path / "other.txt", 75).config_deg == 75
    assert is_kaist_file("/a/b/sine_config_180.txt") and not is_kaist_file("run.csv")
    # any N in the directory, sorted; a malformed file is one line and left out
    write_sine(tmp_path / "sine_config_300.txt", n_stamps=10)
    (tmp_path / "sine_config_45.txt").write_text("0.0, 1.0\n")
    assert [n for n, _ in find_configs(tmp_path)] == [0, 45, 120, 300]
    recs, problems = load_dir(tmp_path)
    assert [r.config_deg for r in recs] == [0, 120, 300]
    assert len(problems) == 1 and problems[0].startswith(str(tmp_path / "sine_config_45.txt")) \
        and "\n" not in problems[0]


def test_source_repository_layout_is_read_in_place(tmp_path):
    """A clone's optimization/selected/ names its files <N>.txt beside other recordings (conf0_60.txt):
    read the numbered ones when the folder has no sine_config_<N>.txt; the project's names win."""
    from recorded.kaist import load_dir
    from recorded.kaist_files import find_configs
    for n in (30, 270, 90):
        write_sine(tmp_path / f"{n}.txt", n_stamps=10)
    write_sine(tmp_path / "conf0_60.txt", n_stamps=10)
    assert [n for n, _ in find_configs(tmp_path)] == [30, 90, 270]
    recs, problems = load_dir(tmp_path)
    assert [r.config_deg for r in recs] == [30, 90, 270] and not problems
    write_sine(tmp_path / "sine_config_0.txt", n_stamps=10)
    assert [n for n, _ in find_configs(tmp_path)] == [0]


def test_cycles_split_at_upward_zero_crossings(tmp_path):
    rec = read_kaist(write_sine(tmp_path / "sine_config_0.txt"))
    cs = cycles(rec)
    assert len(cs) == 2                                       # 13 s of a 2 pi s sine: 2 complete cycles
    assert cs[0].start == 0 and cs[0].stop == cs[1].start
    for s in cs:                                              # stop is the next cycle's first sample
        assert rec.time[s.stop] - rec.time[s.start] == pytest.approx(2 * math.pi, abs=0.03)
    assert rec.time[cs[1].start] == pytest.approx(2 * math.pi, abs=0.03)


@needs_kaist
@pytest.mark.kaist
def test_real_data_five_configurations():
    recs = load_all(KAIST_DIR)
    assert [r.config_deg for r in recs] == list(CONFIGS_DEG)
    for r in recs:
        assert 500 <= len(r) <= 525                            # ~510 distinct time stamps
        assert np.all(np.diff(r.time) > 0)
        assert np.allclose(np.diff(r.time), 0.025, atol=1e-6)  # 40 Hz
        assert np.degrees(np.abs(r.command).max()) == pytest.approx(60.0, abs=0.01)
        assert r.pretension == pytest.approx((5.0, 5.0), abs=0.1)
        cs = cycles(r)
        assert len(cs) == 2
        assert all(r.time[s.stop - 1] - r.time[s.start] == pytest.approx(6.28, abs=0.1) for s in cs)
    # the distal range shrinks as the tube bends more (SOURCE.md): ~37 deg at N=0, ~10 deg at N=240
    ranges = [np.degrees(np.ptp(r.angle)) / 2 for r in recs]
    assert all(a > b for a, b in zip(ranges, ranges[1:], strict=False))
