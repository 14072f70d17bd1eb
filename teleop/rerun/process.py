"""Rerun logging out of the control process: the loop queues the calls, a child process makes them.

The Rerun SDK holds the interpreter lock (GIL) inside its calls: measured on 2 cores (load average
3.5, the logging thread at ``SCHED_FIFO`` 10 below a 1 kHz loop thread at 20, GIL switch interval
0.5 ms), a profile log (bar charts, 3D route) held it 1.7 ms at the median and up to 41 ms, and the
loop thread woke up to 14 ms late behind it (p99 3.8 ms). No idle window fits a call longer than a
period, so a Rerun thread inside a side process costs the loop its deadlines: in a demo the sides'
overruns were 0.38 / 0.26 % with the Rerun thread and 0.02 / 0.00 % without Rerun (same machine,
same minute).

:class:`RerunProcessLogger` has the logging methods of :class:`teleop.rerun.logger.RerunLogger`
(``log_scalars``, ``log_profile``, ``log_phase``, ``log_master``, ``log_state``, ``log_joint``, ``flush``, ``close``,
context manager). A call from the loop is a deque append (arrays copied, a few microseconds). A
sender thread (``rerun-logger``, a helper of :mod:`teleop.timing.realtime`) pickles the queued calls in
batches during the loop's idle window and writes them to the stdin pipe of a child process
(``python -m teleop.rerun.process``) that owns the :class:`~teleop.rerun.logger.RerunLogger` and makes the
calls, with normal scheduling, on its own interpreter lock. If the child falls behind, the pipe
fills, the sender blocks in ``write`` (the lock released) and the loop's queue drops its oldest
calls beyond :data:`MAX_BACKLOG` (counted in :attr:`RerunProcessLogger.dropped`): the loop never
waits. The child finalises the .rrd when told to close and also when its stdin ends (the side was
killed). In ``off`` mode no process is started and every call returns at once.

A saved recording lives in segments (:mod:`teleop.rerun.segments`: ``slave.rrd``, ``slave.1.rrd``, ...), and
here each segment has a child process of its own: when a segment's time is over the sender starts the next
child on the next file (same recording id, the static pieces logged again) and tells the old one to close,
which finalises its file and exits. The SDK's memory, which grows as long as a process logs (rerun-sdk 0.41,
rerun-io/rerun#12623), goes back with each child: a side's Rerun memory is at most one segment's growth.

Wire (parent -> child, pickles on stdin): first ``(args, kwargs)`` of the RerunLogger, then lists of
``(method name, args, kwargs)``, ``"flush"`` (the child answers ``flushed`` on stdout) or None
(close). The child's first stdout line is JSON: ``{"mode": ..., "path": ...}`` (a ``spawn`` without
a display falls back to ``save``).
"""
from __future__ import annotations

import collections
import json
import logging
import math
import pickle
import subprocess
import sys
import threading
import time
import uuid
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from teleop.recording.child_pipe import close_stdin, write_bytes, write_pickle
from teleop.rerun.segments import SEGMENT_S, segment_path
from teleop.timing.realtime import IDLE

__all__ = ["RerunProcessLogger", "MAX_BACKLOG", "BATCH_COST", "main"]

log = logging.getLogger("teleop.rerun")
MAX_BACKLOG = 5000
BATCH = 160                 # pickling cost of a batch at most, in scalar calls (~1.3 us each)
HEAVY = 10                  # the cost of a call with arrays (a profile: ~10 us), in scalar calls
_ARRAYS = ("log_profile", "log_joint")
BATCH_COST = 2e-4           # [s] time pickling a batch holds the interpreter, about (idle-window request)
_READY_TIMEOUT = 30.0       # [s] wait for the child's first line (mode, path) when asked for them


