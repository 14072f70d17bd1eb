"""``teleop record``: a process of its own that writes every message of an instrument, losing none.

It subscribes to ``teleop/<id>/**`` (commands, estimates, heartbeats, anything a later wire version
adds) and to the liveliness tokens of both sides, and writes ``<run dir>/recorder/``:

* ``messages.bin``: every payload as received, ``<d t_recv [s]><H key length><I payload length>`` then the
  key and the codec bytes, zstd-compressed (the lossless record; :func:`read_messages` reads it back); a
  message recovered from a journal carries its publish time instead;
* ``<side>_<stream>.csv`` per key of a heartbeat stream (with ``recording.csv: all``: of every stream), in the
  measured-data format (``# key: value`` metadata, ``# units:``, header, one row per message, in time order): ``time``
  is the recorder's receive time [s, monotonic] (a message recovered from a journal: its publish time, same clock on one
  machine), then every field of the message as :mod:`teleop.wire.codec` decoded it, flattened generically over the
  dataclass fields (``profiles[0][3]``, ``axes[1].tendons[0].T_in``; enums and flags as integers); a nested field keeps
  only its own name where that is unambiguous (:func:`short_names`), so the estimate file of a single tendon (``x_in``,
  ``T_in``) loads with
  :func:`teleop.recording.measured_csv.read_measured_csv`;
* ``state_changes.csv`` (every change of a heartbeat's state), ``liveliness.csv`` and ``recovered.csv``
  (``time,side,key,seq`` of every message taken from a side's journal, see below);
* ``session.mcap``: the messages again in one MCAP file (of a 1 kHz stream every ``recording.mcap_every``-th),
  ROS 2 types where one exists, JSON for the rest (:mod:`live.record.mcap_file`; ``teleop record --repair RUN``
  rebuilds it after a SIGKILL of the recorder, :mod:`live.record.mcap_read`);
* ``record.rrd`` (Rerun, scalar fields decimated by ``recording.log_every``), and at the end ``summary.json`` (per
  stream: count, received, recovered, first/last seq, seqs missing, messages not written, duplicates, rate; the
  command -> echo delay seen here; its streams' counts are the last line printed) and ``streams.png``.

Disk use is bounded by ``recording.max_bytes`` and ``recording.min_free_bytes``, and a write the OS
refuses costs only its own file (:mod:`live.record.budget`, ``disk`` in ``summary.json``).

Nothing runs on zenoh's callback thread but a queue put: a writer thread decodes, formats and
writes, handing the files to the OS at least every ``recording.flush_interval`` seconds, so a SIGKILL
of the slave or the master loses nothing that reached the recorder (and a SIGKILL of the recorder
itself at most that interval). Subscribers are reliable; the publishers drop only under congestion.

What a SIGKILL catches inside a side (still in its zenoh queue) is kept by the side's write-ahead
journal (:mod:`teleop.recording.journal`, ``<run dir>/<side>.journal-NNN``): when a side's liveliness is lost
and at the end, the recorder adds every journaled message it did not receive
(:mod:`live.record.journal`), counted per stream as ``recovered`` in ``summary.json`` (with
``received``) and listed in ``recovered.csv``. That needs the journals reachable: same machine, or a
run directory both share (docs/reference/formats.md); ``--journals DIR`` names another (a bimanual session's,
for each arm's recorder in ``<run dir>/<arm id>``): only the records of the recorder's own keys are taken.
"""
from __future__ import annotations

import json
import logging
import queue
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Literal

from live.record.beside_demo import print_last_line
from live.record.budget import LOW_RATE_HZ, DiskBudget, Writes, is_low_rate
from live.record.files import (
    StreamCounts,
    StreamCsv,
    StreamSample,
    ZstdStream,
    decode_any,
    flatten,
    short_names,
    stream_bytes,
    values_of,
)
from live.record.journal import JournalRecovery
from teleop.recording.journal import RECORD, pack_record, read_records
from teleop.session.entity import Entity
from teleop.timing.latency import LatencyHistogram
from teleop.wire.keys import instrument_keys, liveliness_pattern

__all__ = ["Recorder", "read_messages", "run_record"]

