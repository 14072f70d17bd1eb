"""The recorder in this process: generic flattening of every codec message, files and summary from a real
zenoh session pair on 127.0.0.1 (waits bounded, ending when the messages are there)."""
from __future__ import annotations

import dataclasses
import json
import time

from estimator.phase import Phase
from live.record.files import flatten
from live.record.recorder import Recorder, read_messages
from teleop.config.schema import Config
from teleop.recording.measured_csv import read_measured_csv
from teleop.session.transport import Session, free_tcp_port, loopback_endpoint
from teleop.wire.codec import decode, encode
from teleop.wire.keys import command_key, estimate_key, heartbeat_key
from teleop.wire.messages import AxisState, Command, Estimate, Heartbeat, Side, SideState, TendonState, tendon_estimate

DEADLINE = 5.0


def test_flatten_names_every_field_of_nested_messages():
    td = TendonState(1.0, 0.002, 0.8, 1e-5, Phase.PULL)
    msg = Estimate(3, 2, 0.5, (AxisState(0.01, 0.2, (td, td)),), ((1.0, 2.0), (3.0, 4.0)))
    flat = dict(flatten(msg))
    assert flat["seq"] == 3 and flat["axes[0].tendons[1].T_in"] == 1.0
    assert flat["axes[0].tendons[0].phase"] == int(Phase.PULL) and flat["profiles[1][0]"] == 3.0
    assert dict(flatten(Command(1, 0.1, (0.002,), True, 7)))["engaged"] == 1


def _cfg(tmp_path) -> Config:
    c = Config()
    return dataclasses.replace(c, instrument=dataclasses.replace(c.instrument, id="rec1"),
                               recording=dataclasses.replace(c.recording, rerun="off", flush_interval=0.01, csv="all"))


def test_recorder_writes_every_message_per_stream_and_a_summary(tmp_path):
    port = free_tcp_port()
    from teleop.config.schema import TransportConfig
    with Session(TransportConfig(listen=(loopback_endpoint(port),), connect=())) as rs, \
            Session(TransportConfig(listen=(), connect=(loopback_endpoint(port),))) as side:
        rec = Recorder(rs, _cfg(tmp_path), tmp_path / "recorder")
        cmd, est, hb = (side.publisher(command_key("rec1")), side.publisher(estimate_key("rec1")),
                        side.publisher(heartbeat_key("rec1", "slave")))
        deadline = time.monotonic() + DEADLINE
        while not cmd._handle.matching_status.matching:
            assert time.monotonic() < deadline
            time.sleep(0.01)
        for k in range(200):
            cmd.put(Command(k, 1e-3 * k, (1e-5 * k,)))
            if k != 50:                                  # one estimate never sent: a gap of one
                est.put(tendon_estimate(k, k, 1e-3 * k, 2.0 + k, 1e-4, 1.5, 1e-5, 1e-4, Phase.HOLD, (2.0, 1.0)))
        for k, state in enumerate((SideState.CALIBRATING, SideState.CALIBRATING, SideState.ENGAGED)):
            hb.put(Heartbeat(Side.SLAVE, k, 0.1 * k, state))
        cmd.put_bytes(b"\x00garbage")
        deadline = time.monotonic() + DEADLINE
        while sum(s.count for s in rec.streams.values()) < 200 + 199 + 3 + 1 and time.monotonic() < deadline:
            time.sleep(0.01)
        s = rec.close()
    streams = s["streams"]
    c, e = streams["teleop/rec1/master/command"], streams["teleop/rec1/slave/estimate"]
    assert (c["count"], c["missing"], c["decode_errors"]) == (201, 0, 1)
    assert (e["count"], e["missing"], e["first_seq"], e["last_seq"]) == (199, 1, 0, 199)
    assert [x["state"] for x in s["state_changes"]] == ["CALIBRATING", "ENGAGED"]
    assert s["command_to_echo_at_recorder"]["n"] == 199
    data = read_measured_csv(tmp_path / "recorder" / "slave_estimate.csv")
    assert list(data.T_in[:3]) == [2.0, 3.0, 4.0] and list(data.extra["profiles[0][1]"][:2]) == [1.0, 1.0]
    assert data.metadata["key"] == "teleop/rec1/slave/estimate"
    raw = list(read_messages(tmp_path / "recorder" / "messages.bin"))
    assert len(raw) == 200 + 199 + 3 + 1 and sum(p == b"\x00garbage" for _, _, p in raw) == 1
    assert decode(raw[0][2]) in (Command(0, 0.0, (0.0,)),
                                 tendon_estimate(0, 0, 0.0, 2.0, 1e-4, 1.5, 1e-5, 1e-4, Phase.HOLD, (2.0, 1.0)))
    assert json.loads((tmp_path / "recorder" / "summary.json").read_text())["streams"] == streams
    assert (tmp_path / "recorder" / "streams.png").is_file()


def test_read_messages_ignores_a_torn_last_record(tmp_path):
    from live.record.recorder import _RAW
    p = tmp_path / "m.bin"
    one = encode(Command(1, 0.0, (0.0,)))
    rec = _RAW.pack(1.5, 3, len(one)) + b"a/b" + one
    p.write_bytes(rec + rec[:-4])
    assert [(t, k) for t, k, _ in read_messages(p)] == [(1.5, "a/b")]


def test_rig_interface_payloads_are_decoded_too():
    from live.record.files import decode_any
    from teleop.wire.rig import RigSample, encode_rig
    m = RigSample(4, 3, 0.5, (0.001,), (2.0,), (0.0011,), ((2.0, 1.5, 0.001, 0.0009, 1e-4),))
    flat = dict(flatten(decode_any(encode_rig(m))))
    assert flat["seq"] == 4 and flat["T_in[0]"] == 2.0 and flat["truth[0][1]"] == 1.5
    assert decode_any(encode(Command(1, 0.0, (0.0,)))) == Command(1, 0.0, (0.0,))


def test_short_names_where_unambiguous():
    from live.record.files import short_names
    one = ["seq", "axes[0].effort_hat", "axes[0].tendons[0].T_in", "axes[0].tendons[0].x_in", "profiles[0][1]"]
    assert short_names(one) == ("seq", "effort_hat", "T_in", "x_in", "profiles[0][1]")
    two = ["seq", "axes[0].tendons[0].T_in", "axes[0].tendons[1].T_in", "axes[1].seq"]
    assert short_names(two) == ("seq", "axes[0].tendons[0].T_in", "axes[0].tendons[1].T_in", "axes[1].seq")
