"""ThreadedCsvRecorder: rows queued by the loop reach the file in order, within the flush interval, and
bad rows are skipped and counted instead of raised. Waits are bounded and end when the rows are there."""
from __future__ import annotations

import math
import time

import numpy as np
import pytest

from teleop.csv_writer import ThreadedCsvRecorder
from teleop.recording import read_measured_csv


def _rows_on_disk(path) -> int:
    return sum(1 for ln in path.read_text().splitlines() if ln and not ln.startswith("#")) - 1


def test_rows_are_written_in_order_without_close_then_all_on_close(tmp_path):
    path = tmp_path / "a.csv"
    rec = ThreadedCsvRecorder(path, ("time", "x_in", "T_in"), {"source": "test"}, flush_interval=0.01)
    for k in range(500):
        rec.write((k * 1e-3, 1e-5 * k, 0.5 * k))
    deadline = time.monotonic() + 5.0
    while _rows_on_disk(path) < 500 and time.monotonic() < deadline:   # the thread writes, no close needed
        time.sleep(0.01)
    assert _rows_on_disk(path) == 500
    rec.write_many(np.array([[0.5, 0.0, 1.0], [0.501, 0.0, 2.0]]))
    rec.close()
    rec.close()
    data = read_measured_csv(path)
    assert data.time.size == 502 and np.all(np.diff(data.time) > 0)
    assert data.T_in[:500] == pytest.approx(0.5 * np.arange(500)) and data.T_in[-1] == 2.0
    with pytest.raises(ValueError, match="closed"):
        rec.write((1.0, 0.0, 0.0))


def test_a_bad_row_is_skipped_and_counted_not_raised(tmp_path):
    path = tmp_path / "b.csv"
    with ThreadedCsvRecorder(path, ("time", "x_in", "T_in"), flush_interval=0.01) as rec:
        rec.write((0.0, 0.0, 1.0))
        rec.write((0.001, math.nan, 1.0))        # refused by the base recorder
        rec.write((0.002, 0.0))                  # wrong length
        rec.write((0.003, 0.0, 3.0))
    assert rec.rejected == 2
    data = read_measured_csv(path)
    assert list(data.T_in) == [1.0, 3.0]


def test_flush_interval_must_be_positive(tmp_path):
    with pytest.raises(ValueError, match="flush_interval must be > 0"):
        ThreadedCsvRecorder(tmp_path / "c.csv", ("time", "x_in", "T_in"), flush_interval=0.0)
