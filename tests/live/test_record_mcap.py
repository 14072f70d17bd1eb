"""The recorder's MCAP file (live/record/mcap_file.py, live/record/mcap_read.py): channels, ROS 2 CDR decoded by
mcap-ros2-support's own decoder, JSON equal to the messages, log-time order after a gap is filled, a torn file read
up to its last chunk and rebuilt from messages.bin and a journal, `rerun mcap check` and `convert` on it, and
`teleop replay` of it."""
from __future__ import annotations

import dataclasses
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from estimator.phase import Phase
from live.record.mcap_file import MCAP_NAME, McapRecording, to_json
from live.record.mcap_read import estimate_data, read_session, repair
from teleop.recording.journal import pack_record
from teleop.wire.codec import encode
from teleop.wire.messages import AxisState, Command, Estimate, Heartbeat, Side, SideState, TendonState, tendon_estimate

OFFSET = 1.7e9                      # [s] Unix minus monotonic
RERUN = Path(sys.executable).parent / "rerun"


def _est(k: int) -> Estimate:
    T_in = 5.0 + np.sin(0.01 * k)
    return tendon_estimate(k, k, 10.0 + 1e-3 * k, T_in, 1e-4 * T_in, 0.8 * T_in, 1e-5 * T_in, 9e-5 * T_in,
                           Phase.PULL, (T_in, 0.9 * T_in))