log = logging.getLogger("live.record.recorder")
_RAW = RECORD         # <d t><H key length><I payload length>, then key and payload (teleop/recording/journal.py)
_STOP = object()


def _raise(e: Exception) -> None:
    raise e


class _Subscription(Entity):
    """A plain zenoh subscriber with a callback, closed with its session."""

    def __init__(self, session, key: str, callback):
        super().__init__(session, key)
        self._declare(session.zenoh_session.declare_subscriber, key, callback)


class Recorder:
    """Subscribe to every stream of ``cfg.instrument.id`` on ``session`` and write ``out_dir`` (module docstring).

    Parameters
    ----------
    session : teleop.session.transport.Session
    cfg : Config
        ``instrument.id``, ``recording`` (``flush_interval`` [s], ``log_every``, ``rerun``).
    out_dir : Path
        Created; the files of the module docstring go there.
    rerun : {'save', 'spawn', 'off'}, optional
        Overrides ``recording.rerun``.
    journal_dir : Path, optional
        Where the sides' journals are (default: the run directory, ``out_dir``'s parent); records of ``teleop/<id>/**``
        only.
    """

    def __init__(self, session, cfg, out_dir: Path, *, rerun: Literal["save", "spawn", "off"] | None = None,
                 run_id: str = "", journal_dir: Path | None = None):
        self.cfg, self.dir = cfg, Path(out_dir)
        self.dir.mkdir(parents=True, exist_ok=True)
        self.clock = session.clock
        self.ident = cfg.instrument.id
        self.flush_interval = cfg.recording.flush_interval
        self.streams: dict[str, StreamCounts] = {}
        self._fast = 0                                  # 1 kHz streams seen (commands, estimates, rig)
        self.alive: dict[str, bool] = {}
        self.ever_alive: set[str] = set()
        self.state_changes: list[dict] = []
        self._states: dict[str, int] = {}
        self._csv: dict[tuple, StreamCsv | None] = {}   # (key, message type, value count) -> its file (None: none)
        self._names: dict[tuple, tuple] = {}
        self._shapes: dict[tuple, tuple] = {}           # (key, message type, payload length) -> its shape
        self._samples: dict[tuple, StreamSample] = {}   # a stream without a CSV: its thinned rows for streams.png
        self.budget = DiskBudget(self.dir.parent, cfg.recording.max_bytes, cfg.recording.min_free_bytes,
                                 own=self.dir.name)
        self.budget.live = (self.dir / "live.json", lambda: {k: [s.count, s.missing] for k, s in self.streams.items()})
        self.writes = Writes()
        self._low_t: dict[str, float] = {}             # key -> time of its last low-rate message written
        self._cmd_t: dict[int, float] = {}
        self._echo = LatencyHistogram()                 # command -> echo delays [s], constant memory
        self._echoed: set[int] = set()
        self._q: queue.SimpleQueue = queue.SimpleQueue()
        self._raw = ZstdStream(self.dir / "messages.bin")
        self._aux = {"state": self._aux_csv("state_changes.csv", "time,side,state,seq"),
                     "alive": self._aux_csv("liveliness.csv", "time,side,alive"),
                     "recovered": self._aux_csv("recovered.csv", "time,side,key,seq")}
        self.journals = JournalRecovery(Path(journal_dir or self.dir.parent), self.clock.now(),
                                        instrument_keys(self.ident))
        from live.record.mcap_file import MCAP_NAME, McapRecording
        self._mcap = McapRecording(self.dir / MCAP_NAME, cfg, time.time() - self.clock.now(), self.journals.t_start)
        from teleop.rerun.process import RerunProcessLogger as Rerun  # the SDK in a child per segment, not here
        self._rr = Rerun("teleop-record", run_id or None, rerun or cfg.recording.rerun, self.dir / "record.rrd")
        self._thread = threading.Thread(target=self._writer, name="teleop-record-writer", daemon=True)
        self._thread.start()
        session._track(_Subscription(session, instrument_keys(self.ident), self._on_sample))
        session.liveliness_watcher(liveliness_pattern(self.ident), self._on_alive)

    def _aux_csv(self, name: str, header: str):
        fh = open(self.dir / name, "w", encoding="utf-8")
        fh.write(f"# source: teleop record\n# instrument: {self.ident}\n# units: time=s\n{header}\n")
        return fh

    # ---- zenoh threads: a queue put and nothing else ------------------------------------------------
    def _on_sample(self, sample) -> None:
        self._q.put((self.clock.now(), str(sample.key_expr), sample.payload.to_bytes()))

    def _on_alive(self, key: str, up: bool) -> None:
        self._q.put((self.clock.now(), key, bool(up)))

    # ---- the writer thread --------------------------------------------------------------------------
    def _writer(self) -> None:
        last_flush = time.monotonic()
        while True:
            try:
                item = self._q.get(timeout=self.flush_interval)
            except queue.Empty:
                item = None
            if item is _STOP:
                break
            if item is not None:
                try:
                    self._handle(*item)
                except Exception as e:  # noqa: BLE001 - one bad message must not end the recording
                    log.warning("recorder: %s on %s: %r", type(e).__name__, item[1], e)
            for side in self.journals.due(time.monotonic()):
                self._recover(side)
            # the session's rate is measured once both sides' 1 kHz streams flow (a slave alone writes less)
            self.budget.check(time.monotonic(), self.clock.now(), measure=self._fast >= 2,
                              t_data=max((s.t_last or 0.0 for s in self.streams.values()), default=None))
            if time.monotonic() - last_flush >= self.flush_interval:
                self._flush()
                last_flush = time.monotonic()
        self._flush()

    def _flush(self) -> None:
        w = self.writes
        w.flush_record(self._raw.flush)
        for f in self._csv.values():
            if f is not None:
                w(f.path.name, f.fh.flush)
        for fh in self._aux.values():
            w(Path(fh.name).name, fh.flush)
        w("session.mcap", self._mcap.flush, time.monotonic())   # a chunk at least every record_mcap.CHUNK_INTERVAL

    def _handle(self, t: float, key: str, payload) -> None:
        if isinstance(payload, bool):
            side = key.split("/")[2] if key.count("/") >= 3 else key
            self.alive[side] = payload
            if payload:
                self.ever_alive.add(side)
            else:                                  # gone (killed or ended): complete it from its journal soon
                self.journals.schedule(side, time.monotonic())
            self.writes("liveliness.csv", self._aux["alive"].write, f"{t:.12g},{side},{int(payload)}\n")
            return
        self._record(t, key, payload, recovered=False)

    def _record(self, t: float, key: str, payload: bytes, *, recovered: bool) -> None:
        """Write one message (received, or ``recovered`` from its sender's journal) everywhere."""
        st = self.streams.get(key)
        if st is None:
            st = self.streams[key] = StreamCounts()
            self._fast += not is_low_rate(key)
        try:
            msg = decode_any(payload)
        except Exception:  # noqa: BLE001 - CodecError: counted, kept in messages.bin
            self.writes.message(key, self._raw.write, pack_record(t, key.encode(), payload))
            st.errors += 1
            st.count += 1
            return
        seq = getattr(msg, "seq", None)
        if not self.journals.note(key, payload, recovered, seq):
            return                                 # arrived after it was recovered: already recorded
        st.type = type(msg).__name__
        (st.fill if recovered else st.see)(seq, t)
        vals: list = []                           # the numbers, flattened only where needed (CSV, sample, Rerun)
        numbers = lambda: values_of(msg, vals)   # noqa: E731
        shape = self._shapes.get((key, payload[2], len(payload)))   # a codec layout's length fixes its shape
        if shape is None:                         # a new message shape on this key: names, units, a file
            shape = self._shapes[(key, payload[2], len(payload))] = (key, type(msg), len(numbers()))
            if shape not in self._names:
                self._open_csv(shape, flatten(msg))
        w, f = self.writes, self._csv[shape]
        if self._written(t, key, msg):
            w.message(key, self._raw.write, pack_record(t, key.encode(), payload))
            if recovered:
                side = key.split("/")[2] if key.count("/") >= 3 else key
                w("recovered.csv", self._aux["recovered"].write, f"{t:.12g},{side},{key},{seq}\n")
            if f is not None:
                w(f.path.name, f.write, t, tuple(numbers()))
            else:
                self._samples[shape].write(t, numbers)
            # a problem of the MCAP file costs no other file
            w("session.mcap", self._mcap.write, t, key, msg, recovered)
        else:
            w.skip(key)
        self._derived(t, key, msg, seq, self._names[shape], numbers, st.count)

    def _written(self, t: float, key: str, msg) -> bool:
        """Whether this message goes to the files: always below the disk budget; past it, a low-rate
        stream's at most LOW_RATE_HZ and at every state change, a high-rate stream's never."""
        if self.budget.reached is None:
            return True
        if not is_low_rate(key):
            return False
        state = getattr(msg, "state", None)
        side = key.split("/")[2] if key.count("/") >= 3 else key
        changed = state is not None and self._states.get(side) != int(state)
        if changed or t - self._low_t.get(key, -float("inf")) >= 1.0 / LOW_RATE_HZ:
            self._low_t[key] = t
            return True
        return False

    def _open_csv(self, shape: tuple, flat: list) -> None:
        """The column names of a new message shape, and its CSV unless ``recording.csv`` leaves it out
        (``low_rate``: the high-rate streams are in messages.bin and session.mcap only)."""
        key = shape[0]
        names = self._names[shape] = short_names([n for n, _ in flat])
        self._csv[shape] = None
        parts = key.split("/")
        stem = "_".join(parts[2:]) if len(parts) > 2 else parts[-1]
        n = sum(1 for s in self._names if s[0] == key) - 1
        path = self.dir / (f"{stem}.csv" if n == 0 else f"{stem}-{n + 1}.csv")
        if self.cfg.recording.csv != "all" and not is_low_rate(key):
            self._samples[shape] = StreamSample(path.stem, names)
            return
        meta = {"source": "teleop record", "instrument": self.ident, "key": key, "message": shape[1].__name__,
                "time": "recorder receive time (monotonic clock of the recorder)"}
        try:
            self._csv[shape] = StreamCsv(path, names, flat, meta)
        except OSError as e:
            self.writes(path.name, _raise, e)

    def _derived(self, t: float, key: str, msg, seq, names: tuple, vals: Callable[[], list], count: int) -> None:
        """State changes, the command -> echo delay, and the decimated Rerun scalars (``vals()``: the numbers)."""
        state = getattr(msg, "state", None)
        if state is not None and hasattr(msg, "side"):
            side = key.split("/")[2]
            if self._states.get(side) != int(state):
                self._states[side] = int(state)
                name = getattr(state, "name", str(state))
                self.state_changes.append({"time": t, "side": side, "state": name, "seq": seq})
                self.writes("state_changes.csv", self._aux["state"].write, f"{t:.12g},{side},{int(state)},{seq}\n")
        if key.endswith("/command") and seq is not None:
            self._cmd_t[seq] = t
            if len(self._cmd_t) > 20000:
                for k in list(self._cmd_t)[:10000]:
                    del self._cmd_t[k]
        echo = getattr(msg, "cmd_seq", None)
        if echo is not None and echo not in self._echoed and echo in self._cmd_t:
            self._echoed.add(echo)
            self._echo.add(t - self._cmd_t[echo])
            if len(self._echoed) > 20000:
                self._echoed.clear()
        if count % self.cfg.recording.log_every == 0 and self._rr.enabled and self.budget.reached is None:
            side = key.split("/")[2]
            scalars = {f"{side}_state" if n == "state" else n.replace("[", "").replace("]", "").replace(".", "_"):
                       float(v) for n, v in zip(names, vals(), strict=False)
                       if (n == "state" or isinstance(v, float)) and not n.startswith("t_") and "profile" not in n}
            self._rr.log_scalars(t, **scalars)

    def _recover(self, side: str | None) -> None:
        """Add what ``side``'s journal (every side's: None) has and the recording has not (recovered)."""
        for t, key, payload in self.journals.records(side):
            try:
                self._record(t, key, payload, recovered=True)
            except Exception as e:  # noqa: BLE001 - one bad record must not end the recovery
                log.warning("recorder: journal record on %s: %r", key, e)

    # ---- the end -------------------------------------------------------------------------------------
    def close(self) -> dict:
        """Stop the writer after the queued messages, complete the recording from the sides' journals,
        close the files, write ``summary.json`` and ``streams.png``; returns the summary. Idempotent."""
        if self._raw.closed:
            return self.summary()
        self._q.put(_STOP)
        self._thread.join(30.0)
        self._recover(None)
        w, csvs = self.writes, [f for f in self._csv.values() if f is not None]
        for f in csvs:
            w.close(f.path.name, f.close)          # sorted by time if a recovered message filled a gap
        for fh in self._aux.values():
            w.close(Path(fh.name).name, fh.close)
        w.close("messages.bin", self._raw.close)
        self._rr.close()
        w.close("session.mcap", self._mcap.close)
        s = self.summary()
        s["mcap"] = self._mcap.close() if "session.mcap" not in w.failed else {"error": w.failed["session.mcap"]}
        try:
            from live.record.figures import streams_figure
            s["figure"] = str(streams_figure([f.path for f in csvs] + [x.stream() for x in self._samples.values()],
                                             self.dir / "streams.png"))
        except Exception as e:  # noqa: BLE001 - a figure problem must not lose the summary
            s["figure_error"] = repr(e)
        try:
            (self.dir / "summary.json").write_text(json.dumps(s, indent=2) + "\n", encoding="utf-8")
        except OSError as e:
            log.error("recorder: summary.json not written (%s); not written per file: %s", e, s["disk"]["not_written"])
        return s

    def summary(self) -> dict:
        echo = self._echo.stats() if self._echo.n else {"n": 0}
        return {"instrument": self.ident,
                "streams": {k: {**s.summary(), "not_written": self.writes.messages_not_written(k)}
                            for k, s in sorted(self.streams.items())},
                "recovered_from_journals": self.journals.summary(),
                "files": sorted(str(f.path.name) for f in self._csv.values() if f is not None),
                "disk": {**self.budget.summary(), **self.writes.summary()},
                "state_changes": self.state_changes, "command_to_echo_at_recorder": echo}


