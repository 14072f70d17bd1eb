"""The recorder's disk use (live/record/budget.py): the high-rate CSVs left out by default, the byte
budget and the free-space floor, and writes the OS refuses (disk full) counted per file."""
from __future__ import annotations

import dataclasses
import errno
import json
import time

import numpy as np
import pytest
from mcap.reader import make_reader

from estimator.phase import Phase
from live.record.budget import DiskBudget, Writes, dir_bytes, is_low_rate
from live.record.recorder import Recorder, read_messages
from teleop.config.schema import Config, TransportConfig
from teleop.session.transport import Session, free_tcp_port, loopback_endpoint
from teleop.wire.codec import encode
from teleop.wire.keys import command_key, estimate_key, heartbeat_key
from teleop.wire.messages import Command, Heartbeat, Side, SideState, tendon_estimate

DEADLINE = 20.0     # [s] a condition not met by then fails the test


def _mcap_teleop_messages(path) -> int:
    with open(path, "rb") as fh:
        return sum(1 for _, ch, _ in make_reader(fh).iter_messages() if ch.topic.startswith("/teleop/"))


def _cfg(**recording) -> Config:
    c = Config()
    return dataclasses.replace(c, instrument=dataclasses.replace(c.instrument, id="bud1"),
                               recording=dataclasses.replace(c.recording, **{"rerun": "off", "flush_interval": 0.01,
                                                                             "mcap_every": 1, **recording}))


def _session():
    return Session(TransportConfig(listen=(loopback_endpoint(free_tcp_port()),), connect=()))


def _estimate(k: int) -> bytes:
    return encode(tendon_estimate(k, k, 1e-3 * k, 2.0 + k, 1e-4, 1.5, 1e-5, 1e-4, Phase.HOLD, (2.0, 1.0)))


def _feed(rec: Recorder, n: int, states=()) -> None:
    """``n`` estimates and commands at 1 kHz of recorder time, then one slave heartbeat per state at 50 Hz."""
    for k in range(n):
        rec._q.put((1.0 + 1e-3 * k, estimate_key("bud1"), _estimate(k)))
        rec._q.put((1.0 + 1e-3 * k, command_key("bud1"), encode(Command(k, 1e-3 * k, (1e-5 * k,)))))
    for k, state in enumerate(states):
        rec._q.put((2.0 + 0.02 * k, heartbeat_key("bud1", "slave"), encode(Heartbeat(Side.SLAVE, k, 0.02 * k, state))))


def test_low_rate_streams_are_the_heartbeats():
    assert is_low_rate(heartbeat_key("x", "slave")) and is_low_rate(heartbeat_key("x", "master"))
    assert not is_low_rate(estimate_key("x")) and not is_low_rate(command_key("x"))


def test_default_recording_writes_no_csv_of_a_high_rate_stream_and_every_message_elsewhere(tmp_path):
    with _session() as s:
        rec = Recorder(s, _cfg(), tmp_path / "recorder")
        _feed(rec, 100, (SideState.SAFE, SideState.ENGAGED))
        out = rec.close()
    names = {p.name for p in (tmp_path / "recorder").iterdir()}
    assert "slave_heartbeat.csv" in names
    assert "slave_estimate.csv" not in names and "master_command.csv" not in names
    assert len(list(read_messages(tmp_path / "recorder" / "messages.bin"))) == 202
    assert _mcap_teleop_messages(tmp_path / "recorder" / "session.mcap") == 202
    assert out["disk"]["reached"] is None and out["disk"]["not_written"] == {}
    assert "figure_error" not in out and (tmp_path / "recorder" / "streams.png").is_file()


