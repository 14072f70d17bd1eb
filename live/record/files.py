"""The recorder's files and counters (:mod:`live.record.recorder`): decoding any payload of this project,
flattening a decoded message into named numbers generically, the per-stream CSV in the measured-data
format, and the per-stream counters of the summary.
"""
from __future__ import annotations

import dataclasses
import enum
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import zstandard

from teleop.wire.codec import MAGIC, decode, seq_newer

__all__ = ["decode_any", "flatten", "short_names", "values", "values_of", "StreamCsv", "StreamCounts"]

_SI = {"T": "N", "x": "m", "e": "m", "t": "s"}
_fields_cache: dict[type, tuple[str, ...]] = {}


_DECODERS: dict = {}   # first (magic) byte -> decoder; filled at the end of the module


def _decoders() -> dict:
    """Decoder by first (magic) byte: the teleop codec, and the rig interface when present."""
    out: dict[int, Any] = {MAGIC: decode}
    try:
        from teleop.wire.rig import RIG_MAGIC, decode_rig
        out[RIG_MAGIC] = decode_rig
    except ImportError:   # pragma: no cover - a build without the rig interface
        pass
    return out


def decode_any(payload: bytes):
    """Decode a payload of any byte format of this project (by its magic byte).

    Raises
    ------
    CodecError
        Empty, an unknown magic byte, or what the format's decoder raises.
    """
    fn = _DECODERS.get(payload[0]) if payload else None
    return decode(payload) if fn is None else fn(payload)    # unknown: the codec's own error message


def flatten(msg, prefix: str = "", out: list | None = None) -> list[tuple[str, float | int]]:
    """``[(column name, number), ...]`` of a decoded message, generically over its dataclass fields.

    Nested dataclasses join names with ``.``, tuples index with ``[i]``; enums and booleans become
    integers. Works for whatever message types :mod:`teleop.wire.codec` decodes.
    """
    out = [] if out is None else out
    if dataclasses.is_dataclass(msg):
        names = _fields_cache.get(type(msg))
        if names is None:
            names = _fields_cache[type(msg)] = tuple(f.name for f in dataclasses.fields(msg))
        for n in names:
            flatten(getattr(msg, n), f"{prefix}.{n}" if prefix else n, out)
    elif isinstance(msg, (tuple, list)):
        for i, v in enumerate(msg):
            flatten(v, f"{prefix}[{i}]", out)
    elif isinstance(msg, (bool, enum.Enum)):
        out.append((prefix, int(msg.value) if isinstance(msg, enum.Enum) else int(msg)))
    else:
        out.append((prefix, msg))
    return out


def values(x, out: list) -> None:
    """The numbers of :func:`flatten` without the names (the writer's per-message path, ~10x faster)."""
    if dataclasses.is_dataclass(x):
        names = _fields_cache.get(type(x))
        if names is None:
            names = _fields_cache[type(x)] = tuple(f.name for f in dataclasses.fields(x))
        for n in names:
            values(getattr(x, n), out)
    elif isinstance(x, (tuple, list)):
        if all(type(v) is float for v in x):      # a profile: one extend
            out.extend(x)
        else:
            for v in x:
                values(v, out)
    elif isinstance(x, (bool, enum.Enum)):
        out.append(int(x.value) if isinstance(x, enum.Enum) else int(x))
    else:
        out.append(x)


def values_of(x, out: list) -> list:
    """``out``, filled with the numbers of ``x`` (:func:`values`) when it is empty (a message's numbers once)."""
    if not out:
        values(x, out)
    return out


def short_names(names) -> tuple[str, ...]:
    """Column names: a nested field keeps only its own name where that is unambiguous in the message
    (``axes[0].tendons[0].T_in`` -> ``T_in`` on a single tendon, so the file loads as measured data),
    the full path where it is not (two axes, two tendons) or would clash with another column."""
    leaves = [n.rsplit(".", 1)[-1] for n in names]
    count: dict[str, int] = {}
    for x in leaves:                      # a top-level name is its own leaf: a nested namesake keeps its path
        count[x] = count.get(x, 0) + 1
    return tuple(leaf if "." in n and count[leaf] == 1 else n for n, leaf in zip(names, leaves, strict=False))


