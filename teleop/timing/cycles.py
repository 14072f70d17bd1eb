"""Where a paced loop's time goes: per-cycle cost and lateness, overruns by node state, gc pauses.

:class:`CycleStats` is fed by :meth:`teleop.node.NodeBase.run` once per cycle with the cycle's
lateness (wake-up time minus its deadline), the duration of ``step()`` and the CPU time the loop
thread spent in it (:func:`time.thread_time`: the step's own cost; the wall duration adds what other
threads and processes took meanwhile, while a loaded machine's cold caches slow both), all [s], and the
node's state. It keeps fixed-size histograms (50 us bins to 10 ms, one overflow bin: constant memory, no
allocation per cycle), the worst step, the overruns per state name, so that a summary can tell
the power-up calibration from the teleoperation, and the garbage collector's passes (count per
generation, total and longest pause). With ``TELEOP_CYCLE_TRACE=<dir>`` in the
environment (a diagnostic, never on in normal runs) it also keeps every cycle and every garbage
collection and writes ``<dir>/<name>_cycles.npz`` (:meth:`CycleStats.dump`).
"""
from __future__ import annotations

import gc
import math
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["CycleStats", "BIN", "TRACE_ENV"]

BIN = 50e-6            # [s] histogram bin width
_NBINS = 200           # 0 .. 10 ms, then one overflow bin
_TRACE_BLOCK = 1 << 16  # trace rows per preallocated block
TRACE_ENV = "TELEOP_CYCLE_TRACE"


def _percentile(hist: np.ndarray, q: float) -> float | None:
    """The ``q``-th percentile [ms] of a histogram (upper edge of the bin reaching it); None if empty."""
    n = int(hist.sum())
    if n == 0:
        return None
    k = int(np.searchsorted(np.cumsum(hist), math.ceil(q / 100.0 * n)))
    return (k + 1) * BIN * 1e3 if k < _NBINS else math.inf


