"""RerunProcessLogger: the calls queued by the loop are made by a child process, in order; the .rrd is
complete after close and also after the parent's end of the pipe goes away (a killed side); 'off' starts
nothing; a full backlog drops the oldest calls and the loop never waits."""
from __future__ import annotations

import time

import numpy as np
import pytest

pytest.importorskip("rerun")

from teleop.errors import ConfigError  # noqa: E402
from teleop.rerun import process as rerun_proc  # noqa: E402
from teleop.rerun.process import RerunProcessLogger  # noqa: E402
from tests.teleop.test_rerun_log import _read, _tensor  # noqa: E402


def test_calls_are_made_in_the_child_in_order_and_the_file_is_complete(tmp_path):
    path = tmp_path / "a.rrd"
    log = RerunProcessLogger("test", "r1", "save", path)
    s = np.linspace(0.0, 1.0, 5)
    prof = np.arange(5.0)
    t0 = time.perf_counter()
    for i in range(20):
        log.log_scalars(0.01 * i, T_in=10.0 + i)
    log.log_profile(0.2, s, prof)
    prof[:] = -1.0                                       # the loop reuses its array: the queued copy is kept
    log.log_phase(0.3, "pull")
    queued = time.perf_counter() - t0
    assert log.mode == "save" and log.path == path and log.enabled
    log.flush()
    log.close()
    log.close()
    assert not log.enabled and log.dropped == 0
    assert queued < 0.05, f"queueing 22 calls took {queued:.3f} s: the loop must only append"
    _, rows = _read(path)
    t_in = [(t, r["Scalars:scalars"]) for t, r in rows["/tension/T_in"] if t is not None]
    assert t_in == [(i * 10_000_000, [10.0 + i]) for i in range(20)]
    [bars] = [r for t, r in rows["/profile/T_hat"] if "BarChart:values" in r]
    np.testing.assert_array_equal(_tensor(bars["BarChart:values"]), [0.0, 1.0, 2.0, 3.0, 4.0])
    assert [r["StateChange:state"] for _, r in rows["/phase"]] == [["pull"]]


def test_the_child_finalises_the_recording_when_the_pipe_ends(tmp_path):
    path = tmp_path / "killed.rrd"
    log = RerunProcessLogger("test", "r3", "save", path)
    for i in range(10):
        log.log_scalars(0.01 * i, T_in=float(i))
    log._stop = True                                     # the side dies: no close message, the pipe just ends
    log._thread.join(5.0)
    log._drain()
    log._proc.stdin.close()
    assert log._proc.wait(30.0) == 0
    _, rows = _read(path)                                # a finished file (footer), every call in it
    assert [r["Scalars:scalars"] for t, r in rows["/tension/T_in"] if t is not None] == [[float(i)] for i in range(10)]


def test_off_starts_nothing_bad_arguments_raise_and_a_full_backlog_drops_the_oldest(tmp_path, monkeypatch):
    off = RerunProcessLogger("test", None, "off")
    off.log_scalars(0.0, T_in=1.0)
    assert not off.enabled and off.mode == "off" and off._proc is None and len(off._queue) == 0
    off.close()
    with pytest.raises(ConfigError, match="needs a path"):
        RerunProcessLogger("test", None, "save")
    with pytest.raises(ConfigError, match="expected one of"):
        RerunProcessLogger("test", None, "live", tmp_path / "x.rrd")
    monkeypatch.setattr(rerun_proc, "MAX_BACKLOG", 3)
    log = RerunProcessLogger("test", "r2", "save", tmp_path / "b.rrd")
    log._stop = True                                     # a sender that has stopped draining
    log._thread.join(5.0)
    log._stop = False
    for k in range(5):
        log.log_scalars(float(k), T_in=float(k))
    assert log.dropped == 2 and [c[1][0] for c in log._queue] == [2.0, 3.0, 4.0]
    log.close()


def test_each_segment_has_a_child_of_its_own_and_no_row_is_lost(tmp_path):
    """A saved recording in segments: each file is written and finalised by a child of its own, which exits when
    the next segment starts (its memory goes with it); the files share the recording id, and every call is in
    exactly one of them."""
    from teleop.rerun.segments import segment_path
    path = tmp_path / "slave.rrd"
    log = RerunProcessLogger("test", "r-seg", "save", path, segment_s=3600.0)
    first = log._proc
    for i in range(10):
        log.log_scalars(0.01 * i, T_in=float(i))
    log.flush()
    log._segment_end = 0.0                               # the segment's time is over
    for i in range(10, 20):
        log.log_scalars(0.01 * i, T_in=float(i))
    log.flush()
    second = log._proc
    assert second is not first and first.wait(30.0) == 0       # the first child finalised its file and exited
    assert log.path == path and log.segments == [path, segment_path(path, 1)]
    log.close()
    assert second.poll() == 0
    times = []
    for f in log.segments:
        reader, rows = _read(f)
        assert [e.recording_id for e in reader.recordings()] == ["r-seg"] and reader.store().summary()
        times.append([t for t, _ in rows["/tension/T_in"] if t is not None])
    assert times == [[i * 10_000_000 for i in range(10)], [i * 10_000_000 for i in range(10, 20)]]
