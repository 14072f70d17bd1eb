"""The sides' write-ahead journal (teleop/recording/journal.py) and the recorder completing its recording from it
(live/record/journal.py): rotation, torn records, incremental reading, recovery of exactly what
was journaled and not received, on a real zenoh session pair on 127.0.0.1 (waits bounded)."""
from __future__ import annotations

import dataclasses
import time

from live.record.recorder import Recorder, read_messages
from teleop.config.schema import Config, TransportConfig
from teleop.recording import journal
from teleop.recording.journal import Journal, JournalReader, journal_segments, pack_record, read_records
from teleop.session.transport import Session, free_tcp_port, loopback_endpoint
from teleop.wire.codec import decode, encode
from teleop.wire.keys import command_key
from teleop.wire.messages import Command


def test_journal_rotates_keeps_the_newest_segments_and_reads_incrementally(tmp_path):
    j = Journal(tmp_path, "slave", segment_bytes=1000, keep=2)
    reader = JournalReader(tmp_path, "slave")
    payloads = [encode(Command(k, 0.0, (1e-3 * k,))) for k in range(100)]
    for p in payloads[:10]:
        j.append("a/b/slave/command", p)
    first = list(reader.new_records())
    assert [r[2] for r in first] == payloads[:10] and all(r[1] == "a/b/slave/command" for r in first)
    assert list(reader.new_records()) == []                       # nothing new
    for p in payloads[10:]:
        j.append("a/b/slave/command", p)
    j.close()
    segs = journal_segments(tmp_path)["slave"]
    assert len(segs) == 2 and all(s.stat().st_size <= 1000 for s in segs)   # older segments deleted
    rest = [r[2] for r in reader.new_records()]
    assert rest == payloads[-len(rest):] and len(rest) < 90     # the newest, in order, none twice
    assert Journal(tmp_path, "slave")._n == int(segs[-1].name[-3:]) + 1      # a restart opens a new segment


def test_read_records_leaves_a_torn_record_for_later():
    one, two = pack_record(1.0, b"k", b"abc"), pack_record(2.0, b"k", b"defg")
    recs, end = read_records(one + two[:-2])
    assert recs == [(1.0, "k", b"abc")] and end == len(one)
    recs, end = read_records(one + two, end)
    assert recs == [(2.0, "k", b"defg")] and end == len(one + two)


def test_publisher_journals_before_the_put(tmp_path):
    port = free_tcp_port()
    with Session(TransportConfig(listen=(loopback_endpoint(port),), connect=())) as s:
        pub = s.publisher("x/y/master/command")
        journal.open_journal(tmp_path, "master")
        try:
            for k in range(3):
                pub.put(Command(k, 0.0, (0.0,)))
        finally:
            journal.close_journal()
        pub.put(Command(3, 0.0, (0.0,)))                           # journal closed: not journaled
    recs = list(JournalReader(tmp_path, "master").new_records())
    assert [decode(p).seq for _, _, p in recs] == [0, 1, 2] and journal.JOURNAL is None


def _cfg() -> Config:
    c = Config()
    return dataclasses.replace(c, instrument=dataclasses.replace(c.instrument, id="jr1"),
                               recording=dataclasses.replace(c.recording, rerun="off", flush_interval=0.01, csv="all"))


def test_recorder_recovers_exactly_what_was_journaled_and_not_received(tmp_path):
    port = free_tcp_port()
    key = command_key("jr1")
    run = tmp_path / "run"
    with Session(TransportConfig(listen=(loopback_endpoint(port),), connect=())) as rs, \
            Session(TransportConfig(listen=(), connect=(loopback_endpoint(port),))) as side:
        rec = Recorder(rs, _cfg(), run / "recorder")
        j = Journal(run, "master")
        pub = side.publisher(key)
        deadline = time.monotonic() + 5.0
        while not pub._handle.matching_status.matching:
            assert time.monotonic() < deadline
            time.sleep(0.01)
        for k in range(50):                # journaled; 20..24 lost on the way, 40..49 "killed" before the put
            payload = encode(Command(k, 1e-3 * k, (1e-5 * k,)))
            j.append(key, payload)
            if k < 40 and not 20 <= k < 25:
                pub.put_bytes(payload)
            time.sleep(1e-3)
        j.close()
        while rec.streams.get(key) is None or rec.streams[key].count < 35:
            assert time.monotonic() < deadline
            time.sleep(0.01)
        s = rec.close()
    st = s["streams"][key]
    assert (st["count"], st["received"], st["recovered"], st["missing"], st["last_seq"]) == (50, 35, 15, 0, 49)
    assert s["recovered_from_journals"]["recovered"] == {"master": 15}
    seqs = [decode(p).seq for _, k, p in read_messages(run / "recorder" / "messages.bin") if k == key]
    assert sorted(seqs) == list(range(50))                         # each once
    rows = (run / "recorder" / "recovered.csv").read_text().strip().splitlines()[-15:]
    assert sorted(int(r.rsplit(",", 1)[1]) for r in rows) == [*range(20, 25), *range(40, 50)]
    lines = [ln for ln in (run / "recorder" / "master_command.csv").read_text().splitlines() if not ln.startswith("#")]
    rows = [[float(v) for v in ln.split(",")] for ln in lines[1:]]             # after the header
    # every seq once, the rows in time order (a recovered row carries its publish time, a received one its
    # receive time: under load a delivery can take longer than the gap between two puts, so not seq order)
    assert sorted(r[1] for r in rows) == list(range(50))
    assert all(a[0] < b[0] for a, b in zip(rows, rows[1:], strict=False))