class RerunProcessLogger:
    """A :class:`~teleop.rerun.logger.RerunLogger` in a child process (module docstring).

    Parameters
    ----------
    *args, **kwargs
        As :class:`~teleop.rerun.logger.RerunLogger` (application id, recording id, mode, path, route,
        wall_clock, ...); they must pickle.

    Attributes
    ----------
    dropped : int
        Calls dropped because the sender was more than :data:`MAX_BACKLOG` calls behind.

    Raises
    ------
    ConfigError
        As :class:`~teleop.rerun.logger.RerunLogger` for a bad mode or 'save' without a path (checked
        here, before any process starts).
    OSError
        The child process cannot be started.
    """

    def __init__(self, *args: Any, **kwargs: Any):
        mode = kwargs.get("mode", args[2] if len(args) > 2 else "save")
        path = kwargs.get("path", args[3] if len(args) > 3 else None)
        _check(mode, path)
        self._mode: str = mode
        self._path: Path | None = None if path is None else Path(path)
        # a saved recording: one child per segment (module docstring), each on one file of its own
        segment_s = kwargs.pop("segment_s", SEGMENT_S)
        self._segment_s: float | None = None if mode != "save" or segment_s is None else float(segment_s)
        recording_id = kwargs.pop("recording_id", args[1] if len(args) > 1 else None) or str(uuid.uuid4())
        self._args = args[:1]                     # the application id; the rest goes by keyword
        self._kwargs = {k: v for k, v in kwargs.items() if k not in ("mode", "path")}
        self._kwargs["recording_id"] = recording_id    # every segment's child: one recording
        self._kwargs["segment_s"] = None if mode == "save" else segment_s   # a fallback to 'save' segments itself
        self._rotating = threading.Lock()
        self._segments = 0
        self._segment_end = math.inf
        self._retired: list[subprocess.Popen] = []
        self.dropped = 0
        self._queue: collections.deque = collections.deque()
        self._wake = threading.Event()
        self._stop = False
        self._thread: threading.Thread | None = None
        self._proc: subprocess.Popen | None = None
        self._ready: dict | None = None
        self._flushed = threading.Event()
        self._got_ready = threading.Event()
        self._lock = threading.Lock()              # one writer of the pipe at a time (sender, flush, close)
        if mode == "off":
            return
        self._proc = self._start_child()
        self._thread = threading.Thread(target=self._run, name="rerun-logger", daemon=True)
        self._thread.start()

    def _start_child(self) -> subprocess.Popen:
        """A child logging the next segment (or, not segmented, the whole recording), its reader started."""
        kwargs = dict(self._kwargs, mode=self._mode, path=self._path)
        if self._segment_s is not None:
            assert self._path is not None
            kwargs["path"] = segment_path(self._path, self._segments)
            self._segment_end = time.monotonic() + self._segment_s
        self._segments += 1
        proc = subprocess.Popen([sys.executable, "-m", "teleop.rerun.process"], stdin=subprocess.PIPE,
                                stdout=subprocess.PIPE, close_fds=True)
        write_pickle(proc, (self._args, kwargs))
        threading.Thread(target=self._read, args=(proc, self._segments == 1), name="rerun-logger-reader",
                         daemon=True).start()
        return proc

    def _next_segment(self) -> None:
        """Start the next segment's child; the present one finalises its file and exits (module docstring)."""
        new = self._start_child()
        with self._lock:
            old, self._proc = self._proc, new
        self._retired = [c for c in self._retired if c.poll() is None]    # the finished ones forgotten
        if old is not None:
            write_pickle(old, None)
            close_stdin(old)
            self._retired.append(old)
            threading.Thread(target=old.wait, name="rerun-logger-reap", daemon=True).start()   # no zombie left

    @property
    def segments(self) -> list[Path]:
        """The .rrd files started so far, in order ([] when not saving in segments)."""
        if self._segment_s is None or self._path is None:
            return []
        return [segment_path(self._path, k) for k in range(self._segments)]

    # what RerunLogger reports
    @property
    def enabled(self) -> bool:
        """False in 'off' mode and after :meth:`close`."""
        return self._proc is not None and not self._stop

    @property
    def mode(self) -> str:
        """``save``, ``spawn`` or ``off`` as the child obtained it (a ``spawn`` without display: ``save``)."""
        return str(self._child_info().get("mode", self._mode))

    @property
    def path(self) -> Path | None:
        """The .rrd the child writes (None: a viewer only)."""
        p = self._child_info().get("path", self._path)
        return None if p is None else Path(p)

    def _child_info(self) -> dict:
        if self._proc is not None and self._ready is None:
            self._got_ready.wait(_READY_TIMEOUT)
        return self._ready or {}

    # ---- the loop's side: a deque append ------------------------------------------------------------
    def _put(self, name: str, args: tuple, kwargs: dict) -> None:
        if self._thread is None or self._stop:
            return
        q = self._queue
        if len(q) >= MAX_BACKLOG:
            q.popleft()
            self.dropped += 1
        q.append((name, args, kwargs))
        self._wake.set()

    def __getattr__(self, name: str) -> Callable[..., None]:
        """Every ``log_*`` method of :class:`~teleop.rerun.logger.RerunLogger` (``log_scalars``,
        ``log_profile``, ``log_phase``, ``log_master``, ``log_state``, ``log_joint``, any later one):
        queued with its arguments, arrays copied now (the loop may reuse them)."""
        if not name.startswith("log_"):
            raise AttributeError(name)

        def queue(*args: Any, **kwargs: Any) -> None:
            self._put(name, _copied(args), {k: _copied(v) for k, v in kwargs.items()})
        queue.__name__ = name
        self.__dict__[name] = queue            # found directly from now on
        return queue

    # ---- the sender thread ---------------------------------------------------------------------------
    def _send(self, obj: Any) -> bool:
        """Pickle ``obj`` onto the present child's stdin; False once the child is gone."""
        data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
        with self._lock:
            return self._proc is not None and write_bytes(self._proc, data)

    def _drain(self) -> bool:
        q = self._queue
        with self._rotating:                   # the sender, a flush and a close may drain at once: none of them
            if q and time.monotonic() >= self._segment_end and not self._stop:   # sends while the child changes
                self._next_segment()
        while q:
            IDLE.wait(BATCH_COST)              # pickle while the control loop sleeps (teleop/timing/realtime.py)
            batch, cost = [], 0
            while q and cost < BATCH:          # pickling is one C call: ~0.2 ms at most
                call = q.popleft()
                batch.append(call)
                cost += HEAVY if call[0] in _ARRAYS else 1
            if not self._send(batch):
                log.warning("rerun logging process gone: %d calls not logged", len(batch) + len(q))
                q.clear()
                return False
        return True

    def _run(self) -> None:
        while not self._stop:
            self._wake.wait(0.05)
            self._wake.clear()
            if not self._drain():
                return

    def _read(self, proc: subprocess.Popen, primary: bool) -> None:
        """A child's stdout: its first line (mode, path: the first child's is the logger's), then one
        ``flushed`` per flush; the end of the present child's stdout releases a waiting flush."""
        assert proc.stdout is not None
        first = True
        for line in proc.stdout:
            if first:
                first = False
                if primary:
                    try:
                        self._ready = json.loads(line)
                    except ValueError:
                        self._ready = {}
                    self._got_ready.set()
            elif line.strip() == b"flushed":
                self._flushed.set()
        if first and primary:
            self._ready = {}
            self._got_ready.set()
        if proc is self._proc:
            self._flushed.set()

    # ---- end -----------------------------------------------------------------------------------------
    def flush(self, timeout: float = 10.0) -> None:
        """Send every queued call and wait until the child has made them and flushed its sink (at most
        ``timeout`` [s])."""
        if self._proc is None or self._stop:
            return
        self._drain()
        self._flushed.clear()
        if self._send("flush"):
            self._flushed.wait(timeout)

    def close(self, timeout: float = 30.0) -> None:
        """Send the queued calls, then close: the child finalises the recording and exits (at most
        ``timeout`` [s], then it is killed). Idempotent."""
        proc = self._proc
        if proc is None or self._stop:
            return
        self._stop = True
        self._wake.set()
        if self._thread is not None and self._thread.is_alive():
            self._thread.join(timeout)
        self._drain()
        self._send(None)
        with self._lock:
            proc = self._proc
            assert proc is not None
            close_stdin(proc)
        for child in [*self._retired, proc]:     # every segment's child finalises its file
            try:
                child.wait(timeout)
            except subprocess.TimeoutExpired:
                log.warning("rerun logging process did not finish within %g s: killed", timeout)
                child.kill()
                child.wait()
        if self.dropped:
            log.warning("rerun: %d calls dropped (the logging process fell behind)", self.dropped)

    def __enter__(self) -> RerunProcessLogger:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _copied(v: Any) -> Any:
    """``v`` with every array in it copied (tuples and lists of arrays too); anything else as is."""
    if isinstance(v, np.ndarray):
        return v.copy()
    if isinstance(v, (tuple, list)) and any(isinstance(x, (np.ndarray, tuple, list)) for x in v):
        return type(v)(_copied(x) for x in v)
    return v


