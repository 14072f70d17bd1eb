"""KAIST importer: synthetic files in the KAIST layout, and the real data when it is present."""
from __future__ import annotations

import math

import numpy as np
import pytest

from teleop.errors import DataError
from teleop.kaist import (CONFIGS_DEG, cycles, default_kaist_dir, find_kaist_dir, is_kaist_file,
                          load_all, read_kaist)

KAIST_DIR = default_kaist_dir()
needs_kaist = pytest.mark.skipif(
    not KAIST_DIR.is_dir(),
    reason=f"KAIST data not found at {KAIST_DIR}: these tests need the unlicensed measurements, "
           "see docs/findings.md")


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
    lines[4] = "0.010000, 1.0, 2.0, 0.0, 5.0, 5.0, 1.0, 1.0, \n"             # time goes back
    p.write_text("".join(lines))
    with pytest.raises(DataError, match=r":5: column 0: time 0.01 s goes back"):
        read_kaist(p)
    lines[4] = "0.100000, nan, 2.0, 0.0, 5.0, 5.0, 1.0, 1.0, \n"
    p.write_text("".join(lines))
    with pytest.raises(DataError, match=r":5: column 1: expected a finite number"):
        read_kaist(p)


def test_missing_file_and_directory_are_named(tmp_path):
    with pytest.raises(DataError, match=r"sine_config_0\.txt: no such file"):
        read_kaist(tmp_path / "sine_config_0.txt")
    with pytest.raises(DataError, match=r"KAIST data not found at .*these tests need the unlicensed"):
        find_kaist_dir(tmp_path / "nowhere")
    write_sine(tmp_path / "sine_config_0.txt", n_stamps=10)
    write_sine(tmp_path / "sine_config_120.txt", n_stamps=10)
    with pytest.raises(DataError, match=r"missing KAIST file\(s\) sine_config_60\.txt, sine_config_180\.txt, "
                                        r"sine_config_240\.txt"):
        load_all(tmp_path)
    with pytest.raises(DataError, match="not sine_config_<N>.txt"):
        read_kaist(write_sine(tmp_path / "other.txt", n_stamps=10))
    assert is_kaist_file("/a/b/sine_config_180.txt") and not is_kaist_file("run.csv")


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
    assert all(a > b for a, b in zip(ranges, ranges[1:]))