def test_past_max_bytes_the_high_rate_streams_are_counted_and_not_written(tmp_path):
    states = [SideState.SAFE] * 60 + [SideState.ENGAGED] + [SideState.SAFE] * 9   # 1.4 s of heartbeats at 50 Hz
    with _session() as s:
        rec = Recorder(s, _cfg(max_bytes=1.0), tmp_path / "recorder")    # the file headers alone pass 1 byte
        deadline = time.monotonic() + DEADLINE
        while rec.budget.reached is None:
            assert time.monotonic() < deadline, "the budget was not checked"
            time.sleep(0.01)
        _feed(rec, 100, states)
        out = rec.close()
    summary = json.loads((tmp_path / "recorder" / "summary.json").read_text())
    assert "recording.max_bytes" in summary["disk"]["reached"]["reason"]
    skipped = summary["disk"]["over_budget_not_written"]
    assert skipped[estimate_key("bud1")] == 100 and skipped[command_key("bud1")] == 100
    assert out["streams"][estimate_key("bud1")]["count"] == 100          # still counted
    written = [k for _, k, _ in read_messages(tmp_path / "recorder" / "messages.bin")]
    hb = heartbeat_key("bud1", "slave")
    assert set(written) == {hb}
    # heartbeats at 1 Hz over 1.38 s (t = 2.0, 3.0) and at each of the two state changes (t = 2.0, 3.2, 3.22)
    assert len(written) == 4 and skipped[hb] == len(states) - 4
    assert [c["state"] for c in out["state_changes"]] == ["SAFE", "ENGAGED", "SAFE"]


class _FullFile:
    """A file that takes ``room`` bytes and then refuses every write as a full disk does (ENOSPC)."""

    def __init__(self, fh, room: int):
        self.fh, self.room, self.name = fh, room, fh.name

    def write(self, b: bytes) -> int:
        if len(b) > self.room:
            raise OSError(errno.ENOSPC, "No space left on device")
        self.room -= len(b)
        return self.fh.write(b)

    def flush(self) -> None:
        self.fh.flush()

    def close(self) -> None:
        self.fh.close()

    @property
    def closed(self) -> bool:
        return self.fh.closed