def read_messages(path: str | Path):
    """Yield ``(t [s], key, payload bytes)`` from a ``messages.bin`` (a torn last record is ignored);
    ``t`` is the receive time, or the publish time of a message recovered from a journal."""
    yield from read_records(stream_bytes(path))[0]


def run_record(args) -> int:
    """``teleop record``: record until Ctrl-C/SIGTERM, ``--max-duration``, or (``--exit-when-done``)
    once every side seen has gone (liveliness) for half a second; ``--repair RUN``: rebuild RUN's MCAP file
    (:func:`live.record.mcap_read.repair`) and exit."""
    if getattr(args, "repair", None):
        from live.record.mcap_read import run_repair
        return run_repair(args.repair, getattr(args, "journals", None))
    from live.discovery import side_run_dir, side_session
    from teleop.config.load import load_config
    from teleop.recording.measured import raise_on_sigterm

    cfg = load_config(args.config)
    with raise_on_sigterm():
        session = side_session(cfg, args)
        with session:
            run_dir = side_run_dir(args, cfg)
            rec = Recorder(session, cfg, run_dir / "recorder", rerun=args.rerun, run_id=run_dir.name,
                           journal_dir=getattr(args, "journals", None))
            log.info("recording %s into %s", instrument_keys(cfg.instrument.id), rec.dir)
            print(f"teleop record: {rec.dir} (ready)", flush=True)
            t0, gone_since = time.monotonic(), None
            try:
                while args.max_duration is None or time.monotonic() - t0 < args.max_duration:
                    time.sleep(0.05)
                    if args.exit_when_done and rec.ever_alive:
                        anyone = any(rec.alive.values())
                        gone_since = None if anyone else (gone_since or time.monotonic())
                        if gone_since is not None and time.monotonic() - gone_since > 0.5:
                            break
            finally:                       # the last line on every way out, Ctrl-C and SIGTERM included
                code = print_last_line(rec.close(), rec.dir, cfg.instrument.id, rec.ever_alive)
    return code

