"""Measured-data CSV: round trip, metadata, load errors with file/line/column, recorder exits."""
from __future__ import annotations

import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from estimator.data import MeasuredData
from estimator.errors import DataError
from teleop.recording.measured import CsvRecorder, Terminated, raise_on_sigterm, write_measured_csv
from teleop.recording.measured_csv import read_measured_csv


def _write(path: Path, text: str) -> Path:
    path.write_text(textwrap.dedent(text).lstrip("\n"), encoding="utf-8")
    return path


def _full_data(n: int = 50) -> MeasuredData:
    rng = np.random.default_rng(1)
    t = np.cumsum(rng.uniform(1e-4, 2e-3, n)) + 12.5
    x_in = rng.normal(0, 3e-3, n)
    return MeasuredData(time=t, x_in=x_in, T_in=rng.uniform(0, 40, n),
                        x_out=x_in - rng.uniform(0, 1e-3, n), T_out=rng.uniform(0, 30, n),
                        extra={"marker": rng.integers(0, 3, n).astype(float),
                               "motor_current": rng.normal(0, 0.5, n)},
                        metadata={"rig": "bench-2", "operator": "A. B."}, source="mem")


# ---- round trip, metadata, columns ---------------------------------------------------------

def test_round_trip_equal_within_float_formatting(tmp_path):
    data = _full_data()
    path = tmp_path / "run" / "x.csv"
    write_measured_csv(path, data)
    back = read_measured_csv(path)
    assert len(back) == len(data)
    np.testing.assert_allclose(back.time, data.time, rtol=1e-11, atol=0)
    for name in ("x_in", "T_in", "x_out", "T_out"):
        np.testing.assert_allclose(getattr(back, name), getattr(data, name), rtol=1e-8, atol=0)
    assert list(back.extra) == ["marker", "motor_current"]
    np.testing.assert_array_equal(back.extra["marker"], data.extra["marker"])
    np.testing.assert_allclose(back.extra["motor_current"], data.extra["motor_current"], rtol=1e-8)
    assert back.metadata["rig"] == "bench-2" and back.metadata["operator"] == "A. B."
    assert back.metadata["units"] == "time=s, x_in=m, T_in=N, x_out=m, T_out=N"
    assert back.source == str(path)
    np.testing.assert_allclose(back.elongation, data.x_in - data.x_out, rtol=1e-6, atol=1e-12)


def test_file_layout_metadata_then_units_then_header(tmp_path):
    path = tmp_path / "r.csv"
    with CsvRecorder(path, ["time", "x_in", "T_in", "current"], {"rig": "r1"},
                     units={"current": "A"}) as rec:
        rec.write([0.0, 1e-3, 2.5, 0.1])
    lines = path.read_text().splitlines()
    assert lines[:3] == ["# rig: r1", "# units: time=s, x_in=m, T_in=N, current=A",
                         "time,x_in,T_in,current"]
    assert lines[3] == "0,0.001,2.5,0.1"


def test_metadata_comments_blank_lines_and_extra_columns(tmp_path):
    path = _write(tmp_path / "m.csv", """
        # rig: kaist-1
        # just a comment, no key
        #date:2024-05-01
        # note: pulled twice: then released

        time, x_in ,T_in,temperature
        0.0,0.0,1.0,21.5
        # a comment between rows is skipped
        0.1,1e-3,2.0,21.6

        0.2,2e-3,3.0,21.7
    """)
    data = read_measured_csv(path)
    assert data.metadata == {"rig": "kaist-1", "date": "2024-05-01",
                             "note": "pulled twice: then released"}
    np.testing.assert_array_equal(data.x_in, [0.0, 1e-3, 2e-3])
    np.testing.assert_array_equal(data.extra["temperature"], [21.5, 21.6, 21.7])
    assert data.x_out is None and data.T_out is None and data.elongation is None
    assert list(data.columns()) == ["time", "x_in", "T_in", "temperature"]


def test_require_distal(tmp_path):
    path = _write(tmp_path / "p.csv", "time,x_in,T_in\n0,0,1\n1,0,2\n")
    data = read_measured_csv(path)
    with pytest.raises(DataError, match=r"p\.csv: needs a distal column 'x_out' or 'T_out' "
                                        r"\(have: time, x_in, T_in\)"):
        data.require_distal()
    with_t_out = _write(tmp_path / "q.csv", "time,x_in,T_in,T_out\n0,0,1,1\n1,0,2,1.5\n")
    assert read_measured_csv(with_t_out).require_distal().T_out.tolist() == [1.0, 1.5]


def test_slice_duration_and_shape_check():
    data = _full_data(20)
    part = data.slice(5, 9)
    assert len(part) == 4
    np.testing.assert_array_equal(part.T_out, data.T_out[5:9])
    np.testing.assert_array_equal(part.extra["marker"], data.extra["marker"][5:9])
    assert part.duration == pytest.approx(data.time[8] - data.time[5])
    assert part.metadata == data.metadata and part.source == data.source
    with pytest.raises(DataError, match=r"mem: column 'T_in' has shape \(3,\), expected \(4,\)"):
        MeasuredData(np.arange(4.0), np.zeros(4), np.zeros(3), source="mem")


