"""Where a paced loop's time goes: per-cycle cost and lateness, overruns by node state, gc pauses.

:class:`CycleStats` is fed by :meth:`teleop.node.NodeBase.run` once per cycle with the cycle's
lateness (wake-up time minus its deadline) and the duration of ``step()``, both [s], and the node's
state. It keeps fixed-size histograms (50 us bins to 10 ms, one overflow bin: constant memory, no
allocation per cycle), the worst step, and the overruns per state name, so that a summary can tell
the power-up calibration from the teleoperation. With ``TELEOP_CYCLE_TRACE=<dir>`` in the
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
        self.late_hist = np.zeros(_NBINS + 1, dtype=np.int64)
        self.overruns_by_state: dict[str, int] = {}
        self.cycles_by_state: dict[str, int] = {}
        self.worst_step = 0.0
        self.worst_step_state = ""
        self.trace_dir = os.environ.get(TRACE_ENV) if trace is None else (os.environ.get(TRACE_ENV) or ".")
        self._rows: list[tuple[float, float, float, int]] = []
        self._gc: list[tuple[float, float, int]] = []
        self._gc_t0 = 0.0
        if self.trace_dir:
            gc.callbacks.append(self._on_gc)

    def _on_gc(self, phase: str, info: dict) -> None:
        if phase == "start":
            self._gc_t0 = time.monotonic()
        else:
            self._gc.append((self._gc_t0, time.monotonic() - self._gc_t0, int(info.get("generation", -1))))

    def add(self, t: float, lateness: float, overrun: bool, step: float, state: str) -> None:
        """One cycle: woke at ``t`` [s], ``lateness`` [s] after its deadline (an ``overrun`` when the
        wait was called after it), ``step()`` took ``step`` [s], in node state ``state``."""
        self.step_hist[min(int(step / BIN), _NBINS)] += 1
        self.late_hist[min(int(lateness / BIN), _NBINS)] += 1
        self.cycles_by_state[state] = self.cycles_by_state.get(state, 0) + 1
        if overrun:
            self.overruns_by_state[state] = self.overruns_by_state.get(state, 0) + 1
        if step > self.worst_step:
            self.worst_step, self.worst_step_state = step, state
        if self.trace_dir:
            self._rows.append((t, lateness, step, int(overrun)))

    def stats(self) -> dict[str, Any]:
        """``step_ms`` and ``lateness_ms`` (p50, p99, p99.9 from the 50 us histograms, max of the steps),
        ``cycles_by_state`` and ``overruns_by_state``."""
        return {
            "step_ms": {"p50": _percentile(self.step_hist, 50), "p99": _percentile(self.step_hist, 99),
                        "p99_9": _percentile(self.step_hist, 99.9), "max": self.worst_step * 1e3,
                        "max_in_state": self.worst_step_state},
            "lateness_ms": {"p50": _percentile(self.late_hist, 50), "p99": _percentile(self.late_hist, 99),
                            "p99_9": _percentile(self.late_hist, 99.9)},
            "cycles_by_state": dict(self.cycles_by_state),
            "overruns_by_state": dict(self.overruns_by_state),
        }

    def dump(self) -> Path | None:
        """Write ``<trace dir>/<name>_cycles.npz`` (``cycles``: t, lateness, step, overrun per cycle;
        ``gc``: start, duration, generation per collection) when tracing; its path, else None."""
        if not self.trace_dir:
            return None
        if self._on_gc in gc.callbacks:
            gc.callbacks.remove(self._on_gc)
        path = Path(self.trace_dir) / f"{self.name}_cycles.npz"
        path.parent.mkdir(parents=True, exist_ok=True)
        np.savez(path, cycles=np.asarray(self._rows, dtype=np.float64).reshape(-1, 4),
                 gc=np.asarray(self._gc, dtype=np.float64).reshape(-1, 3))
        return path