class CycleStats:
    """Histograms of step duration and wake-up lateness, overruns by state (module docstring).

    Parameters
    ----------
    name : str
        Used in the trace file name (``slave``, ``master``).
    trace : bool, optional
        Keep every cycle and gc pause for :meth:`dump` (default: whether ``TELEOP_CYCLE_TRACE`` is set).
    """

    def __init__(self, name: str, trace: bool | None = None):
        self.name = name
        self.step_hist = np.zeros(_NBINS + 1, dtype=np.int64)
        self.cpu_hist = np.zeros(_NBINS + 1, dtype=np.int64)
        self.late_hist = np.zeros(_NBINS + 1, dtype=np.int64)
        self.overruns_by_state: dict[str, int] = {}
        self.cycles_by_state: dict[str, int] = {}
        self.worst_step = 0.0
        self.worst_step_state = ""
        self.trace_dir = os.environ.get(TRACE_ENV) if trace is None else (os.environ.get(TRACE_ENV) or ".")
        self.worst_cpu = 0.0
        # the trace: rows (t, lateness, step, overrun, cpu) in preallocated float blocks, not a list of
        # tuples (a tuple per cycle would survive into the collector's older generations and make its
        # passes longer in exactly the runs that measure them)
        self._blocks: list[np.ndarray] = []
        self._n = _TRACE_BLOCK
        self._gc: list[tuple[float, float, int]] = []
        self._gc_t0 = 0.0
        self.gc_collections = [0, 0, 0]      # per generation, during the loop (every thread of the process)
        self.gc_total = 0.0                  # [s]
        self.gc_worst = 0.0                  # [s]
        gc.callbacks.append(self._on_gc)

    def _on_gc(self, phase: str, info: dict) -> None:
        if phase == "start":
            self._gc_t0 = time.monotonic()
            return
        dt = time.monotonic() - self._gc_t0
        gen = int(info.get("generation", 2))
        self.gc_collections[min(max(gen, 0), 2)] += 1
        self.gc_total += dt
        if dt > self.gc_worst:
            self.gc_worst = dt
        if self.trace_dir:
            self._gc.append((self._gc_t0, dt, gen))

    def add(self, t: float, lateness: float, overrun: bool, step: float, state: str, cpu: float = math.nan) -> None:
        """One cycle: woke at ``t`` [s], ``lateness`` [s] after its deadline (an ``overrun`` when the
        wait was called after it), ``step()`` took ``step`` [s] of wall time and ``cpu`` [s] of the
        loop thread's CPU time (NaN: not measured), in node state ``state``."""
        self.step_hist[min(int(step / BIN), _NBINS)] += 1
        if cpu == cpu:                                  # not NaN
            self.cpu_hist[min(int(cpu / BIN), _NBINS)] += 1
            if cpu > self.worst_cpu:
                self.worst_cpu = cpu
        self.late_hist[min(int(lateness / BIN), _NBINS)] += 1
        self.cycles_by_state[state] = self.cycles_by_state.get(state, 0) + 1
        if overrun:
            self.overruns_by_state[state] = self.overruns_by_state.get(state, 0) + 1
        if step > self.worst_step:
            self.worst_step, self.worst_step_state = step, state
        if self.trace_dir:
            if self._n == _TRACE_BLOCK:
                self._blocks.append(np.empty((_TRACE_BLOCK, 5)))
                self._n = 0
            self._blocks[-1][self._n] = (t, lateness, step, overrun, cpu)
            self._n += 1

    def stats(self) -> dict[str, Any]:
        """``step_ms`` (wall), ``step_cpu_ms`` (the loop thread's CPU time) and ``lateness_ms`` (p50, p99,
        p99.9 from the 50 us histograms, max of the steps), ``cycles_by_state``, ``overruns_by_state`` and
        ``gc``: the garbage collector's passes while the stats were kept (any thread of the process; per
        generation), their total and longest pause [ms]."""
        return {
            "step_ms": {"p50": _percentile(self.step_hist, 50), "p99": _percentile(self.step_hist, 99),
                        "p99_9": _percentile(self.step_hist, 99.9), "max": self.worst_step * 1e3,
                        "max_in_state": self.worst_step_state},
            "step_cpu_ms": {"p50": _percentile(self.cpu_hist, 50), "p99": _percentile(self.cpu_hist, 99),
                            "p99_9": _percentile(self.cpu_hist, 99.9), "max": self.worst_cpu * 1e3},
            "lateness_ms": {"p50": _percentile(self.late_hist, 50), "p99": _percentile(self.late_hist, 99),
                            "p99_9": _percentile(self.late_hist, 99.9)},
            "cycles_by_state": dict(self.cycles_by_state),
            "overruns_by_state": dict(self.overruns_by_state),
            "gc": {"collections": list(self.gc_collections), "total_ms": self.gc_total * 1e3,
                   "max_ms": self.gc_worst * 1e3},
        }

    def close(self) -> None:
        """Stop watching the garbage collector (idempotent; :meth:`dump` calls it)."""
        if self._on_gc in gc.callbacks:
            gc.callbacks.remove(self._on_gc)

    def dump(self) -> Path | None:
        """Stop watching the collector; write ``<trace dir>/<name>_cycles.npz`` (``cycles``: t, lateness,
        step, overrun, step CPU time per cycle [s]; ``gc``: start, duration, generation per collection)
        when tracing; its path, else None."""
        self.close()
        if not self.trace_dir:
            return None
        path = Path(self.trace_dir) / f"{self.name}_cycles.npz"
        path.parent.mkdir(parents=True, exist_ok=True)
        rows = np.concatenate([b for b in self._blocks[:-1]] + [self._blocks[-1][:self._n]]) if self._blocks \
            else np.zeros((0, 5))
        np.savez(path, cycles=rows, gc=np.asarray(self._gc, dtype=np.float64).reshape(-1, 3))
        return path
