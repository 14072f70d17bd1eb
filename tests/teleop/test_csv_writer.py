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


def test_wide_rows_are_formatted_in_chunks_that_each_fit_the_loops_idle_time(tmp_path, monkeypatch):
    from teleop import csv_writer
    from teleop.recording import CsvRecorder
    sizes = []
    real = CsvRecorder.write_many
    monkeypatch.setattr(CsvRecorder, "write_many", lambda self, rows: (sizes.append(len(rows)), real(self, rows)))
    columns = ("time", "x_in", "T_in") + tuple(f"c{k}" for k in range(69))   # the 3-joint slave's width
    path = tmp_path / "wide.csv"
    rec = ThreadedCsvRecorder(path, columns, flush_interval=10.0)     # only close() drains: one batch
    for k in range(20):
        rec.write((k * 1e-3,) + (float(k),) * 71)                    # in order, whatever the chunks
    rec.close()
    per_chunk = int(csv_writer.CHUNK_COST / (csv_writer.VALUE_COST * len(columns)))
    assert sum(sizes) == 20 and max(sizes) <= per_chunk < 20 and len(sizes) >= 20 // per_chunk
    data = read_measured_csv(path)
    assert np.all(np.diff(data.time) > 0) and data.time.size == 20 and data.T_in == pytest.approx(np.arange(20.0))


def test_a_batch_longer_than_flush_every_with_rows_arriving_meanwhile_does_not_deadlock(tmp_path, monkeypatch):
    # the 3-joint master's rare shutdown stall: a writer thread late by more than flush_every rows (a
    # loaded machine) made the base recorder flush in the middle of the batch; that flush drained again,
    # found the rows the loop had queued meanwhile and waited for the lock its own thread held: the
    # writer hung, the CSV stopped, and close() waited for the lock forever
    import threading

    from teleop import csv_writer
    path = tmp_path / "late.csv"
    rec = ThreadedCsvRecorder(path, ("time", "x_in", "T_in"), flush_every=5, flush_interval=60.0)
    monkeypatch.setattr(csv_writer, "CHUNK_COST", 1e-9)              # one row per chunk
    k = [0]
    running = [True]

    def loop_queues_a_row(need, timeout=0.05):                       # the loop runs between the chunks
        if running[0] and k[0] < 30:
            k[0] += 1
            rec.write((1.0 + k[0] * 1e-3, 0.0, float(k[0])))
        return True

    monkeypatch.setattr(csv_writer.IDLE, "wait", loop_queues_a_row)
    for i in range(12):
        rec.write((i * 1e-3, 0.0, -1.0))
    drainer = threading.Thread(target=rec.flush, daemon=True)
    drainer.start()
    drainer.join(10.0)
    assert not drainer.is_alive(), "the drain deadlocked on its own lock"
    running[0] = False                                               # the loop has ended
    rec.close()
    data = read_measured_csv(path)
    assert k[0] > 5 and data.time.size == 12 + k[0] and np.all(np.diff(data.time) > 0)   # every row, in order
