"""A side's files (live/side_files.py): its CSV at recording.csv_every, and both high-rate files stopped, said
once and counted, past recording.max_bytes or below the free-space floor, while the loop's calls go on."""
from __future__ import annotations

import dataclasses
import json
import logging

from live.side_files import SideFiles, add_to_stats
from teleop.config.schema import Config
from teleop.timing.latency import EXACT, LatencyHistogram, bin_percentile


class _Rows:
    def __init__(self):
        self.rows: list = []
        self.path = "x.csv"

    def write(self, row):
        self.rows.append(row)


class _Rerun:
    enabled = True

    def __init__(self):
        self.calls = 0

    def log_scalars(self, *args):
        self.calls += 1


def _cfg(**recording) -> Config:
    c = Config()
    return dataclasses.replace(c, recording=dataclasses.replace(c.recording, **recording))


def test_the_csv_gets_one_row_every_csv_every_cycles(tmp_path):
    files = SideFiles(tmp_path, _cfg(csv_every=4), "slave", watch=False)
    rows = _Rows()
    gate = files.csv(rows)
    for k in range(10):
        gate.write((k,))
    assert rows.rows == [(0,), (4,), (8,)] and gate.path == "x.csv"
    assert files.summary()["csv_rows_written"] == 3 and files.summary()["csv_every"] == 4


def test_past_max_bytes_a_side_stops_its_high_rate_files_says_so_once_and_counts(tmp_path, caplog):
    (tmp_path / "slave.csv").write_bytes(b"x" * 300)
    files = SideFiles(tmp_path, _cfg(csv_every=1, max_bytes=200.0), "slave", ("slave.csv", "slave.rrd"), watch=False)
    rows, rr = _Rows(), _Rerun()
    gate, view = files.csv(rows), files.rerun(rr)
    gate.write((1,))
    view.log_scalars(1.0)
    with caplog.at_level(logging.WARNING):
        assert files.check(0.0) is True
        assert files.check(5.0) is False                       # said once
    for k in range(5):
        gate.write((k,))                                       # the loop's calls go on, nothing written
        view.log_scalars(2.0)
    assert rows.rows == [(1,)] and rr.calls == 1 and view.enabled
    said = [r.getMessage() for r in caplog.records if "no longer written" in r.getMessage()]
    assert len(said) == 1 and "recording.max_bytes" in said[0] and "slave.csv, slave.rrd" in said[0]
    s = files.summary()
    assert s["stopped"] and s["csv_rows_not_written"] == 5 and s["rerun_calls_not_logged"] == 5
    add_to_stats(tmp_path / "slave_stats.json", "disk", s)
    assert json.loads((tmp_path / "slave_stats.json").read_text())["disk"]["csv_rows_not_written"] == 5


def test_below_the_free_space_floor_a_side_stops_too(tmp_path):
    files = SideFiles(tmp_path, _cfg(max_bytes=None, min_free_bytes=1e18), "master", watch=False)
    assert files.check(0.0) and "recording.min_free_bytes" in files.budget.reached["reason"]


def test_the_live_file_holds_the_loop_figures_and_is_replaced_whole(tmp_path):
    files = SideFiles(tmp_path, _cfg(), "master", watch=False)
    files.live_source = lambda: {"cycles": 7, "overruns": 1}
    data = json.loads(files.live().read_text())
    assert data["cycles"] == 7 and data["overruns"] == 1 and data["disk"]["stopped"] is False
    assert not list(tmp_path.glob("*.tmp"))


def test_round_trips_past_the_exact_samples_come_from_bins_within_half_a_bin():
    h = LatencyHistogram()
    for k in range(EXACT + 1000):
        h.add(1e-3 if k % 100 else 4e-3)                       # 1 % at 4 ms
    s = h.stats()
    assert s["n"] == EXACT + 1000 and abs(s["p50_ms"] - 1.0) <= 1e-3 and abs(s["max_ms"] - 4.0) < 1e-9
    snap = h.snapshot()
    import numpy as np
    counts = np.zeros(max(snap["bins"]) + 2, dtype=np.int64)
    for i, c in snap["bins"].items():
        counts[i] = c
    assert abs(bin_percentile(counts, 50) - 1e-3) <= 1e-6 and sum(snap["bins"].values()) == snap["n"]
