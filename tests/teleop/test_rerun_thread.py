"""ThreadedRerunLogger: calls queued by the loop are made on the thread, in order, and the .rrd is complete
after close; 'off' mode does nothing; the loop never waits when the thread is behind."""
from __future__ import annotations

import sys

import numpy as np

from teleop.rerun import thread as rerun_thread
from teleop.rerun.thread import ThreadedRerunLogger


def test_calls_run_on_the_thread_in_order_and_the_file_is_written(tmp_path, monkeypatch):
    seen = []
    log = ThreadedRerunLogger("test", "r1", "save", tmp_path / "a.rrd")
    inner = log._inner
    monkeypatch.setattr(inner, "log_scalars", lambda t, **v: seen.append(("s", t, v)))
    s = np.linspace(0.0, 1.0, 5)
    prof = np.arange(5.0)
    real_profile = inner.log_profile
    monkeypatch.setattr(inner, "log_profile", lambda *a: (seen.append(("p", a[0], a[2].copy())), real_profile(*a)))
    log.log_scalars(0.1, T_in=1.0)
    log.log_profile(0.2, s, prof)
    prof[:] = -1.0                                       # the loop reuses its array: the queued copy is kept
    log.log_phase(0.3, "pull")
    log.close()
    log.close()
    assert [x[:2] for x in seen] == [("s", 0.1), ("p", 0.2)]
    assert seen[0][2] == {"T_in": 1.0} and list(seen[1][2]) == [0.0, 1.0, 2.0, 3.0, 4.0]
    assert (tmp_path / "a.rrd").stat().st_size > 0
    assert sys.getswitchinterval() <= rerun_thread.SWITCH_INTERVAL


def test_off_mode_queues_nothing_and_a_full_backlog_drops_the_oldest(tmp_path, monkeypatch):
    off = ThreadedRerunLogger("test", None, "off")
    off.log_scalars(0.0, T_in=1.0)
    assert not off.enabled and len(off._queue) == 0
    off.close()
    monkeypatch.setattr(rerun_thread, "MAX_BACKLOG", 3)
    log = ThreadedRerunLogger("test", "r2", "save", tmp_path / "b.rrd")
    log._stop = True                                     # a thread that has stopped draining
    log._thread.join(5.0)
    for k in range(5):
        log.log_scalars(float(k), T_in=float(k))
    assert log.dropped == 2 and [c[1][0] for c in log._queue] == [2.0, 3.0, 4.0]
    log.close()
