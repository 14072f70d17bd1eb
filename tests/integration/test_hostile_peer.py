"""Hostile peers against a live session (slave and master as two processes on 127.0.0.1).

While the operator's master runs its protocol, two hostile peers try what a tester tried on an open session:

* a peer without the installation's credentials: it dials the slave's port, and would replay the master's
  ``source_info``, declare the master's liveliness token, publish commands far from the instrument, forge
  estimates (a sequence number far ahead, 1e4 N) and flood malformed payloads;
* a peer with the installation's *observer* credentials (what a recorder holds), which links to both sides (the
  master listens too): it copies the master's ``source_info`` off a command it received and replays it on
  commands 28 mm out, declares the master's
  liveliness token, sends ROS 2 ``servo_jp`` and ``state_command``, forges estimates and floods garbage on the
  master's and the slave's keys.

The slave's commanded position stays what the operator commanded, the tension under its limit, the master's
force under its clamp, the real stream runs to its end, and the refusals are counted by reason.
"""
from __future__ import annotations

import json
import threading
from pathlib import Path

import numpy as np
import pytest
import zenoh

from teleop.config.load import load_config
from teleop.recording.measured_csv import read_measured_csv
from teleop.session.transport import free_tcp_ports, loopback_endpoint
from teleop.wire.codec import encode
from teleop.wire.keys import command_key, estimate_key, liveliness_key
from teleop.wire.messages import AxisState, Command, Estimate, TendonState
from tests.integration.processes import start, stop_all, wait_for, write_bare_config
from tests.zenoh_peer import raw_peer

pytestmark = pytest.mark.integration

ATTACK_TARGET = 0.028          # [m] the hostile commands' target: inside slave.x_in_max, far from the operator's


def _forged_estimate(seq: int, T: float) -> bytes:
    tendon = TendonState(T, 0.001, T, 0.0, 0)
    return encode(Estimate(seq, seq, 0.0, (AxisState(T, 0.0, (tendon,)),), ()))


class Attack:
    """One hostile peer's loop until stopped: what it tried, what it saw."""

    def __init__(self, eps: list[str], ident: str, role: str | None):
        self.z, self.ident, self.role = raw_peer(eps, role=role), ident, role
        self.source_info = None
        self.sent = 0
        self.stop = threading.Event()
        self.z.declare_subscriber(command_key(ident), self._on_command)
        self.token = self.z.liveliness().declare_token(liveliness_key(ident, "master"))
        self.thread = threading.Thread(target=self._run, daemon=True)

    def _on_command(self, sample: zenoh.Sample) -> None:
        self.source_info = self.source_info or sample.source_info       # the master's session id, copied

    def _run(self) -> None:
        seq = 4_000_000
        garbage = [b"", b"\x00" * 7, b"\xff" * 300, b"TSM1" + b"\x01" * 60]
        while not self.stop.is_set():
            seq += 1
            cmd = encode(Command(seq, 0.0, (ATTACK_TARGET,), True, 0))
            kw = {} if self.source_info is None else {"source_info": self.source_info}
            self.z.put(command_key(self.ident), cmd, **kw)
            self.z.put(estimate_key(self.ident), _forged_estimate(seq, 1e4))
            self.z.put(estimate_key(self.ident), _forged_estimate(seq + 1, 5.0))
            for g in garbage:
                self.z.put(command_key(self.ident), g)
                self.z.put(estimate_key(self.ident), g)
            self.z.put(f"7/{self.ident}/servo_jp/sensor_msgs::msg::dds_::JointState_/RIHS01_x", b"\x00\x01" * 20)
            self.z.put(f"7/{self.ident}/state_command/crtk_msgs::msg::dds_::StringStamped_/RIHS01_x", b"pause")
            self.sent += 1
            self.stop.wait(0.002)

    def linked(self) -> bool:
        return bool(list(self.z.info.peers_zid()))

    def close(self) -> None:
        self.stop.set()
        if self.thread.is_alive():
            self.thread.join(2)
        self.z.close()


def test_hostile_peers_do_not_move_the_instrument_or_the_hand(tmp_path: Path):
    ident = "ithostile"
    port, port_master = free_tcp_ports(2)
    ep, ep_master = loopback_endpoint(port), loopback_endpoint(port_master)
    cfg_path = write_bare_config(tmp_path / "hostile.yaml", ident, tmp_path / "runs", port)
    cfg = load_config(cfg_path)
    run_dir = tmp_path / "run"
    slave = start(["slave", "--config", str(cfg_path), "--listen", ep, "--run-dir", str(run_dir),
                   "--exit-on-master-stop", "--max-duration", "90"], tmp_path / "slave.log")
    attacks: list[Attack] = []
    master = None
    try:
        wait_for(lambda: (tmp_path / "slave.log").read_text().count("SAFE") > 0, 60, "the calibrated slave")
        master = start(["master", "--config", str(cfg_path), "--connect", ep, "--listen", ep_master, "--run-dir",
                        str(run_dir), "--protocol", "short", "--max-duration", "90"], tmp_path / "master.log")
        attacks = [Attack([ep, ep_master], ident, None), Attack([ep, ep_master], ident, "observer")]
        wait_for(attacks[1].linked, 10, "the observer's link")
        for a in attacks:
            a.thread.start()
        wait_for(lambda: attacks[1].source_info is not None, 40, "a command of the master, its source_info copied")
        linked = [a.linked() for a in attacks]
        assert master.wait(90) == 0 and slave.wait(30) == 0
        sent = [a.sent for a in attacks]
    finally:
        for a in attacks:
            a.close()
        stop_all([p for p in (slave, master) if p is not None])
    assert linked == [False, True] and min(sent) > 100
    s = json.loads((run_dir / "slave_stats.json").read_text())
    m = json.loads((run_dir / "master_stats.json").read_text())
    # the real stream ran to its end, undisturbed
    assert m["finished"] and s["commands_applied"] > 1000 and s["safe_events"] == 0 and m["safe_events"] == 0
    assert m["estimates_rejected_range"] == 0 and m.get("estimates_resync", 0) == 0 and m["tension_latches"] == 0
    # nothing of the hostile peers reached the sides' loops: the access control dropped it inside Zenoh
    r = s["refusals"]
    assert r["foreign_source"] == 0 and r["decode_error"] == 0 and r["out_of_order"] == 0 and r["step"] == 0
    assert s.get("commands_resync", 0) == 0
    # the instrument followed the operator's commands only; tension and force within their limits
    sl = read_measured_csv(run_dir / "slave.csv")
    x_cmd = np.asarray(sl.extra["x_in_cmd"])
    assert x_cmd.max() < ATTACK_TARGET - 0.01 and np.abs(sl.T_in).max() < cfg.slave.max_tension
    assert m["max_abs_force"] <= cfg.master.mapping.force_limit
    log = (tmp_path / "slave.log").read_text() + (tmp_path / "master.log").read_text()
    assert "Traceback" not in log