def test_a_full_disk_keeps_what_was_written_and_the_summary_counts_what_was_not(tmp_path):
    with _session() as s:
        rec = Recorder(s, _cfg(), tmp_path / "recorder")
        size = len(_estimate(0)) + 14 + len(estimate_key("bud1"))          # one record of messages.bin [B]
        rec._raw = _FullFile(rec._raw, 30 * size + size // 2)                # room for 30 estimates and a half
        for k in range(100):
            rec._q.put((1.0 + 1e-3 * k, estimate_key("bud1"), _estimate(k)))
        out = rec.close()
    kept = [k for _, k, _ in read_messages(tmp_path / "recorder" / "messages.bin")]
    assert len(kept) == 30                                                  # every one written before stays
    assert out["disk"]["not_written"]["messages.bin"] >= 70                 # the 70 later ones (and the flushes)
    error = out["disk"]["write_errors"]["messages.bin"]
    assert "ENOSPC" in error or "No space" in error
    assert out["streams"][estimate_key("bud1")]["count"] == 100
    assert _mcap_teleop_messages(tmp_path / "recorder" / "session.mcap") == 100
    assert json.loads((tmp_path / "recorder" / "summary.json").read_text())["disk"]["not_written"]["messages.bin"] >= 70


def test_writes_stop_at_the_first_error_of_a_file_and_count_the_rest():
    w, calls = Writes(), []

    def full(x):
        calls.append(x)
        raise OSError(errno.EFBIG, "File too large")

    assert w("a.csv", calls.append, 1) and not w("a.csv" + "x", full, 2)
    assert not w("a.csvx", full, 3)                                          # not tried again
    assert calls == [1, 2] and w.summary()["not_written"] == {"a.csvx": 2}
    assert "File too large" in w.summary()["write_errors"]["a.csvx"]


@pytest.mark.parametrize(("max_bytes", "min_free", "reason"), [
    (10.0, None, "recording.max_bytes"), (None, 1e18, "recording.min_free_bytes"), (1e15, 0.0, None)])
def test_the_budget_is_reached_past_either_limit(tmp_path, max_bytes, min_free, reason):
    (tmp_path / "slave.csv").write_bytes(b"x" * 100)
    (tmp_path / "slave.journal-000").write_bytes(b"j" * 7)
    (tmp_path / "recorder").mkdir()
    (tmp_path / "recorder" / "messages.bin").write_bytes(b"y" * 50)
    assert dir_bytes(tmp_path) == {"slave": 100, "slave.journal": 7, "recorder": 50}
    b = DiskBudget(tmp_path, max_bytes, min_free)
    assert b.check(0.0, 0.0) is (reason is not None)
    assert (b.reached is None) if reason is None else reason in b.reached["reason"]
    assert b.summary()["run_bytes"] == 157


def test_messages_bin_is_compressed_and_reads_back_up_to_its_last_flush_when_cut(tmp_path):
    from live.record.files import ZSTD_MAGIC, ZstdStream, stream_bytes
    from teleop.recording.journal import pack_record

    z = ZstdStream(tmp_path / "messages.bin")
    recs = [pack_record(1e-3 * k, estimate_key("bud1").encode(), _estimate(k)) for k in range(200)]
    for r in recs[:150]:
        z.write(r)
    z.flush()
    flushed = (tmp_path / "messages.bin").read_bytes()
    for r in recs[150:]:
        z.write(r)
    z.close()
    whole = (tmp_path / "messages.bin").read_bytes()
    assert whole.startswith(ZSTD_MAGIC) and len(whole) < len(b"".join(recs)) / 3
    assert stream_bytes(tmp_path / "messages.bin") == b"".join(recs)
    (tmp_path / "cut.bin").write_bytes(flushed)                  # a kill or a full disk after the flush
    assert stream_bytes(tmp_path / "cut.bin") == b"".join(recs[:150])
    assert [k for _, k, _ in read_messages(tmp_path / "cut.bin")] == [estimate_key("bud1")] * 150


def test_the_demo_line_says_the_rate_and_what_the_disk_kept_out(tmp_path):
    from live.record.beside_demo import summary_line

    disk = {"bytes_per_second": {"slave": 4e5, "master": 1e5}, "not_written": {"messages.bin": 3},
            "reached": {"reason": "free space 1.0 MB < recording.min_free_bytes 500.0 MB", "time": 12.5}}
    streams = {"teleop/a/slave/estimate": {"count": 10, "missing": 0}}
    (tmp_path / "summary.json").write_text(json.dumps({"streams": streams, "disk": disk}))
    line = summary_line(tmp_path)
    assert "500 kB/s (1.80 GB per hour)" in line and "not written (disk): messages.bin 3" in line
    assert "recording.min_free_bytes" in line and "t=12.5 s" in line


def test_a_stream_without_csv_is_thinned_in_memory_and_plotted(tmp_path, monkeypatch):
    import live.record.files as rf
    from live.record.figures import streams_plot

    monkeypatch.setattr(rf, "SAMPLE_ROWS", 8)
    s = rf.StreamSample("slave_estimate", ("T_in", "x_in"))
    for k in range(200):
        s.write(1e-3 * k, [2.0 + k, 1e-5 * k])
    st = s.stream()
    assert st.data.shape[1] == 3 and len(st.data) < 8 and s.every > rf.SAMPLE_EVERY
    assert list(np.diff(st.data[:, 0])) == pytest.approx([1e-3 * s.every] * (len(st.data) - 1))
    assert st.units == {"time": "s", "T_in": "N", "x_in": "m"}
    fig = streams_plot([st])
    assert [ax.get_title() for ax in fig.axes if ax.get_title()] == ["slave_estimate"]


def test_the_session_rate_leaves_the_journals_out_and_takes_the_recorder_over_its_messages_time(tmp_path, capsys):
    from live.record.budget import RATE_AFTER
    (tmp_path / "recorder").mkdir()
    b = DiskBudget(tmp_path, None, None, own="recorder")
    b.check(0.0, 0.0, t_data=100.0)
    (tmp_path / "slave.csv").write_bytes(b"x" * 2000)                     # 2000 B in 20 s of wall time
    (tmp_path / "slave.journal-000").write_bytes(b"j" * 10**6)            # a bounded ring: not the rate
    (tmp_path / "recorder" / "messages.bin").write_bytes(b"y" * 4000)     # 4000 B for 40 s of messages
    b.check(2 * RATE_AFTER, 2 * RATE_AFTER, t_data=100.0 + 4 * RATE_AFTER)
    assert b.rates == {"recorder": 4000 / (4 * RATE_AFTER), "slave": 2000 / (2 * RATE_AFTER)}
    assert "journals: a ring" in capsys.readouterr().out


class _DiskGone(_FullFile):
    """A full disk as the OS gives it: after the first refused write, every flush and the close are refused too,
    so what the stream held unflushed never reaches the file."""

    def write(self, b: bytes) -> int:
        if self.room < 0:
            raise OSError(errno.ENOSPC, "No space left on device")
        try:
            return super().write(b)
        except OSError:
            self.room = -1
            raise

    def flush(self) -> None:
        if self.room < 0:
            raise OSError(errno.ENOSPC, "No space left on device")
        super().flush()

    def close(self) -> None:
        if self.room < 0:
            self.fh.fh.close()                     # the zstd stream's file, its last block never handed out
            raise OSError(errno.ENOSPC, "No space left on device")
        super().close()


def test_the_last_line_and_the_summary_count_what_a_write_error_kept_out_alike(tmp_path):
    """Every stream's messages not written (refused after the error, and those the error cut since the last flush)
    are counted once: summary.json's streams and the recorder's last line say the same, and what is counted as
    written reads back from messages.bin."""
    from live.record.beside_demo import final_line
    est, cmd = estimate_key("bud1"), command_key("bud1")
    with _session() as s:
        rec = Recorder(s, _cfg(), tmp_path / "recorder")
        size = len(_estimate(0)) + 14 + len(est)
        rec._raw = _DiskGone(rec._raw, 40 * size)
        _feed(rec, 100, (SideState.SAFE, SideState.ENGAGED))
        out = rec.close()
    on_disk = json.loads((tmp_path / "recorder" / "summary.json").read_text())
    kept = [k for _, k, _ in read_messages(tmp_path / "recorder" / "messages.bin")]
    assert 0 < len(kept) < 100                           # the budget holds about 40 estimates
    hb = heartbeat_key("bud1", "slave")
    for key, n in ((est, 100), (cmd, 100), (hb, 2)):
        v = on_disk["streams"][key]
        assert v["count"] == n and v["not_written"] == n - kept.count(key) > 0, key
        assert v == out["streams"][key]
    line = final_line(out, tmp_path / "recorder")
    assert line.startswith("teleop record: ")
    assert f"slave/estimate 100 (missing 0, not written {100 - kept.count(est)})" in line
    assert f"master/command 100 (missing 0, not written {100 - kept.count(cmd)})" in line
    assert "slave/heartbeat 2 (missing 0, not written 2)" in line
    assert "stopped by a write error: messages.bin (OSError: [Errno 28] No space left on device)" in line
    assert line.endswith(f"; {tmp_path / 'recorder' / 'summary.json'}") and "\n" not in line
    from live.record.beside_demo import summary_line
    assert f"{202 - len(kept)} not written" in summary_line(tmp_path / "recorder")


def test_a_recording_without_errors_says_not_written_0(tmp_path):
    from live.record.beside_demo import final_line
    with _session() as s:
        rec = Recorder(s, _cfg(), tmp_path / "recorder")
        _feed(rec, 20)
        out = rec.close()
    assert all(v["not_written"] == 0 for v in out["streams"].values())
    assert final_line(out, tmp_path) == ("teleop record: master/command 20 (missing 0, not written 0), "
                                         f"slave/estimate 20 (missing 0, not written 0); {tmp_path / 'summary.json'}")