def _session(n: int = 300) -> list[tuple[float, str, object]]:
    """(receive time [s], key, message): commands and estimates at 1 kHz, a heartbeat every 100 ms."""
    out: list[tuple[float, str, object]] = []
    for k in range(n):
        t = 10.0 + 1e-3 * k
        if k % 100 == 0:
            out.append((t + 1e-4, "teleop/m1/slave/heartbeat", Heartbeat(Side.SLAVE, k // 100, t, SideState.ENGAGED)))
        out.append((t + 2e-4, "teleop/m1/master/command", Command(k, t, (1e-4 * k,), True, 1)))
        out.append((t + 3e-4, "teleop/m1/slave/estimate", _est(k)))
    return out


def _cfg(joints=(), mcap_every=1):
    """Every message in the file (``recording.mcap_every: 1``) unless ``mcap_every`` says otherwise."""
    from teleop.config.schema import Config
    c = Config()
    return dataclasses.replace(c, instrument=dataclasses.replace(c.instrument, id="m1", joints=joints),
                               recording=dataclasses.replace(c.recording, mcap_every=mcap_every))


def _write(path: Path, msgs, cfg=None) -> dict:
    mc = McapRecording(path, cfg or _cfg(), OFFSET)
    for t, key, m in msgs:
        mc.write(t, key, m)
    return mc.close()


def test_channels_ros2_cdr_and_json_hold_every_message(tmp_path):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    path = tmp_path / MCAP_NAME
    res = _write(path, _session())
    assert res["channels"] == 8 and not res["sorted_at_end"]
    with open(path, "rb") as fh:
        reader = make_reader(fh, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        topics = {c.topic: (summary.schemas[c.schema_id].name, c.message_encoding) for c in summary.channels.values()}
        assert topics["/m1/actuators/measured_js"] == ("sensor_msgs/msg/JointState", "cdr")
        assert topics["/m1/measured_cf"] == ("geometry_msgs/msg/WrenchStamped", "cdr")
        assert topics["/teleop/m1/slave/estimate"] == ("teleop.Estimate", "json")
        est_schema = json.loads(next(x.data for x in summary.schemas.values() if x.name == "teleop.Estimate"))
        assert est_schema["properties"]["profiles"]["items"] == {"type": "array", "items": {"type": "number"}}
        phase = est_schema["properties"]["axes"]["items"]["properties"]["tendons"]["items"]["properties"]["phase"]
        assert phase["type"] == "integer" and set(phase["enum"]) == {int(p) for p in Phase}
        assert summary.chunk_indexes and all(c.compression == "zstd" for c in summary.chunk_indexes)
        js = list(reader.iter_decoded_messages(topics=["/m1/measured_js"]))
        cf = list(reader.iter_decoded_messages(topics=["/m1/measured_cf"]))
    assert len(js) == len(cf) == 300
    e = _est(123)
    _, _, m, ros = js[123]
    assert list(ros.position) == [e.axes[0].tendons[0].x_in] and list(ros.effort) == [e.axes[0].tendons[0].T_in]
    assert list(ros.name) == ["tendon"]
    assert ros.header.stamp.sec + ros.header.stamp.nanosec * 1e-9 == pytest.approx(OFFSET + e.t_slave, abs=1e-6)
    assert m.log_time == round((10.123 + 3e-4) * 1e9) + round(OFFSET * 1e9) and m.publish_time < m.log_time
    assert cf[123].decoded_message.wrench.force.z == pytest.approx(e.axes[0].effort_hat)
    assert cf[123].decoded_message.header.frame_id == "m1_distal"
    s = read_session(path)
    assert not s.torn and s.metadata["instrument"] == "m1"
    assert [d for _, _, d in s.messages["teleop/m1/slave/estimate"]] == [to_json(_est(k)) for k in range(300)]
    assert len(s.messages["teleop/m1/master/command"]) == 300 and len(s.messages["teleop/m1/slave/heartbeat"]) == 3
    assert s.messages["teleop/m1/slave/estimate"][7][0] == pytest.approx(10.007 + 3e-4, abs=1e-6)   # back to monotonic


def test_a_joint_instrument_gets_one_tendon_per_side_of_each_pair(tmp_path):
    from teleop.config.schema import JointConfig
    ta, tb = TendonState(3.0, 1e-3, 2.5, 1e-5, Phase.HOLD), TendonState(1.0, 2e-3, 0.5, 1e-5, Phase.HOLD)
    m = Estimate(1, 1, 5.0, (AxisState(0.01, 0.2, (ta, tb)), AxisState(-0.02, 0.1, (ta, tb))))
    cfg = _cfg((JointConfig("wrist", pulley_radius=0.004), JointConfig("grip", pulley_radius=0.003)))
    _write(tmp_path / "j.mcap", [(5.001, "teleop/m1/slave/estimate", m)], cfg)
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    with open(tmp_path / "j.mcap", "rb") as fh:
        reader = make_reader(fh, decoder_factories=[DecoderFactory()])
        cdr = [c.topic for c in reader.get_summary().channels.values() if c.message_encoding == "cdr"]
        got = {x.channel.topic: x.decoded_message for x in reader.iter_decoded_messages(topics=cdr)}
    assert list(got["/m1/actuators/measured_js"].name) == ["wrist_a", "wrist_b", "grip_a", "grip_b"]
    assert list(got["/m1/distal/measured_js"].effort) == [0.01, -0.02]
    assert list(got["/m1/measured_js"].position) == [0.2, 0.1]
    assert list(got["/m1/measured_js"].effort) == pytest.approx([0.004 * 2.0, 0.003 * 2.0])
    assert got["/m1/grip/measured_cf"].wrench.torque.z == -0.02


def test_a_message_recovered_into_a_gap_is_sorted_at_the_end(tmp_path):
    msgs = _session(200)
    late = msgs.pop(203)                       # the estimate of cycle 100 arrives from a journal, last
    assert late[1].endswith("estimate") and late[2].seq == 100
    res = _write(tmp_path / "s.mcap", msgs + [late])
    assert res["sorted_at_end"] and res["messages"] == sum(5 if "estimate" in k else 2 if "command" in k else 1
                                                           for _, k, _ in msgs + [late])
    s = read_session(tmp_path / "s.mcap")
    seqs = [d["seq"] for _, _, d in s.messages["teleop/m1/slave/estimate"]]
    assert seqs == list(range(200))


def _raw_and_torn(tmp_path: Path, msgs) -> Path:
    """recorder/ with messages.bin holding ``msgs`` and a session.mcap torn in its middle."""
    rec = tmp_path / "run" / "recorder"
    rec.mkdir(parents=True)
    (rec / "messages.bin").write_bytes(b"".join(pack_record(t, k.encode(), encode(m)) for t, k, m in msgs))
    mc = McapRecording(rec / MCAP_NAME, _cfg(), OFFSET)
    for i, (t, key, m) in enumerate(msgs):
        mc.write(t, key, m)
        if i % 200 == 199:
            mc.flush()                        # a chunk closed, as the recorder does every CHUNK_INTERVAL
    mc._fh.flush()
    data = (rec / MCAP_NAME).read_bytes()     # no footer: the writer was killed; cut inside the last chunk too
    (rec / MCAP_NAME).write_bytes(data[: len(data) - 100])
    return rec


def test_a_torn_file_reads_up_to_its_last_chunk_and_repair_completes_it(tmp_path):
    msgs = _session(300)
    rec = _raw_and_torn(tmp_path, msgs)
    s = read_session(rec / MCAP_NAME)
    n_torn = len(s.messages["teleop/m1/slave/estimate"])
    assert s.torn and 0 < n_torn < 300
    # the slave journaled 20 more estimates the recorder never received (it was killed)
    from teleop.recording.journal import Journal
    tail = [_est(k) for k in range(300, 320)]
    j = Journal(rec.parent, "slave")
    for m in tail:
        j.append("teleop/m1/slave/estimate", encode(m))
    j.close()
    res = repair(rec)
    assert (res["from_messages_bin"], res["from_journals"], res["before"]) == (len(msgs), 20, sum(
        len(v) for v in s.messages.values()))
    s = read_session(rec / MCAP_NAME)
    assert not s.torn
    assert [d["seq"] for _, _, d in s.messages["teleop/m1/slave/estimate"]] == list(range(320))
    assert s.metadata["clock_offset_s"] == repr(OFFSET)


def _rerun(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([str(RERUN), *args], capture_output=True, text=True, timeout=120,
                          env={"RERUN_ANALYTICS": "off", "HOME": "/tmp", "PATH": "/usr/bin:/bin"})


@pytest.mark.skipif(not RERUN.is_file(), reason="the rerun CLI comes with rerun-sdk")
def test_rerun_checks_and_converts_it_with_joint_state_plots(tmp_path):
    path = tmp_path / MCAP_NAME
    _write(path, _session(300))
    chk = _rerun("mcap", "check", str(path))
    assert chk.returncode == 0, chk.stderr
    rows = [r for r in (ln.split() for ln in chk.stdout.splitlines()) if len(r) >= 4 and r[3].startswith("/")]
    assert len(rows) == 8 and all(r[0] == "ok" for r in rows), chk.stdout
    conv = _rerun("mcap", "convert", str(path), "-o", str(tmp_path / "s.rrd"))
    assert conv.returncode == 0, conv.stderr
    out = _rerun("rrd", "print", str(tmp_path / "s.rrd")).stdout
    scalars = {}
    for line in out.splitlines():
        if "Scalars:scalars" in line:
            entity = line.split(" - ")[1].strip()
            scalars[entity] = scalars.get(entity, 0) + int(line.split(" with ")[1].split(" rows")[0])
    assert scalars["/m1/measured_js/effort"] == 300 and scalars["/m1/actuators/measured_js/position"] == 300
    assert scalars["/m1/distal/measured_js/position"] == 300
    assert scalars["/m1/servo_jp/position"] == 300


def test_replay_reads_the_mcap_file_of_a_run(tmp_path):
    from live.cli import main
    from teleop.config.load import load_config, write_config
    run = tmp_path / "runs" / "r1"
    (run / "recorder").mkdir(parents=True)
    write_config(load_config(None), run / "config.yaml")
    (run / "calibration.json").write_text(json.dumps({"K": 0.5, "compliance_m_per_N": 1e-4, "use_route": False}))
    _write(run / "recorder" / MCAP_NAME, _session(400))
    data = estimate_data(read_session(run / "recorder" / MCAP_NAME))
    assert data.time.size == 400 and data.T_in[5] == _est(5).axes[0].tendons[0].T_in
    for k, target in enumerate((run, run / "recorder" / MCAP_NAME)):
        out = tmp_path / f"r{k}.json"
        assert main(["replay", str(target), "--json", str(out), "--rrd", str(tmp_path / f"r{k}.rrd")]) == 0
        res = json.loads(out.read_text())
        assert res["samples"] == 400 and res["csv"].endswith(MCAP_NAME) and res["calibration"].endswith(".json")
        assert "vs_recorded" in res["comparison"]["all"]
    shutil.rmtree(run / "recorder")
    assert main(["replay", str(run)]) != 0          # neither slave.csv nor an MCAP file: one line, exit 2


def test_a_1khz_stream_keeps_the_messages_whose_seq_is_a_multiple_of_mcap_every_and_heartbeats_all(tmp_path):
    path = tmp_path / MCAP_NAME
    msgs = _session(300)
    _write(path, msgs, _cfg(mcap_every=10))
    s = read_session(path)
    assert [d["seq"] for _, _, d in s.messages["teleop/m1/slave/estimate"]] == list(range(0, 300, 10))
    assert [d["seq"] for _, _, d in s.messages["teleop/m1/master/command"]] == list(range(0, 300, 10))
    beats = [m.seq for _, k, m in msgs if k.endswith("/heartbeat")]
    assert [d["seq"] for _, _, d in s.messages["teleop/m1/slave/heartbeat"]] == beats and beats
    assert s.metadata["mcap_every"] == "10"
    from mcap.reader import make_reader
    with open(path, "rb") as fh:
        n_cf = sum(1 for _ in make_reader(fh).iter_messages(topics=["/m1/measured_cf"]))
    assert n_cf == 30                        # the CRTK channels of a kept estimate only