def _unit(name: str) -> str | None:
    leaf = name.rsplit(".", 1)[-1].split("[")[0]
    if leaf.startswith(("T_", "profile")):
        return "N"
    if leaf.startswith(("x_", "elongation")):
        return "m"
    if leaf.startswith("t_"):
        return "s"
    if leaf.startswith("angle"):
        return "rad"
    if leaf.startswith("torque"):
        return "N m"
    return None


class StreamCsv:
    """One measured-data CSV of one stream (columns fixed by its first message)."""

    def __init__(self, path: Path, names: tuple[str, ...], sample: list, meta: dict[str, str]):
        self.path, self.names = path, names
        cols = ("time",) + names
        units = [f"{c}={u}" for c in cols if (u := ("s" if c == "time" else _unit(c)))]
        self.fmt = ",".join(["%.12g"] + ["%d" if isinstance(v, int) else "%.12g" for _, v in sample]) + "\n"
        self.fh = open(path, "w", encoding="utf-8")
        head = [f"# {k}: {v}" for k, v in meta.items()] + ["# units: " + ", ".join(units), ",".join(cols)]
        self.fh.write("\n".join(head) + "\n")
        self.head_lines = len(head)
        self.rows = 0
        self.last_t = -math.inf
        self.unsorted = False           # a row older than the one before it (a message recovered into a gap)

    def write(self, t: float, values: tuple) -> None:
        self.fh.write(self.fmt % ((t,) + values))
        self.rows += 1
        if t <= self.last_t:
            self.unsorted = True
        self.last_t = max(self.last_t, t)

    def close(self) -> None:
        """Close the file; when rows came out of time order, rewrite them sorted by time (stable)."""
        self.fh.close()
        if not self.unsorted:
            return
        lines = self.path.read_text(encoding="utf-8").splitlines(keepends=True)
        head, rows = lines[:self.head_lines], lines[self.head_lines:]
        rows.sort(key=lambda r: float(r.split(",", 1)[0]))
        self.path.write_text("".join(head + rows), encoding="utf-8")
        self.unsorted = False


class StreamSample:
    """A stream written to no CSV (``recording.csv: low_rate``): an evenly thinned copy of its rows, in
    memory, for ``streams.png``. Every :data:`SAMPLE_EVERY`-th message is kept; at :data:`SAMPLE_ROWS`
    rows every other one is dropped and the stride doubles. The rows live in one array of
    :data:`SAMPLE_ROWS` rows, allocated and touched at the stream's first message (8 bytes a number: about
    10 MB for a 1 kHz estimate of 60 numbers), so the recorder's memory is at its size from the start of
    a session, not growing over its first minutes."""

    def __init__(self, name: str, names: tuple[str, ...]):
        self.name, self.names = name, names
        self.data = np.full((SAMPLE_ROWS, 1 + len(names)), np.nan)   # written now: resident from the start
        self.count = 0                      # rows kept in ``data``
        self.every, self.n = SAMPLE_EVERY, 0

    def write(self, t: float, values: list | Callable[[], list]) -> None:
        """One message at ``t`` [s], its numbers (or a function giving them, called only for a kept row).

        Raises
        ------
        ValueError
            The message has another count of numbers than the stream's names.
        """
        if self.n % self.every == 0:
            row = self.data[self.count]
            row[0] = t
            row[1:] = values() if callable(values) else values
            self.count += 1
            if self.count >= SAMPLE_ROWS:
                half = SAMPLE_ROWS // 2
                self.data[:half] = self.data[0:SAMPLE_ROWS:2]
                self.count, self.every = half, self.every * 2
        self.n += 1

    def stream(self):
        """The rows as a :class:`live.record.figures.Stream` (units as a CSV's ``# units:`` line)."""
        from live.record.figures import Stream
        cols = ("time",) + tuple(self.names)
        units = {c: u for c in cols if (u := ("s" if c == "time" else _unit(c)))}
        data = self.data[:self.count].copy() if self.count else np.empty((0, 0))
        return Stream(self.name, list(cols), data, units)


