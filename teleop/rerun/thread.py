"""Rerun logging off the control loop: the loop queues the calls, a thread makes them.

:class:`ThreadedRerunLogger` has the logging methods of :class:`teleop.rerun.logger.RerunLogger`
(``log_scalars``, ``log_profile``, ``log_phase``, ``flush``, ``close``, context manager). A call
from the loop costs a deque append (arrays copied, a few microseconds); the Rerun SDK's conversions
(~0.1 ms a scalar batch, ~0.5 ms a profile bar chart) run on the thread. The thread never makes the
loop wait: if it falls more than :data:`MAX_BACKLOG` calls behind, the oldest queued calls are
dropped and counted (:attr:`ThreadedRerunLogger.dropped`). In ``off`` mode every call returns at
once. Each call waits for the control loop's idle window (:data:`teleop.timing.realtime.IDLE`): it runs
while the loop sleeps, not as it wakes. The process's GIL switch interval is lowered to 0.5 ms, so that a
background thread in the middle of pure-Python work hands the interpreter back to the woken loop within half
a cycle (CPython's default is 5 ms).

The sides (``teleop slave``, ``teleop master``) no longer use this class: the Rerun SDK holds the
interpreter lock inside its calls (a profile log 1.7 ms at the median, up to 41 ms, on 2 loaded
cores), longer than any idle window, so they log from a child process
(:class:`teleop.rerun.process.RerunProcessLogger`). This class stays for tools without a real-time loop.
"""
from __future__ import annotations

import collections
import logging
import sys
import threading

import numpy as np

from teleop.rerun.logger import RerunLogger
from teleop.timing.realtime import IDLE

__all__ = ["ThreadedRerunLogger", "MAX_BACKLOG", "SWITCH_INTERVAL", "PROFILE_COST", "CALL_COST"]

log = logging.getLogger("teleop.rerun")
MAX_BACKLOG = 5000
SWITCH_INTERVAL = 0.0005     # [s] GIL switch interval of a process with writer threads beside its loop
PROFILE_COST = 5e-4          # [s] time a profile log (bar charts, 3D route) holds the interpreter, about
CALL_COST = 1.5e-4           # [s] the same for a scalar, phase or state log


def lower_switch_interval() -> None:
    """Lower the GIL switch interval to :data:`SWITCH_INTERVAL` (never raise it)."""
    if sys.getswitchinterval() > SWITCH_INTERVAL:
        sys.setswitchinterval(SWITCH_INTERVAL)


class ThreadedRerunLogger:
    """A :class:`~teleop.rerun.logger.RerunLogger` whose calls run on a thread (module docstring).

    Parameters
    ----------
    *args, **kwargs
        As :class:`~teleop.rerun.logger.RerunLogger` (application id, recording id, mode, path, ...).

    Attributes
    ----------
    dropped : int
        Calls dropped because the thread was more than :data:`MAX_BACKLOG` behind.
    """

    def __init__(self, *args, **kwargs) -> None:
        self._inner = RerunLogger(*args, **kwargs)
        self.dropped = 0
        self._queue: collections.deque = collections.deque()
        self._wake = threading.Event()
        self._stop = False
        self._thread = None
        if self._inner.enabled:
            lower_switch_interval()
            self._thread = threading.Thread(target=self._run, name="rerun-logger", daemon=True)
            self._thread.start()

    # what RerunLogger reports
    mode = property(lambda self: self._inner.mode)
    path = property(lambda self: self._inner.path)
    enabled = property(lambda self: self._inner.enabled)

    def _put(self, fn, args, kwargs) -> None:
        if self._thread is None:
            return
        q = self._queue
        if len(q) >= MAX_BACKLOG:
            q.popleft()
            self.dropped += 1
        q.append((fn, args, kwargs))
        self._wake.set()

    def log_scalars(self, t: float, **values) -> None:
        """Queue :meth:`RerunLogger.log_scalars` (``t`` [s], SI values)."""
        self._put(self._inner.log_scalars, (t,), values)

    def log_profile(self, t: float, s_positions, T_estimated, T_true=None) -> None:
        """Queue :meth:`RerunLogger.log_profile` (the arrays are copied now)."""
        self._put(self._inner.log_profile, (t, np.array(s_positions, dtype=np.float64),
                                            np.array(T_estimated, dtype=np.float64),
                                            None if T_true is None else np.array(T_true, dtype=np.float64)), {})

    def log_phase(self, t: float, phase_label) -> None:
        """Queue :meth:`RerunLogger.log_phase`."""
        self._put(self._inner.log_phase, (t, phase_label), {})

    def log_master(self, t: float, **values) -> None:
        """Queue :meth:`RerunLogger.log_master` (master-side series)."""
        self._put(self._inner.log_master, (t,), values)

    def log_state(self, t: float, entity: str, label: str) -> None:
        """Queue :meth:`RerunLogger.log_state`."""
        self._put(self._inner.log_state, (t, entity, label), {})

    def log_joint(self, t: float, joint: str, *, profiles=None, **values) -> None:
        """Queue :meth:`RerunLogger.log_joint` (the profiles are copied now)."""
        if profiles is not None:
            values["profiles"] = tuple(np.array(p, dtype=np.float64) for p in profiles)
        self._put(self._inner.log_joint, (t, joint), values)

    def _drain(self) -> None:
        q = self._queue
        profile = self._inner.log_profile
        while q:
            fn, args, kwargs = q.popleft()
            # run while the control loop sleeps (teleop/timing/realtime.py), never as it wakes
            IDLE.wait(PROFILE_COST if fn == profile else CALL_COST)
            try:
                fn(*args, **kwargs)
            except Exception as e:  # noqa: BLE001 - a logging problem must not end the logging thread
                log.warning("rerun logging failed: %r", e)

    def _run(self) -> None:
        while not self._stop:
            self._wake.wait(0.05)
            self._wake.clear()
            self._drain()

    def flush(self) -> None:
        """Wait until the thread has made every queued call (at most 10 s), then :meth:`RerunLogger.flush`."""
        if self._thread is not None and self._thread.is_alive():
            self._wake.set()
            for _ in range(10000):
                if not self._queue:
                    break
                threading.Event().wait(0.001)
        self._inner.flush()

    def close(self) -> None:
        """Stop the thread after the queued calls, finalise the recording. Idempotent."""
        self._stop = True
        self._wake.set()
        if self._thread is not None and self._thread.is_alive():
            self._thread.join(30.0)
        self._drain()
        self._inner.close()

    def __enter__(self) -> ThreadedRerunLogger:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