def _check(mode: str, path) -> None:
    from teleop.errors import ConfigError
    from teleop.rerun.logger import MODES
    if mode not in MODES:
        raise ConfigError(f"recording.rerun: expected one of {', '.join(MODES)}, got {mode!r}")
    if mode == "save" and path is None:
        raise ConfigError("recording.rerun: mode 'save' needs a path for the .rrd file")


def main() -> int:
    """The child: read the logger's arguments, then batches of calls, from stdin until None or EOF."""
    import signal
    signal.signal(signal.SIGINT, signal.SIG_IGN)   # Ctrl-C reaches the whole process group: the side closes us
    from teleop.rerun.logger import RerunLogger
    inp, out = sys.stdin.buffer, sys.stdout.buffer
    try:
        args, kwargs = pickle.load(inp)
    except EOFError:
        return 0
    try:
        logger = RerunLogger(*args, **kwargs)
    except OSError as e:                 # 'serve': the port taken; the side goes on without its view
        print(f"rerun: {e}", file=sys.stderr)
        return 1
    out.write(json.dumps({"mode": logger.mode, "path": None if logger.path is None else str(logger.path)}).encode()
              + b"\n")
    out.flush()
    failed = 0
    try:
        while True:
            try:
                msg = pickle.load(inp)
            except EOFError:                 # the side ended or was killed: finalise what we have
                break
            if msg is None:
                break
            if msg == "flush":
                logger.flush()
                out.write(b"flushed\n")
                out.flush()
                continue
            for name, a, kw in msg:
                try:
                    getattr(logger, name)(*a, **kw)
                except Exception as e:  # noqa: BLE001 - a logging problem must not end the logging
                    failed += 1
                    if failed <= 3:
                        print(f"rerun logging failed: {name}: {e!r}", file=sys.stderr)
    finally:
        logger.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
