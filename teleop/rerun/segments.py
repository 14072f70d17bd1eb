"""Segmented .rrd files for long sessions: a saved Rerun recording starts a new file every :data:`SEGMENT_S`.

A saved recording (:class:`teleop.rerun.logger.RerunLogger`, mode ``save``) is written in segments of
:data:`SEGMENT_S` of wall-clock time: ``slave.rrd``, then
``slave.1.rrd``, ``slave.2.rrd``, ... (``rerun <run dir>/*.rrd`` opens them as one recording: they share
the recording id). Each file is finalised when the next one starts, so a session of hours leaves files of a
few MB that each open alone, and a crash loses at most the open one. Each segment opens with the static pieces
again (routes, series styles, profile grid) and the current phase and states at their next log. The SDK's
process memory is not bounded by it: a process logging at a side's rate (scalars at 100 Hz, a profile at
10 Hz) grows 1-2 MB a minute with segments of 30 s, 60 s or 5 min alike, its Python heap flat
(rerun-sdk 0.41; rerun-io/rerun#12623; docs/results/index.md, "An hour at 1 kHz"), so the sides and the
recorder log through :class:`teleop.rerun.process.RerunProcessLogger`, which gives each segment a child process of
its own: the memory goes back when the segment's child exits.
"""
from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

__all__ = ["SEGMENT_S", "SegmentedSave", "segment_path"]

SEGMENT_S = 300.0           # [s] a saved recording starts a new .rrd file this often (wall clock)


def segment_path(path: Path, k: int) -> Path:
    """The ``k``-th segment file of the saved recording ``path`` (k = 0: ``path`` itself; ``slave.rrd`` ->
    ``slave.<k>.rrd``)."""
    return path if k == 0 else path.with_name(f"{path.stem}.{k}{path.suffix}")


class SegmentedSave:
    """The segment bookkeeping of :class:`teleop.rerun.logger.RerunLogger` (a mixin: the logger owns the stream,
    its path and mode, its caches and :meth:`_log_statics`)."""

    _rec: Any
    _blueprint: Any
    _segment_s: float | None
    _segment_end: float
    _segments: int
    _paths: dict
    _grid: dict
    _states: dict
    _phase: str | None
    _abscissa: Any
    mode: str
    path: Path | None

    def _log_statics(self) -> None:  # pragma: no cover - RerunLogger's
        raise NotImplementedError

    def _init_segments(self, segment_s: float | None) -> None:
        """``segment_s`` [s] of wall clock per file (None: one file); no segment runs before a file is saved."""
        self._segment_s = None if segment_s is None else float(segment_s)
        self._segment_end = math.inf
        self._segments = 1
        self._blueprint = None

    def _begin_segments(self, blueprint: Any) -> None:
        """The first file is open (``blueprint``: sent again with every later file): its segment time starts."""
        self._blueprint = blueprint
        if self._segment_s is not None:
            self._segment_end = time.monotonic() + self._segment_s

    @property
    def segments(self) -> list[Path]:
        """The .rrd files written so far, in order (module docstring: segments); [] when not saving."""
        if self.mode != "save" or self.path is None:
            return []
        return [self.path] + [segment_path(self.path, k) for k in range(1, self._segments)]

    def _next_segment(self, now: float) -> None:
        """Finalise the present .rrd and go on in the next segment file, its static pieces sent again."""
        rec = self._rec
        assert rec is not None and self.path is not None and self._segment_s is not None
        rec.save(segment_path(self.path, self._segments), default_blueprint=self._blueprint)
        self._segments += 1
        self._segment_end = now + self._segment_s
        self._paths, self._grid, self._states, self._phase, self._abscissa = {}, {}, {}, None, None
        self._log_statics()