# ---- load errors: each names the file and the line / column --------------------------------

GOOD_HEAD = "# rig: r\ntime,x_in,T_in\n"
INCREASING = "(must be strictly increasing)"
EMPTY = ": empty file (expected a header line of column names)"


@pytest.mark.parametrize("body, expected", [
    # (data after the 2 head lines, so the first data row is line 3)
    ("0,0,1\n0.1,abc,2\n", ":4: column 2 ('x_in'): expected a number, got 'abc'"),
    ("0,0,1\n0.1,,2\n", ":4: column 2 ('x_in'): expected a number, got ''"),
    ("0,0,1\n0.1,0,2,7\n", ":4: expected 3 values (time, x_in, T_in), found 4"),
    ("0,0,1\n0.1,0\n", ":4: expected 3 values (time, x_in, T_in), found 2"),
    ("0,0,1\n0.1,0,2\n0.2,nan,3\n", ":5: column 2 ('x_in'): expected a finite number, got nan"),
    ("0,0,1\n# c\n\n0.1,0,2\n0.2,0,inf\n",
     ":7: column 3 ('T_in'): expected a finite number, got inf"),
    ("0,0,1\n0.1,0,2\n0.1,0,3\n",
     ":5: column 1 ('time'): time 0.1 s is not after the previous 0.1 s " + INCREASING),
    ("0,0,1\n0.3,0,2\n# gap\n0.2,0,3\n",
     ":6: column 1 ('time'): time 0.2 s is not after the previous 0.3 s " + INCREASING),
    ("0,0,1\n", ": 1 data row(s), need at least 2"),
    ("", ": 0 data row(s), need at least 2"),
])
def test_data_errors_name_file_line_column(tmp_path, body, expected):
    path = _write(tmp_path / "bad.csv", GOOD_HEAD + body)
    with pytest.raises(DataError) as err:
        read_measured_csv(path)
    assert str(err.value) == f"{path}{expected}"


@pytest.mark.parametrize("text, expected", [
    ("", EMPTY),
    ("# only: metadata\n\n# and comments\n", EMPTY),
    ("time,x_in\n0,0\n1,1\n", ": missing column 'T_in' (have: time, x_in)"),
    ("0,0,1\n1,0,2\n", ":1: expected a header line of column names, got numbers"),
    ("# a: 1\ntime,x_in,,T_in\n", ":2: header column 3 is empty"),
    ("time,x_in,T_in,x_in\n", ":1: header column 4: 'x_in' appears twice"),
    ("# a: 1\n# a: 2\ntime,x_in,T_in\n", ":2: metadata key 'a' given twice"),
    ("# units: time=s, x_in=mm, T_in=N\ntime,x_in,T_in\n0,0,1\n1,0,2\n",
     ": units: column 'x_in' is in 'mm', expected 'm' (convert to SI before loading)"),
])
def test_file_errors(tmp_path, text, expected):
    path = _write(tmp_path / "bad.csv", text)
    with pytest.raises(DataError) as err:
        read_measured_csv(path)
    assert str(err.value) == f"{path}{expected}"
    assert "\n" not in str(err.value)


def test_missing_file_and_exact_missing_column_message(tmp_path, monkeypatch):
    with pytest.raises(DataError, match=r"nowhere\.csv: no such file$"):
        read_measured_csv(tmp_path / "nowhere.csv")
    monkeypatch.chdir(tmp_path)
    Path("runs").mkdir()
    _write(Path("runs/x.csv"), "time,x_in\n0,0\n1,0\n")
    with pytest.raises(DataError) as err:
        read_measured_csv("runs/x.csv")
    assert str(err.value) == "runs/x.csv: missing column 'T_in' (have: time, x_in)"
    assert isinstance(err.value, ValueError)  # callers that only know builtins still catch it


# ---- recorder: buffering and every exit path ----------------------------------------------

COLS = ["time", "x_in", "T_in"]


def _rows(n: int, start: int = 0) -> list[list[float]]:
    return [[0.001 * i, 1e-5 * i, 2.0 + 0.5 * i] for i in range(start, start + n)]


def _n_rows_on_disk(path: Path) -> int:
    lines = path.read_text().splitlines()
    return sum(1 for ln in lines[lines.index(",".join(COLS)) + 1:] if ln and not ln.startswith("#"))


@pytest.mark.parametrize("exc", [RuntimeError("boom"), KeyboardInterrupt()])
def test_recorder_flushed_and_closed_on_exception(tmp_path, exc):
    path = tmp_path / "e.csv"
    with pytest.raises(type(exc)):
        with CsvRecorder(path, COLS, flush_every=1000) as rec:
            for row in _rows(10):
                rec.write(row)
            assert _n_rows_on_disk(path) == 0  # still buffered: only close() can save them
            raise exc
    assert rec.closed
    data = read_measured_csv(path)
    np.testing.assert_allclose(data.T_in, [r[2] for r in _rows(10)])


