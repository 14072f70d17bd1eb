"""Reading the recorder's MCAP file back, and rebuilding it after a SIGKILL of the recorder.

:func:`read_session` reads a ``session.mcap`` (:mod:`live.record.mcap_file`) record by record, so a file
whose writer was killed reads up to its last whole chunk; :func:`estimate_data` turns its estimate
channel into the measured-data arrays ``teleop replay`` re-estimates; :func:`repair` (``teleop record
--repair RUN``) writes the file again from ``messages.bin`` (the recorder's lossless record, handed to
the OS every ``recording.flush_interval``) and the messages of the sides' journals that the recording
lacks (published after the recorder started), so that a killed recorder's MCAP holds every message
that reached it and every message the sides journaled.
"""
from __future__ import annotations

import json
import os
import struct
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from estimator.data import MeasuredData
from estimator.errors import DataError
from live.record.files import decode_any, stream_bytes
from live.record.journal import JournalRecovery
from live.record.mcap_file import MCAP_NAME, McapRecording, sender_stamp
from teleop.errors import ConfigError
from teleop.recording.journal import read_records
from teleop.wire.keys import instrument_keys

__all__ = ["Session", "read_session", "estimate_data", "find_mcap", "repair", "run_repair"]


@dataclass
class Session:
    """What :func:`read_session` found: ``messages[key]`` = ``[(log [s], publish [s], message dict), ...]``
    (the JSON channels, times on the recorder's monotonic clock), the ``teleop`` metadata, the ROS 2
    topics with their message counts, and whether the file ended before its footer (``torn``)."""

    metadata: dict[str, str] = field(default_factory=dict)
    messages: dict[str, list[tuple[float, float, dict]]] = field(default_factory=dict)
    ros_topics: dict[str, int] = field(default_factory=dict)
    torn: bool = False


def read_session(path: str | Path) -> Session:
    """Read every whole record of a ``session.mcap`` (a torn end is tolerated and reported as ``torn``).

    Raises
    ------
    DataError
        No such file, or not an MCAP file.
    """
    from mcap.exceptions import McapError
    from mcap.records import Channel, DataEnd, Footer, Message, Metadata
    from mcap.stream_reader import StreamReader

    p = Path(path)
    if not p.is_file():
        raise DataError(f"{p}: no such MCAP file")
    out, channels = Session(), {}
    offset = 0
    with open(p, "rb") as fh:
        try:
            for rec in StreamReader(fh, skip_magic=False).records:
                if isinstance(rec, Metadata) and rec.name == "teleop":
                    out.metadata = dict(rec.metadata)
                    offset = round(float(out.metadata.get("clock_offset_s", 0.0)) * 1e9)
                elif isinstance(rec, Channel):
                    channels[rec.id] = rec
                elif isinstance(rec, Message):
                    ch = channels[rec.channel_id]
                    if ch.message_encoding == "json":
                        out.messages.setdefault(ch.topic[1:], []).append(
                            ((rec.log_time - offset) * 1e-9, (rec.publish_time - offset) * 1e-9, json.loads(rec.data)))
                    else:
                        out.ros_topics[ch.topic] = out.ros_topics.get(ch.topic, 0) + 1
                elif isinstance(rec, (DataEnd, Footer)):
                    break
            else:
                out.torn = True
        except (McapError, struct.error, EOFError, ValueError, KeyError) as e:
            if not channels and not out.metadata:
                raise DataError(f"{p}: not a readable MCAP file ({e})") from None
            out.torn = True
    return out


def estimate_data(session: Session, source: str = "<mcap>") -> MeasuredData:
    """The single-tendon estimate channel as measured data: ``time`` [s] (log time, recorder's clock),
    ``T_in`` [N], ``x_in`` [m]; extra ``T_out_hat`` [N], ``elongation_hat`` [m], ``x_out_hat`` [m], ``phase``,
    ``seq``. Rows in log-time order; a repeated time keeps its first row.

    Raises
    ------
    DataError
        No estimate channel, or a joint instrument's (two tendons per axis, or several axes).
    """
    key = next((k for k in session.messages if k.endswith("/slave/estimate")), None)
    if key is None:
        raise DataError(f"{source}: no slave estimate channel in the MCAP file")
    rows = sorted(session.messages[key], key=lambda r: r[0])
    if any(len(m["axes"]) != 1 or len(m["axes"][0]["tendons"]) != 1 for _, _, m in rows):
        raise DataError(f"{source}: a joint instrument's estimates: replay reads single-tendon MCAP files")
    t = np.array([r[0] for r in rows])
    keep = np.concatenate(([True], np.diff(t) > 0)) if t.size else np.zeros(0, bool)
    rows = [r for r, k in zip(rows, keep, strict=False) if k]
    tend = [m["axes"][0]["tendons"][0] for _, _, m in rows]
    col = lambda name: np.array([x[name] for x in tend], dtype=float)   # noqa: E731
    return MeasuredData(time=t[keep], x_in=col("x_in"), T_in=col("T_in"),
                        extra={"T_out_hat": col("T_out_hat"), "elongation_hat": col("elongation_hat"),
                               "x_out_hat": np.array([m["axes"][0]["position_hat"] for _, _, m in rows]),
                               "phase": col("phase"), "seq": np.array([m["seq"] for _, _, m in rows], float)},
                        metadata={"source": "teleop record (MCAP)", "key": key}, source=source)


