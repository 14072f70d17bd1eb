"""A bimanual side journals both arms' messages in one journal in the session's run directory
(live/bimanual_sides.py), and each arm's recorder runs in ``<run dir>/<arm id>``: the recorder reads the
journals of the directory it is given (``--journals``) and recovers only the records of its own keys; the
other arm's records are counted as left out, never recorded nor counted as missing."""
from __future__ import annotations

import dataclasses

from estimator.phase import Phase
from live.record.journal import JournalRecovery
from live.record.recorder import Recorder
from teleop.config.schema import Config, TransportConfig
from teleop.recording.journal import Journal
from teleop.session.transport import Session, free_tcp_port, loopback_endpoint
from teleop.wire.codec import encode
from teleop.wire.keys import estimate_key, instrument_keys
from teleop.wire.messages import tendon_estimate

ARMS = ("notes_left", "notes_right")


def _estimate(seq: int, tension: float) -> bytes:
    return encode(tendon_estimate(seq, seq, 1e-3 * seq, tension, 1e-4, 1.5, 1e-5, 1e-4, Phase.HOLD, (2.0, 1.0)))


def _journal_both_arms(run_dir, n: int) -> dict[str, list[bytes]]:
    """The slave's journal in ``run_dir`` with ``n`` estimates of each arm, interleaved as one loop publishes
    them; returns each arm's payloads by seq."""
    j = Journal(run_dir, "slave")
    sent: dict[str, list[bytes]] = {a: [] for a in ARMS}
    for seq in range(n):
        for i, arm in enumerate(ARMS):
            payload = _estimate(seq, 2.0 + seq + 0.5 * i)    # the arms' payloads differ, as their states do
            j.append(estimate_key(arm), payload)
            sent[arm].append(payload)
    j.close()
    return sent


def test_recovery_for_one_arm_adds_only_that_arms_missing_messages(tmp_path):
    sent = _journal_both_arms(tmp_path, 10)
    left = estimate_key("notes_left")
    rec = JournalRecovery(tmp_path, 0.0, instrument_keys("notes_left"))
    for seq in range(7):                                  # the recorder received the left arm's first seven
        assert rec.note(left, sent["notes_left"][seq], False, seq)
    found = list(rec.records("slave"))
    assert [(k, p) for _, k, p in found] == [(left, sent["notes_left"][s]) for s in (7, 8, 9)]
    assert rec.other_keys == 10                           # the right arm's records: left out, counted
    for seq, (_, key, payload) in zip((7, 8, 9), found, strict=False):
        assert rec.note(key, payload, True, seq)
    assert rec.counts == {"slave": 3}
    assert rec.summary()["other_keys"] == 10
    everything = JournalRecovery(tmp_path, 0.0)           # no key expression: every record is the recorder's
    assert sum(1 for _ in everything.records(None)) == 20 and everything.other_keys == 0


def test_an_arms_recorder_completes_its_recording_from_the_session_journal_only_with_its_arm(tmp_path):
    c = Config()
    cfg = dataclasses.replace(c, instrument=dataclasses.replace(c.instrument, id="notes_left"),
                              recording=dataclasses.replace(c.recording, rerun="off", flush_interval=0.01))
    with Session(TransportConfig(listen=(loopback_endpoint(free_tcp_port()),), connect=())) as rs:
        rec = Recorder(rs, cfg, tmp_path / "notes_left" / "recorder", journal_dir=tmp_path)
        _journal_both_arms(tmp_path, 5)                   # published after the recorder started, never received
        s = rec.close()
    assert list(s["streams"]) == [estimate_key("notes_left")]
    st = s["streams"][estimate_key("notes_left")]
    assert (st["count"], st["recovered"], st["missing"]) == (5, 5, 0)
    j = s["recovered_from_journals"]
    assert j["journals"] == {"slave": 1} and j["recovered"] == {"slave": 5} and j["other_keys"] == 5
    rows = (tmp_path / "notes_left" / "recorder" / "recovered.csv").read_text().splitlines()[4:]
    assert len(rows) == 5 and all(f",{estimate_key('notes_left')}," in r for r in rows)