class StreamCounts:
    """Counters of one key: messages, seqs missing (gaps), duplicates or out of order, decode errors."""

    def __init__(self):
        self.count = self.errors = self.missing = self.dup_or_old = self.recovered = 0
        self.first_seq = self.last_seq = None
        self.t_first = self.t_last = None
        self.type = None

    def see(self, seq, t: float) -> None:
        self.count += 1
        self.t_first = t if self.t_first is None else self.t_first
        self.t_last = t
        if seq is None:
            return
        if self.first_seq is None:
            self.first_seq = self.last_seq = seq
        elif seq_newer(seq, self.last_seq):
            self.missing += (seq - self.last_seq) % (1 << 32) - 1
            self.last_seq = seq
        else:
            self.dup_or_old += 1

    def fill(self, seq, t: float) -> None:
        """A message recovered from the sender's journal (teleop/recording/journal.py): the tail after the last
        received seq extends the stream, an older seq fills a gap."""
        self.recovered += 1
        if seq is None or self.last_seq is None or seq_newer(seq, self.last_seq):
            self.see(seq, t)
        else:
            self.count += 1
            self.missing = max(0, self.missing - 1)

    def summary(self) -> dict:
        span = (self.t_last - self.t_first) if self.count > 1 else 0.0
        return {"type": self.type, "count": self.count, "received": self.count - self.recovered,
                "recovered": self.recovered, "first_seq": self.first_seq, "last_seq": self.last_seq,
                "missing": self.missing, "duplicate_or_old": self.dup_or_old, "decode_errors": self.errors,
                "rate_hz": (self.count - 1) / span if span > 0 else 0.0}


_DECODERS.update(_decoders())


SAMPLE_EVERY = 10       # [messages] stride of a StreamSample at first
SAMPLE_ROWS = 20000     # [rows] a StreamSample thins itself to half at this many
ZSTD_MAGIC = b"\x28\xb5\x2f\xfd"   # first bytes of a zstd frame
_BLOCK = 1 << 16


class ZstdStream:
    """An append-only file holding one zstd stream (level 3): :meth:`flush` ends a block and hands it to
    the OS, so a reader decodes everything up to the last flush even when the writer is killed.

    Parameters
    ----------
    path : Path
        Created (truncated).
    """

    def __init__(self, path: Path):
        self.fh = open(path, "wb")
        self.name = str(path)
        self._c = zstandard.ZstdCompressor(level=3).compressobj()

    @property
    def closed(self) -> bool:
        return self.fh.closed

    def write(self, data: bytes) -> None:
        """Compress ``data`` into the stream (written with the next block)."""
        self.fh.write(self._c.compress(data))

    def flush(self) -> None:
        """End the block under way and hand the file to the OS."""
        self.fh.write(self._c.flush(zstandard.COMPRESSOBJ_FLUSH_BLOCK))
        self.fh.flush()

    def close(self) -> None:
        """End the frame and close the file. Idempotent."""
        if not self.fh.closed:
            try:
                self.fh.write(self._c.flush())
            finally:
                self.fh.close()


def stream_bytes(path: str | Path) -> bytes:
    """The content of a file written by :class:`ZstdStream` (decoded up to its last whole block: a file cut
    by a kill or a full disk gives what was flushed before) or of a plain file (as it is)."""
    data = Path(path).read_bytes()
    if not data.startswith(ZSTD_MAGIC):
        return data
    d, out = zstandard.ZstdDecompressor().decompressobj(), []
    for i in range(0, len(data), _BLOCK):
        try:
            out.append(d.decompress(data[i:i + _BLOCK]))
        except zstandard.ZstdError:
            break
        if d.eof:
            break
    return b"".join(out)
