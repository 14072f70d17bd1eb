"""Round-trip latencies of a long session in constant memory: exact samples first, then a histogram.

A master at 1 kHz sees 3.6 million command echoes an hour; a list of them grows by ~115 MB (a Python
float and its pointer per sample). :class:`LatencyHistogram` keeps the first :data:`EXACT` samples in a
preallocated array (percentiles as ``numpy.percentile`` gives them, interpolated) and every sample in
fixed bins of :data:`BIN` up to :data:`SPAN`, one overflow bin beyond; past :data:`EXACT` samples the
percentiles come from the bins (the middle of the bin that holds them: within BIN / 2 of the sample's
value). The maximum is always exact. Memory: 8 (EXACT + SPAN / BIN) bytes, allocated once.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["LatencyHistogram", "BIN", "SPAN", "EXACT"]

BIN = 1e-6          # [s] bin width
SPAN = 0.1          # [s] binned range; longer round trips fall in one overflow bin
EXACT = 1 << 16     # samples kept exactly (65 s at 1 kHz)
_NBINS = int(round(SPAN / BIN))


class LatencyHistogram:
    """Round-trip samples [s]: :meth:`add`, :meth:`stats`, :meth:`snapshot` (module docstring)."""

    def __init__(self) -> None:
        self.counts = np.zeros(_NBINS + 1, dtype=np.int64)
        self._exact = np.empty(EXACT)
        self.n = 0
        self.max = -math.inf
        self.last: float | None = None

    def add(self, rtt: float) -> None:
        """One round trip [s] (>= 0; a negative one counts in the first bin)."""
        if self.n < EXACT:
            self._exact[self.n] = rtt
        self.n += 1
        self.last = rtt
        if rtt > self.max:
            self.max = rtt
        self.counts[min(_NBINS, max(0, int(rtt / BIN)))] += 1

    def percentile(self, q: float) -> float | None:
        """The ``q``-th percentile [s] (0..100), None without samples."""
        if self.n == 0:
            return None
        if self.n <= EXACT:
            return float(np.percentile(self._exact[:self.n], q))
        return bin_percentile(self.counts, q)

    def stats(self) -> dict[str, float | int | None]:
        """``{"n", "p50_ms", "p99_ms", "max_ms"}`` [ms] (None without samples)."""
        p50, p99 = self.percentile(50), self.percentile(99)
        if p50 is None or p99 is None:
            return {"n": 0, "p50_ms": None, "p99_ms": None, "max_ms": None}
        return {"n": self.n, "p50_ms": 1e3 * p50, "p99_ms": 1e3 * p99, "max_ms": 1e3 * self.max}

    def snapshot(self) -> dict:
        """``{"bin_s", "n", "max_s", "bins": {index: count}}`` (non-empty bins; index :data:`SPAN` / BIN is the
        overflow): two snapshots' differences give a window's percentiles (:func:`bin_percentile`)."""
        counts = self.counts.copy()      # the loop thread may add a sample while another thread snapshots
        nz = np.flatnonzero(counts)
        return {"bin_s": BIN, "n": int(counts.sum()), "max_s": None if self.n == 0 else self.max,
                "bins": {int(i): int(counts[i]) for i in nz}}


def bin_percentile(counts: np.ndarray, q: float) -> float | None:
    """The ``q``-th percentile [s] of histogram ``counts`` (bins of :data:`BIN`, the last one overflow: inf);
    the middle of the bin that reaches it, None when empty."""
    n = int(counts.sum())
    if n == 0:
        return None
    k = int(np.searchsorted(np.cumsum(counts), max(1, math.ceil(q / 100.0 * n))))
    return (k + 0.5) * BIN if k < len(counts) - 1 else math.inf
