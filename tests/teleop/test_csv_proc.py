"""ProcessCsvRecorder: rows queued by the loop reach the file in order, within the flush interval, formatted by a
child process; bad rows are skipped and counted instead of raised; nothing the child received is lost when the
side is killed, and a child gone makes an error line and counted rows, never an exception in the loop. Waits
are bounded and end when the rows are there."""
from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

from teleop.recording import csv_proc
from teleop.recording.csv_proc import ProcessCsvRecorder, wait_written
from teleop.recording.measured_csv import read_measured_csv

COLUMNS = ("time", "x_in", "T_in")


def _rows_on_disk(path) -> int:
    return sum(1 for ln in path.read_text().splitlines() if ln and not ln.startswith("#")) - 1


def _wait_rows(path, n: int, timeout: float = 10.0) -> int:
    deadline = time.monotonic() + timeout
    while _rows_on_disk(path) < n and time.monotonic() < deadline:
        time.sleep(0.01)
    return _rows_on_disk(path)


def test_rows_are_written_in_order_without_close_then_all_on_close(tmp_path):
    path = tmp_path / "a.csv"
    rec = ProcessCsvRecorder(path, COLUMNS, {"source": "test"}, flush_every=100_000, flush_interval=0.01)
    assert path.read_text().startswith("# source: test\n")          # the header is written before any row
    for k in range(500):
        rec.write((k * 1e-3, 1e-5 * k, 0.5 * k))
    assert _wait_rows(path, 500) == 500               # the child writes each batch it receives: no close needed
    assert not wait_written(path, timeout=0.05)                     # and holds the file while open
    rec.write_many(np.array([[0.5, 0.0, 1.0], [0.501, 0.0, 2.0]]))
    rec.close()
    rec.close()
    assert wait_written(path, timeout=0.0)
    assert rec.closed and rec.rows_written == 502 and rec.rejected == rec.dropped == 0 and rec.error is None
    data = read_measured_csv(path)
    assert data.time.size == 502 and np.all(np.diff(data.time) > 0)
    assert data.T_in[:500] == pytest.approx(0.5 * np.arange(500)) and data.T_in[-1] == 2.0
    with pytest.raises(ValueError, match="closed"):
        rec.write((1.0, 0.0, 0.0))


def test_flush_waits_until_the_rows_are_on_disk(tmp_path):
    path = tmp_path / "f.csv"
    with ProcessCsvRecorder(path, COLUMNS, flush_every=10_000, flush_interval=60.0) as rec:
        for k in range(30):
            rec.write((k * 1e-3, 0.0, float(k)))
        rec.flush()
        assert _rows_on_disk(path) == 30 and rec.rows_written == 30


def test_a_bad_row_is_skipped_and_counted_not_raised(tmp_path, caplog):
    path = tmp_path / "b.csv"
    with ProcessCsvRecorder(path, COLUMNS, flush_interval=0.01) as rec:
        rec.write((0.0, 0.0, 1.0))
        rec.write((0.001, math.nan, 1.0))        # a non-finite value
        rec.write((0.002, 0.0))                  # wrong length
        rec.write((0.0025, "x", 1.0))            # not a number
        rec.write((0.003, 0.0, 3.0))
    assert rec.rejected == 3 and rec.rows_written == 2
    data = read_measured_csv(path)
    assert list(data.T_in) == [1.0, 3.0]
    said = [r.getMessage() for r in caplog.records if "row skipped" in r.getMessage()]
    assert len(said) == 3 and "non-finite" in said[0] and "shape (1, 2)" in said[1]


def test_a_bad_setup_raises_before_any_process_starts(tmp_path):
    with pytest.raises(ValueError, match="flush_interval must be > 0"):
        ProcessCsvRecorder(tmp_path / "c.csv", COLUMNS, flush_interval=0.0)
    with pytest.raises(ValueError, match="bad recorder setup"):
        ProcessCsvRecorder(tmp_path / "c.csv", ("time", "x in"))
    (tmp_path / "d.csv").write_text("kept\n")
    with pytest.raises(FileExistsError):
        ProcessCsvRecorder(tmp_path / "d.csv", COLUMNS)
    assert (tmp_path / "d.csv").read_text() == "kept\n"


