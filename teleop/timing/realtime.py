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

**The kernel's real-time budget** (:func:`rt_budget`). Linux lets the real-time threads on a CPU run
for ``sched_rt_runtime_us`` of every ``sched_rt_period_us`` (default 950 ms of every second); once a
CPU's real-time threads have used that, the kernel stops all of them on that CPU until the period
ends (up to 50 ms by default). A loop whose process holds about one CPU of real-time work reaches it
and stalls for 40-60 ms; ``sched_rt_runtime_us = -1`` lifts the limit (a host setting,
``docs/how-to/real-time.md``), but kernels from 6.12 on also run ordinary tasks for up to 50 ms a second on
a CPU that real-time threads hold (the fair server), whatever that setting says.

**Idle window** (:data:`IDLE`). After each ``step()`` the loop announces until when it will sleep
(its next deadline less a guard); a helper thread calls :meth:`IdleWindow.wait` with the expected
duration of its next piece of work before doing it, so that it holds the interpreter lock while the
loop sleeps, not when the loop wakes. Without a loop (tests, tools) the window is always open.
"""
from __future__ import annotations

import dataclasses
import math
import os
import threading
import time

__all__ = ["promote_threads", "demote_threads", "IdleWindow", "IDLE", "HELPER_PREFIXES", "scheduling",
           "machine_steal", "RtBudget", "rt_budget", "rt_budget_note", "CO_LOCATED_MIN_CPUS", "co_located_priority"]

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


@dataclasses.dataclass(frozen=True)
class RtBudget:
    """The kernel's budget for real-time threads on each CPU (module docstring).

    Attributes
    ----------
    runtime_s : float or None
        Real-time CPU time allowed per period on one CPU [s]; None: unlimited (``sched_rt_runtime_us = -1``).
    period_s : float
        The accounting period [s] (``sched_rt_period_us``).
    """

    runtime_s: float | None
    period_s: float

    @property
    def limited(self) -> bool:
        """Whether the kernel stops real-time threads that use up the budget."""
        return self.runtime_s is not None and self.runtime_s < self.period_s

    @property
    def per_second(self) -> float:
        """Real-time CPU time allowed per second of one CPU [s/s]; ``inf`` when unlimited."""
        return math.inf if self.runtime_s is None else self.runtime_s / self.period_s

    @property
    def longest_stop(self) -> float:
        """The longest stop of throttled real-time threads [s]: the period less the runtime; 0 when unlimited."""
        return self.period_s - self.runtime_s if self.limited and self.runtime_s is not None else 0.0

    def stats(self) -> dict[str, float | str]:
        """For a side's stats: ``rt_budget_ms`` (per second of one CPU, or ``"unlimited"``) and
        ``rt_stop_ms`` (the longest stop, 0 when unlimited)."""
        return {"rt_budget_ms": "unlimited" if not self.limited else round(1e3 * self.per_second, 3),
                "rt_stop_ms": round(1e3 * self.longest_stop, 3)}


def rt_budget(kernel_dir: str = "/proc/sys/kernel") -> RtBudget | None:
    """The kernel's real-time budget from ``sched_rt_runtime_us`` and ``sched_rt_period_us`` in
    ``kernel_dir``; None where the files are absent or unreadable (not Linux, a container without them).
    A negative runtime (``-1``) is unlimited."""
    try:
        with open(os.path.join(kernel_dir, "sched_rt_runtime_us"), encoding="ascii") as fh:
            runtime = int(fh.read().strip())
        with open(os.path.join(kernel_dir, "sched_rt_period_us"), encoding="ascii") as fh:
            period = int(fh.read().strip())
    except (OSError, ValueError):
        return None
    if period <= 0:
        return None
    return RtBudget(None if runtime < 0 else runtime * 1e-6, period * 1e-6)


def rt_budget_note(budget: RtBudget | None) -> str | None:
    """One line on a limited budget for a loop that runs at ``SCHED_FIFO``: what the kernel does and how
    a dedicated control host lifts it; None when the budget is unknown or unlimited."""
    if budget is None or not budget.limited:
        return None
    return (f"the kernel stops real-time threads that use more than {1e3 * budget.per_second:.0f} ms of a CPU "
            f"in a second, for up to {1e3 * budget.longest_stop:.0f} ms (sched_rt_runtime_us); on a dedicated "
            "control host `sysctl -w kernel.sched_rt_runtime_us=-1` lifts it (docs/how-to/real-time.md)")


#: [count] the fewest CPUs on which master, slave and recorder sharing one machine (``teleop demo``) run their loops
#: at ``SCHED_FIFO``: each side's loop and transport may hold most of a CPU on a slow machine, and the recorder and the
#: CSV writers need the rest. On fewer, the real-time threads starve the ordinary ones and the kernel stops them for
#: up to 50 ms so that those run (the real-time budget, or the fair server of kernels from 6.12): a stop of a side's
#: transport threads leaves both links stale past the 50 ms watchdog while the loops themselves run on time.
CO_LOCATED_MIN_CPUS = 4


def _available_cpus() -> int | None:
    """The CPUs this process may run on: its affinity (a container's or a ``taskset``'s CPUs), else the machine's."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count()


def co_located_priority(priority: int, cpus: int | None = None) -> tuple[int, str | None]:
    """The ``SCHED_FIFO`` priority of a side that shares the machine with the other side and the recorder.

    Parameters
    ----------
    priority : int
        The configured ``<side>.realtime_priority`` (0: normal scheduling already).
    cpus : int, optional
        The CPUs the sides may run on (default: this process's CPU affinity, e.g. a container's cpuset; where that
        cannot be read, :func:`os.cpu_count`).

    Returns
    -------
    (int, str or None)
        ``priority`` and None on :data:`CO_LOCATED_MIN_CPUS` CPUs or more (or when ``priority`` is 0); else 0 and one
        line saying why the loops run with normal scheduling.
    """
    n = _available_cpus() if cpus is None else cpus
    if priority <= 0 or n is None or n >= CO_LOCATED_MIN_CPUS:
        return priority, None
    return 0, (f"{n} CPU{'s' if n != 1 else ''} for master, slave and recorder: their loops run with normal "
               f"scheduling (at SCHED_FIFO {priority} their threads would hold the CPUs, and the kernel stops "
               "real-time threads for up to 50 ms so that ordinary tasks run: both links would go stale past the "
               "watchdog); docs/how-to/real-time.md")


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
