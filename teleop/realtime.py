"""Real-time scheduling of a control process's threads, and the loop's idle window for its helpers.

**Priorities** (:func:`promote_threads`). On a loaded machine the kernel's fair scheduler lets any
other runnable process delay a 1 kHz loop by milliseconds (measured: 9-18 % overruns of the demo's
loops under a load average of 8 on 2 cores). A control loop on Linux asks for ``SCHED_FIFO``
instead, with three levels inside the process, highest first:

* the loop thread (the caller): ``priority``;
* the transport's threads (Zenoh's runtime: every native thread of the process when the loop starts,
  the Rerun SDK's and numba's too): ``priority - 5``. Zenoh stamps and hands over each received
  message on its own thread, holding the interpreter lock for the callback: at normal priority,
  another process preempting it there holds up the loop behind the lock (measured under a load
  average of 10: master overruns 1.9 %, round trip p99 8.8 ms, against 0.3 % and 1.6 ms);
* the process's Python helper threads (CSV writer, Rerun logger: threads named in
  :data:`HELPER_PREFIXES`): ``priority - 10`` (at least 1), below the transport. They are real-time
  for the same reason, and their work is small and bounded by what the loop queues.

Without the privilege (``CAP_SYS_NICE`` or an ``RLIMIT_RTPRIO``) nothing changes and the reason is
returned: the loop runs with normal scheduling. :func:`demote_threads` puts every thread back to
normal scheduling when the loop ends (writing the stats and closing the files is no real-time work).

**Idle window** (:data:`IDLE`). After each ``step()`` the loop announces until when it will sleep
(its next deadline less a guard); a helper thread calls :meth:`IdleWindow.wait` with the expected
duration of its next piece of work before doing it, so that it holds the interpreter lock while the
loop sleeps, not when the loop wakes. Without a loop (tests, tools) the window is always open.
"""
from __future__ import annotations

import math
import os
import threading
import time

__all__ = ["promote_threads", "demote_threads", "IdleWindow", "IDLE", "HELPER_PREFIXES", "scheduling",
           "machine_steal"]

HELPER_PREFIXES = ("csv-writer", "rerun-logger")


def _set_fifo(tid: int, priority: int) -> None:
    # reset on fork: a thread (or process) started from a real-time thread begins with normal scheduling
    policy = os.SCHED_FIFO | getattr(os, "SCHED_RESET_ON_FORK", 0)
    os.sched_setscheduler(tid, policy, os.sched_param(max(1, min(99, priority))))


def promote_threads(priority: int) -> str:
    """Put the calling thread at ``SCHED_FIFO`` ``priority``, the other threads below it (module docstring).

    Parameters
    ----------
    priority : int
        1..99; 0 or less: nothing is changed.

    Returns
    -------
    str
        What was obtained, for the run's stats (``"SCHED_FIFO 20"``, ``"off"``, or ``"not permitted: ..."``).
    """
    if priority <= 0:
        return "off"
    if not hasattr(os, "sched_setscheduler"):
        return "not available on this platform"
    me = threading.get_native_id()
    try:
        _set_fifo(0, priority)
    except OSError as e:
        return f"not permitted ({e.strerror}): normal scheduling"
    helpers = {t.native_id for t in threading.enumerate() if t.name.startswith(HELPER_PREFIXES)}
    try:
        tids = [int(t) for t in os.listdir("/proc/self/task")]
    except OSError:
        tids = []
    for tid in tids:
        if tid != me:
            try:
                _set_fifo(tid, priority - 10 if tid in helpers else priority - 5)
            except OSError:      # a thread that has just ended
                pass
    return f"SCHED_FIFO {priority}"


def demote_threads() -> None:
    """Every thread of the process back to normal scheduling (``SCHED_OTHER``), after the loop."""
    if not hasattr(os, "sched_setscheduler"):
        return
    try:
        tids = [int(t) for t in os.listdir("/proc/self/task")]
    except OSError:
        tids = [0]
    for tid in tids:
        try:
            if os.sched_getscheduler(tid) & ~getattr(os, "SCHED_RESET_ON_FORK", 0) == os.SCHED_FIFO:
                os.sched_setscheduler(tid, os.SCHED_OTHER, os.sched_param(0))
        except OSError:
            pass


def scheduling() -> str:
    """The calling thread's policy and priority, e.g. ``"SCHED_FIFO 20"`` or ``"SCHED_OTHER nice 0"``."""
    if not hasattr(os, "sched_getscheduler"):
        return "unknown"
    pol = os.sched_getscheduler(0) & ~getattr(os, "SCHED_RESET_ON_FORK", 0)
    if pol == os.SCHED_FIFO:
        return f"SCHED_FIFO {os.sched_getparam(0).sched_priority}"
    return f"SCHED_OTHER nice {os.getpriority(os.PRIO_PROCESS, 0)}"


def machine_steal(stat: str = "/proc/stat") -> float | None:
    """Time the hypervisor ran something else while this machine's CPUs wanted to run [s, summed
    over the CPUs since boot]: the ``steal`` column of ``/proc/stat`` (10 ms resolution). A virtual
    machine's stall stops every process at once, whatever their priority; its steal during a run
    tells such stalls from the loop's own faults. None where there is no such file (not Linux).
    """
    try:
        with open(stat, encoding="ascii") as fh:
            fields = fh.readline().split()
        return int(fields[8]) / os.sysconf("SC_CLK_TCK") if fields[0] == "cpu" and len(fields) > 8 else None
    except (OSError, ValueError, IndexError):
        return None


class IdleWindow:
    """Until when the control loop sleeps [s, :func:`time.monotonic`] (module docstring)."""

    def __init__(self):
        self._cond = threading.Condition()
        self._until = math.inf

    def open(self, until: float) -> None:
        """The loop sleeps until ``until`` [s, monotonic] (called after each step)."""
        with self._cond:
            self._until = until
            self._cond.notify_all()

    def release(self) -> None:
        """No loop any more: always open."""
        self.open(math.inf)

    def wait(self, need: float, timeout: float = 0.05) -> bool:
        """Block until ``need`` [s] of work fits before the loop wakes (or ``timeout`` [s]); True if it fits."""
        if time.monotonic() + need <= self._until:
            return True
        end = time.monotonic() + timeout
        with self._cond:
            while True:
                now = time.monotonic()
                if now + need <= self._until:
                    return True
                if now >= end:
                    return False
                self._cond.wait(min(end - now, 0.002))


IDLE = IdleWindow()