def test_wide_rows_are_sent_in_chunks_that_each_fit_the_loops_idle_time(tmp_path, monkeypatch):
    sizes: list[int] = []
    real = ProcessCsvRecorder._send
    monkeypatch.setattr(ProcessCsvRecorder, "_send", lambda self, msg, rows=0: (
        sizes.append(rows) if rows else None, real(self, msg, rows))[1])
    monkeypatch.setattr(csv_proc, "CHUNK_COST", 2e-5)
    columns = COLUMNS + tuple(f"c{k}" for k in range(92))             # a bimanual arm's width
    path = tmp_path / "wide.csv"
    rec = ProcessCsvRecorder(path, columns, flush_interval=60.0)     # only close() sends: one batch
    for k in range(100):
        rec.write((k * 1e-3,) + (float(k),) * 94)
    rec.close()
    per_chunk = int(csv_proc.CHUNK_COST / (csv_proc.VALUE_COST * len(columns)))
    assert sum(sizes) == 100 and max(sizes) <= per_chunk < 100 and len(sizes) >= 100 // per_chunk
    data = read_measured_csv(path)
    assert np.all(np.diff(data.time) > 0) and data.time.size == 100 and data.T_in == pytest.approx(np.arange(100.0))


def test_the_child_ignores_ctrl_c_and_a_child_gone_is_an_error_line_and_counted_rows(tmp_path, caplog):
    path = tmp_path / "g.csv"
    rec = ProcessCsvRecorder(path, COLUMNS, flush_interval=0.005)
    assert os.getpgid(rec._proc.pid) != os.getpgid(0)              # Ctrl-C at the terminal is the side's
    for k in range(20):
        if k == 10:
            rec.flush()
            os.kill(rec._proc.pid, signal.SIGINT)                   # and ignored by the child
        rec.write((k * 1e-3, 0.0, float(k)))
    rec.flush()
    assert _rows_on_disk(path) == 20 and rec._proc.poll() is None
    rec._proc.kill()
    rec._proc.wait(10)
    for k in range(20, 60):                                         # the loop goes on: nothing raises
        rec.write((k * 1e-3, 0.0, float(k)))
    rec.close()
    assert rec.dropped == 40 and "has ended" in (rec.error or "")
    assert sum("no longer written" in r.getMessage() for r in caplog.records) == 1
    assert read_measured_csv(path).time.size == 20


KILLED = textwrap.dedent("""
    import os, signal, sys
    from teleop.recording.csv_proc import ProcessCsvRecorder, wait_written
    rec = ProcessCsvRecorder(sys.argv[1], ("time", "x_in", "T_in"), flush_every=100_000, flush_interval=0.001)
    for k in range(300):
        rec.write((k * 1e-3, 0.0, float(k)))
    rec._drain()                                  # every row sent, none yet on disk (flush_every)
    os.kill(os.getpid(), signal.SIGKILL)
""")


def test_a_killed_side_loses_no_row_the_child_received(tmp_path):
    path = tmp_path / "k.csv"
    out = subprocess.run([sys.executable, "-c", KILLED, str(path)], capture_output=True, text=True, timeout=60)
    assert out.returncode == -signal.SIGKILL, out.stderr[-2000:]
    assert wait_written(path)                                       # the child: stdin ended, writes, lets go
    data = read_measured_csv(path)
    assert data.time.size == 300 and data.T_in == pytest.approx(np.arange(300.0))


def test_the_reports_of_the_child_are_json_lines(tmp_path):
    path = tmp_path / "w.csv"
    ProcessCsvRecorder(path, COLUMNS).close()                       # the header; the child appends
    proc = subprocess.Popen([sys.executable, "-m", "teleop.recording.csv_proc"], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE)
    import pickle
    wire = b"".join(pickle.dumps(m) for m in [(str(path), COLUMNS, 100), [(0.0, 0.0, 1.0), (1e-3, math.inf, 0.0)],
                                              "flush", [(2e-3, 0.0, 2.0)], None])
    out, _ = proc.communicate(wire, timeout=60)
    reports = [json.loads(ln) for ln in out.splitlines()]
    assert [r["event"] for r in reports] == ["ready", "warning", "flushed", "closed"]
    assert reports[2]["written"] == 1 and reports[-1] == {"event": "closed", "written": 2, "rejected": 1,
                                                           "dropped": 0, "error": None}