def test_recorder_flushed_on_sigterm_in_process(tmp_path):
    path = tmp_path / "s.csv"
    before = signal.getsignal(signal.SIGTERM)
    with pytest.raises(Terminated):
        with raise_on_sigterm(), CsvRecorder(path, COLS, flush_every=1000) as rec:
            rec.write_many(np.array(_rows(7)))
            signal.raise_signal(signal.SIGTERM)
            pytest.fail("SIGTERM did not interrupt the block")
    assert signal.getsignal(signal.SIGTERM) is before
    assert len(read_measured_csv(path)) == 7


def test_recorder_flushed_when_process_gets_sigterm(tmp_path):
    path = tmp_path / "child.csv"
    script = textwrap.dedent(f"""
        import sys
        from teleop.recording.measured import CsvRecorder, Terminated, raise_on_sigterm
        try:
            with raise_on_sigterm(), CsvRecorder({str(path)!r}, {COLS!r}, flush_every=1000) as rec:
                for i in range(5):
                    rec.write([0.01 * i, 0.0, 1.0 + i])
                print("ready", flush=True)
                sys.stdin.readline()  # blocks until the parent terminates us
        except Terminated:
            sys.exit(143)
    """)
    child = subprocess.Popen([sys.executable, "-c", script], stdin=subprocess.PIPE,
                             stdout=subprocess.PIPE, text=True)
    try:
        assert child.stdout.readline().strip() == "ready"
        assert _n_rows_on_disk(path) == 0
        child.terminate()
        assert child.wait(timeout=60) == 143
    finally:
        if child.poll() is None:
            child.kill()
        child.stdin.close()
        child.stdout.close()
    np.testing.assert_array_equal(read_measured_csv(path).T_in, [1.0, 2.0, 3.0, 4.0, 5.0])


def test_partially_written_file_is_readable(tmp_path):
    path = tmp_path / "p.csv"
    rec = CsvRecorder(path, COLS, {"rig": "sim"}, flush_every=4)
    for row in _rows(10):
        rec.write(row)
    partial = read_measured_csv(path)  # flushed after rows 4 and 8; the recorder is still open
    assert len(partial) == 8 and partial.metadata["rig"] == "sim"
    rec.flush()
    assert len(read_measured_csv(path)) == 10
    rec.write_many(np.array(_rows(3, start=10)))
    rec.close()
    rec.close()  # idempotent
    assert len(read_measured_csv(path)) == 13 and rec.rows_written == 13


def test_recorder_rejects_bad_use(tmp_path):
    path = tmp_path / "r.csv"
    with CsvRecorder(path, COLS) as rec:
        with pytest.raises(ValueError, match=r"\(1, 2\), expected \(n, 3\) for time, x_in, T_in"):
            rec.write([0.0, 1.0])
        with pytest.raises(ValueError, match=r"row 0, column .T_in.: non-finite value nan"):
            rec.write([0.0, 1.0, float("nan")])
        with pytest.raises(ValueError, match=r"rows have shape \(2, 2\), expected \(n, 3\)"):
            rec.write_many(np.zeros((2, 2)))
        with pytest.raises(ValueError, match=r"row 1, column 'x_in': non-finite value"):
            rec.write_many(np.array([[0.0, 0.0, 0.0], [1.0, np.inf, 0.0]]))
    with pytest.raises(ValueError, match="recorder is closed"):
        rec.write([0.0, 0.0, 0.0])
    with pytest.raises(FileExistsError):
        CsvRecorder(path, COLS)
    CsvRecorder(path, COLS, overwrite=True).close()
    for bad, named in ((dict(columns=["time", "time"]), "('time', 'time')"),
                       (dict(columns=["a,b"]), "'a,b'"), (dict(columns=[]), "columns ()"),
                       (dict(columns=COLS, metadata={"units": "x"}), "'units: x'"),
                       (dict(columns=COLS, flush_every=0), "flush_every 0"),
                       (dict(columns=COLS, units={"x_in": "mm"}), "'x_in=mm'"),
                       (dict(columns=COLS, metadata={"k": "a\nb"}), "'k: a\\nb'")):
        with pytest.raises(ValueError) as err:
            CsvRecorder(tmp_path / "other.csv", **bad)
        assert named in str(err.value) and not (tmp_path / "other.csv").exists()


def test_write_many_matches_write(tmp_path):
    rows = np.array(_rows(9000)) * np.array([1.0, 3.3, 1.7])
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    with CsvRecorder(a, COLS) as rec:
        for r in rows:
            rec.write(r)
    with CsvRecorder(b, COLS) as rec:
        rec.write_many(rows)
    assert a.read_text() == b.read_text()
