"""The recorder remembers what it has in constant memory (live/record/journal.py): by seq in a ring, and the
messages without a seq in two bounded generations of hashes; a journal record it has is not recovered again."""
from __future__ import annotations

from live.record.journal import SEEN, JournalRecovery


def test_received_seqs_are_kept_in_a_fixed_ring_and_recovery_skips_them_only(tmp_path):
    j = JournalRecovery(tmp_path, 0.0)
    key = "teleop/x/slave/estimate"
    for seq in range(SEEN + 1000):                     # more than the ring: the oldest slots are reused
        assert j.note(key, seq.to_bytes(8, "little"), False, seq)
    seen = j._seen[key]
    assert seen.seqs.size == SEEN and not seen.new and not seen.old
    assert not j.note(key, (SEEN + 10).to_bytes(8, "little"), True, SEEN + 10)    # received: not recovered again
    assert j.note(key, b"gap", True, SEEN + 5000)                                 # never received: recovered
    assert not j.note(key, b"gap", True, SEEN + 5000)                             # and only once
    assert j.counts == {"slave": 1}


def test_messages_without_a_seq_are_known_by_hash_in_two_bounded_generations(tmp_path):
    j = JournalRecovery(tmp_path, 0.0)
    key = "teleop/x/rig/sample"
    for k in range(SEEN + 10):
        j.note(key, b"m%d" % k, False)
    seen = j._seen[key]
    assert len(seen.new) + len(seen.old) <= SEEN
    assert not j.note(key, b"m%d" % (SEEN + 9), True)                            # the newest are remembered