def find_mcap(run: str | Path) -> Path | None:
    """``RUN/recorder/session.mcap``, ``RUN/session.mcap`` or RUN itself when it is an ``.mcap`` file; else None."""
    p = Path(run)
    if p.suffix == ".mcap":
        return p
    for cand in (p / "recorder" / MCAP_NAME, p / MCAP_NAME):
        if cand.is_file():
            return cand
    return None


def _run_config(run_dir: Path, ident: str) -> Any:
    """The run's config (``config.yaml``; the defaults when it has none), for ``ident``."""
    import dataclasses

    from teleop.config.load import load_config
    from teleop.config.schema import Config
    cfg = load_config(run_dir / "config.yaml") if (run_dir / "config.yaml").is_file() else Config()
    return dataclasses.replace(cfg, instrument=dataclasses.replace(cfg.instrument, id=ident))


def repair(rec_dir: str | Path, journal_dir: str | Path | None = None) -> dict[str, Any]:
    """Write ``<rec_dir>/session.mcap`` again from ``<rec_dir>/messages.bin`` and the sides' journals.

    The clock offset, instrument and start time come from the old file's metadata record (a file torn
    anywhere after its first records still has it); without one, the offset is 0 and the start is the
    first message's time. Journal records published before the start, already in ``messages.bin``
    (same key, same payload bytes) or of another instrument's keys, are left out; the journals are in
    ``journal_dir`` (default: ``rec_dir``'s parent). Returns ``{"path", "messages", "from_messages_bin",
    "from_journals", "before": messages the old file held}``.

    Raises
    ------
    DataError
        No ``messages.bin`` in ``rec_dir``.
    """
    d = Path(rec_dir)
    raw = d / "messages.bin"
    if not raw.is_file():
        raise DataError(f"{d}: no messages.bin to rebuild {MCAP_NAME} from")
    records = read_records(stream_bytes(raw))[0]
    old = d / MCAP_NAME
    meta: dict[str, str] = {}
    before = 0
    if old.is_file():
        try:
            s = read_session(old)
            meta, before = s.metadata, sum(len(v) for v in s.messages.values())
        except DataError:
            pass
    t_first = min((t for t, _, _ in records), default=0.0)
    t_start = float(meta.get("t_start_s", t_first))
    ident = meta.get("instrument") or next((k.split("/")[1] for _, k, _ in records if k.count("/") >= 3), "unknown")
    try:
        keys: str | None = instrument_keys(ident)          # the recorder's own keys only
    except ConfigError:
        keys = None
    journals = JournalRecovery(d.parent if journal_dir is None else Path(journal_dir), t_start, keys)
    all_records = []
    for t, key, payload in records:
        journals.note(key, payload, False)
        all_records.append((t, key, payload))
    extra = list(journals.records(None))
    tmp = d / (MCAP_NAME + ".repair")
    every = int(meta["mcap_every"]) if meta.get("mcap_every", "").isdigit() else None   # as the recorder kept them
    mc = McapRecording(tmp, _run_config(d.parent, ident), float(meta.get("clock_offset_s", 0.0)), t_start, every)
    entries = _log_order(all_records, extra)
    for t, key, msg in entries:
        mc.write(t, key, msg)
    mc.close()
    os.replace(tmp, old)
    return {"path": str(old), "messages": len(entries), "from_messages_bin": len(all_records),
            "from_journals": len(extra), "before": before}


def _log_order(received: list, recovered: list) -> list[tuple[float, str, Any]]:
    """``(log time [s], key, message)`` of every decodable record, in log-time order. Per key, in the order
    of the senders' stamps, a log time is raised to the one before it where it is earlier (a journal time
    precedes the receive time of a message published just before it), so that log and publish times order
    each topic alike; a record that does not decode is left out, as the live recorder leaves it out."""
    by_key: dict[str, list[tuple[float, float, int, Any]]] = {}
    for i, (t, key, payload) in enumerate(received + recovered):
        try:
            msg = decode_any(payload)
        except Exception:  # noqa: BLE001 - CodecError
            continue
        stamp = sender_stamp(msg)
        by_key.setdefault(key, []).append((t if stamp is None else stamp, t, i, msg))
    out = []
    for key, rows in by_key.items():
        rows.sort(key=lambda r: (r[0], r[2]))
        last = -np.inf
        for _, t, _, msg in rows:
            last = max(last, t)
            out.append((last, key, msg))
    out.sort(key=lambda r: r[0])
    return out


def run_repair(run: str | Path, journal_dir: str | Path | None = None) -> int:
    """``teleop record --repair RUN [--journals DIR]``: RUN is a run directory or its ``recorder/``; the
    journals are in ``journal_dir`` (default: RUN's run directory); prints one line."""
    p = Path(run)
    rec_dir = p if (p / "messages.bin").is_file() else p / "recorder"
    res = repair(rec_dir, journal_dir)
    print(f"teleop record --repair: {res['messages']} messages ({res['from_messages_bin']} from messages.bin, "
          f"{res['from_journals']} from the journals; the old file held {res['before']}) -> {res['path']}",
          flush=True)
    return 0


def iter_topics(session: Session) -> Iterator[tuple[str, int]]:
    """``(topic, messages)`` of every channel: the JSON ones, then the ROS 2 ones."""
    for k, v in sorted(session.messages.items()):
        yield "/" + k, len(v)
    yield from sorted(session.ros_topics.items())
