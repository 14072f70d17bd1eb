"""Run one fault against the two real processes (`teleop slave` + `teleop master` over Zenoh on 127.0.0.1).

``instrument="tendon"`` runs the single tendon of the default config, ``"3dof"`` the three-joint
instrument of configs/instrument-3dof.yaml and ``"spindle"`` the spindle-driven jaw of
configs/instrument-spindle.yaml (the slave of these two records ``slave_joints.csv``). Each instrument is
calibrated once with ``teleop calibrate`` and the file copied under each scenario's instrument id.

:func:`run_fault` starts both sides on a free port, waits until both are ENGAGED (seen from their
heartbeats by an observer session), lets them run, applies the fault (a signal to one process or
SIGUSR1 to the process whose ``--inject`` spec waits for it), observes, stops both with SIGINT
(recordings flushed) and returns what the recordings say. Times are CLOCK_MONOTONIC, which all
processes on the machine share: the test's own signal times, the injector's fault time and the
rows of ``slave.csv`` (``t_node``, ``t_cmd_recv``) and ``master.csv`` (``time``, ``t_est_recv``) compare
directly.

Time to safe state of a surviving side = first row in SAFE after the fault minus the receive time
of the last valid message from the other side recorded in that row (a command for the slave, an
estimate for the master). Deadlines here only bound waiting; the figures come from the recordings.
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from live.cli import main as teleop_main
from teleop.config.load import load_config
from teleop.config.schema import Config
from teleop.recording.csv_proc import wait_written
from teleop.recording.measured_csv import read_measured_csv
from teleop.session.transport import Session, accepts_connections, free_tcp_ports, loopback_endpoint, zenoh_config
from teleop.wire.keys import heartbeat_key
from teleop.wire.messages import Heartbeat, SideState
from tests.integration.processes import co_located

CONFIG = """\
instrument:
  id: {ident}
calibration:
  speed: 0.04
recording:
  rerun: "off"
  csv_every: 1
"""
SAFE = int(SideState.SAFE)
DEBUG = []
CONFIGS = Path(__file__).resolve().parents[2] / "configs"
#: joint instrument -> (its config, its instrument id there)
JOINT_CONFIGS = {"3dof": (CONFIGS / "instrument-3dof.yaml", "flex3"),
                 "spindle": (CONFIGS / "instrument-spindle.yaml", "forceps1")}
_CALIBRATION: dict[str, str] = {}        # the calibration text of each instrument, made once
_CAL_ID = "fcalibrated"                  # the instrument id it is made under


class Rows:
    """A recording read by column name, any columns: ``time`` and the other columns in ``extra``."""

    def __init__(self, path: Path):
        with open(path, encoding="utf-8") as fh:
            lines = [ln for ln in fh if ln.strip() and not ln.startswith("#")]
        header = lines[0].strip().split(",")
        data = np.loadtxt(lines[1:], delimiter=",", ndmin=2)
        self.extra = {name: data[:, k] for k, name in enumerate(header)}
        self.time = self.extra["time"]
        if np.any(~np.isfinite(data)) or np.any(np.diff(self.time) < 0):
            raise ValueError(f"{path}: non-finite values or time going back")


def _calibration_dir(text: str, cal_dir: Path) -> str:
    """The config ``text`` with its calibration read from and written to ``cal_dir``."""
    return text.replace("\ncalibration:\n", f"\ncalibration:\n  dir: {cal_dir}\n")


def _calibrated(run_dir: Path, ident: str, instrument: str, text: str) -> Path:
    """The calibration folder of the run in ``run_dir``, holding ``instrument``'s calibration under ``ident``: the
    instrument (its config ``text``, its id replaced) is calibrated once with ``teleop calibrate`` and the file copied
    (a slave that finds it starts without the power-up calibration, which the demo tests run)."""
    if instrument not in _CALIBRATION:
        tmp = run_dir.parent / f"_{instrument}_calibration"
        tmp.mkdir(exist_ok=True)
        cfg = tmp / "cfg.yaml"
        cfg.write_text(_calibration_dir(text, tmp), encoding="utf-8")
        assert teleop_main(["calibrate", "--config", str(cfg)]) == 0
        _CALIBRATION[instrument] = (tmp / f"{_CAL_ID}.yaml").read_text()
    cal_dir = run_dir / "calibration"
    cal_dir.mkdir()
    cal = _CALIBRATION[instrument].replace(f"instrument: {_CAL_ID}", f"instrument: {ident}")
    (cal_dir / f"{ident}.yaml").write_text(cal)
    return cal_dir


def _joint_config(run_dir: Path, ident: str, instrument: str) -> Path:
    """The joint instrument ``instrument`` under ``ident``, quiet, with its calibration file in ``run_dir``."""
    config, base_id = JOINT_CONFIGS[instrument]
    text = config.read_text().replace("rerun: save", "rerun: off")
    cal_dir = _calibrated(run_dir, ident, instrument, text.replace(f"id: {base_id}", f"id: {_CAL_ID}"))
    path = run_dir / "cfg.yaml"
    run_text = text.replace(f"id: {base_id}", f"id: {ident}").replace(
        "rerun: off", "rerun: off\n  csv_every: 1")       # every cycle: the fault timing reads rows
    path.write_text(co_located(_calibration_dir(run_text, cal_dir)), encoding="utf-8")
    return path


@dataclass
class FaultRun:
    name: str
    t_fault: float
    run_dir: Path
    logs: dict[str, str]
    rc: dict[str, int | None]
    slave: object = None              # MeasuredData of slave.csv, Rows of slave_joints.csv (None if unreadable)
    master: object = None             # MeasuredData or Rows of master.csv
    stats: dict[str, dict] = field(default_factory=dict)
    faults: dict[str, dict] = field(default_factory=dict)
    errors: dict[str, str] = field(default_factory=dict)
    t_stop: float = float("inf")      # when the harness sent the first SIGINT (the end of the observation)

    # ---- figures ------------------------------------------------------------------------------
    @property
    def force(self) -> np.ndarray:
        """The largest |rendered force| over the device axes at each master row [N]."""
        cols = [v for k, v in self.master.extra.items() if k == "force" or k.endswith(".force")]
        return np.abs(np.array(cols)).max(axis=0)

    def _safe_after(self, side: str, t_col: str, recv_col: str, t0: float):
        d = getattr(self, side)
        t = d.time if t_col == "time" else d.extra[t_col]
        state = d.extra["state"].astype(int)
        idx = np.flatnonzero((t >= t0) & (state == SAFE))
        if idx.size == 0:
            return None
        i = int(idx[0])
        return {"t_safe": float(t[i]), "t_last_msg": float(d.extra[recv_col][i]),
                "from_last_msg_ms": 1e3 * float(t[i] - d.extra[recv_col][i]),
                "from_fault_ms": 1e3 * float(t[i] - self.t_fault)}

    def slave_safe(self):
        """Slave: first SAFE row at/after the fault, from the last accepted command's receive time."""
        return self._safe_after("slave", "t_node", "t_cmd_recv", self.t_fault - 0.2)

    def master_safe(self):
        """Master: first SAFE row at/after the fault, from the last accepted estimate's receive time."""
        return self._safe_after("master", "time", "t_est_recv", self.t_fault - 0.2)

    def engaged_before_fault(self, side: str) -> bool:
        d = getattr(self, side)
        t = d.time if side == "master" else d.extra["t_node"]
        sel = (t > self.t_fault - 0.3) & (t < self.t_fault)
        return bool(np.any(d.extra["state"][sel] == int(SideState.ENGAGED)))

    def states_after(self, side: str, t0: float):
        """The side's recorded states from ``t0`` until the harness stopped it (rows after its SIGINT are the
        shutdown: a side that sees its peer stop first goes SAFE there)."""
        d = getattr(self, side)
        t = d.time if side == "master" else d.extra["t_node"]
        return d.extra["state"][(t >= t0) & (t < self.t_stop)].astype(int)

    def max_gap(self, side: str) -> float:
        d = getattr(self, side)
        t = d.time if side == "master" else d.extra["t_node"]
        return float(np.diff(t).max())


def _observer_state(sub):
    rec = sub.latest()
    return None if rec is None else rec.message.state


def _wait(pred, timeout: float, what: str, procs) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if pred():
            return
        for name, p in procs.items():
            if p.poll() is not None:
                raise AssertionError(f"the {name} exited with {p.returncode} while waiting for {what}"
                                     f"{DEBUG[0]() if DEBUG else ''}")
        time.sleep(0.01)
    raise AssertionError(f"gave up waiting {timeout:g} s for {what}")



def _run_config(run_dir: Path, ident: str, instrument: str) -> Path:
    """The run's config in ``run_dir``: the joint instrument's (:func:`_joint_config`) or the default tendon's."""
    if instrument in JOINT_CONFIGS:
        return _joint_config(run_dir, ident, instrument)
    cal_dir = _calibrated(run_dir, ident, instrument, CONFIG.format(ident=_CAL_ID))
    path = run_dir / "cfg.yaml"
    path.write_text(co_located(_calibration_dir(CONFIG.format(ident=ident), cal_dir)), encoding="utf-8")
    return path


def _start_sides(cfg_path: Path, run_dir: Path, port: int, port_m: int, inject: dict[str, str],
                 logs: dict[str, Path], procs: dict[str, subprocess.Popen]) -> None:
    """Start the slave listening on ``port`` (waited for until it accepts connections), then the master connected to
    it and listening on ``port_m``; each process goes into ``procs`` as it starts, so that the caller can kill what
    runs."""
    ep = loopback_endpoint(port)
    base = [sys.executable, "-m", "live.cli"]
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    for side, extra in (("slave", ["--listen", ep]),
                        ("master", ["--connect", ep, "--listen", loopback_endpoint(port_m),
                                    "--protocol", "paper"])):
        args = base + [side, "--config", str(cfg_path), "--run-dir", str(run_dir), "--max-duration", "60",
                       *extra] + (["--inject", inject[side]] if side in inject else [])
        with open(logs[side], "w") as fh:
            procs[side] = subprocess.Popen(args, stdout=fh, stderr=subprocess.STDOUT, env=env)
        if side == "slave":
            _wait(lambda: accepts_connections(port), 60, f"the slave to listen on {ep}", procs)


def _fault_window(cfg: Config, ident: str, port: int, procs: dict[str, subprocess.Popen], *, signal_to: str | None,
                  sig: int | None, resume_after: float | None, observe: float, engaged_for: float,
                  trigger_side: str | None, settle: float) -> float:
    """Watch both sides' heartbeats until both are ENGAGED, let them run ``engaged_for`` [s], apply the fault,
    observe it (and wait up to ``settle`` for both to be ENGAGED again). Returns the fault time (CLOCK_MONOTONIC)."""
    ep = loopback_endpoint(port)
    with Session(zenoh_config(cfg.transport, listen=(), connect=(ep,), role="observer")) as obs:
        beats = {s: obs.subscriber(heartbeat_key(ident, s), Heartbeat) for s in ("slave", "master")}
        DEBUG[:] = [lambda: str({s: (b.count, b.errors, _observer_state(b)) for s, b in beats.items()})]
        _wait(lambda: all(_observer_state(b) == SideState.ENGAGED for b in beats.values()), 60,
              "both sides ENGAGED", procs)
        time.sleep(engaged_for)
        t_fault = time.monotonic()
        if signal_to is not None:
            procs[signal_to].send_signal(sig)
        if trigger_side is not None:
            procs[trigger_side].send_signal(signal.SIGUSR1)
        if resume_after is not None:
            time.sleep(resume_after)
            procs[signal_to].send_signal(signal.SIGCONT)
        time.sleep(observe)
        if settle > 0.0:
            deadline = time.monotonic() + settle
            while time.monotonic() < deadline and not all(
                    _observer_state(b) == SideState.ENGAGED for b in beats.values()):
                time.sleep(0.01)
            time.sleep(0.05)      # a few rows after the last heartbeat seen
    return t_fault


def _stop_sides(procs: dict[str, subprocess.Popen]) -> dict[str, int | None]:
    """SIGINT to every side still running (its recordings flushed); returns each side's exit code (killed after
    20 s)."""
    for p in procs.values():
        if p.poll() is None:
            p.send_signal(signal.SIGINT)
    rc: dict[str, int | None] = {}
    for s, p in procs.items():
        try:
            rc[s] = p.wait(20)
        except subprocess.TimeoutExpired:
            p.kill()
            rc[s] = p.wait()
    return rc


def _read_run(out: FaultRun, joints: bool) -> None:
    """Fill ``out`` from its run directory: each side's recording (or the error reading it), its stats and faults,
    and the injector's fault time where one reports it."""
    for side in ("slave", "master"):
        try:
            name = ("slave_joints.csv" if side == "slave" else "master.csv") if joints else f"{side}.csv"
            path = out.run_dir / name
            wait_written(path)          # a killed side's CSV process writes the rows it received, then lets go
            setattr(out, side, Rows(path) if joints else read_measured_csv(path))
        except Exception as e:  # noqa: BLE001 - reported by the test
            out.errors[side] = f"{type(e).__name__}: {e}"
        for kind in ("stats", "faults"):
            path = out.run_dir / f"{side}_{kind}.json"
            if path.is_file():
                getattr(out, kind)[side] = json.loads(path.read_text())
    inj = [f.get("t_fault") for f in out.faults.values() if f.get("t_fault") is not None]
    if inj:
        out.t_fault = float(min(inj))


def run_fault(tmp: Path, name: str, *, inject: dict[str, str] | None = None, signal_to: str | None = None,
              sig: int | None = None, resume_after: float | None = None, observe: float = 1.0,
              engaged_for: float = 0.6, trigger_side: str | None = None, instrument: str = "tendon",
              settle: float = 0.0) -> FaultRun:
    """Run one fault scenario; see the module docstring.

    inject : {"master"|"slave": spec} passed as ``--inject`` (use ``on=usr1`` to start at the fault).
    signal_to, sig : send ``sig`` to that side at the fault (SIGKILL, SIGSTOP); ``resume_after`` [s]:
        SIGCONT after this long.
    trigger_side : side whose injector is triggered by SIGUSR1 at the fault.
    settle : after ``observe``, wait up to this long [s] for both sides to be ENGAGED again before stopping
        them (a ride-through fault: a brief SAFE from a process stall at the end of the window is then seen
        to recover, or seen not to; the recordings decide, this only bounds the wait).
    instrument : ``"tendon"``, ``"3dof"`` or ``"spindle"`` (module docstring).
    """
    joints = instrument in JOINT_CONFIGS
    ident = f"f{instrument[0] if joints else ''}{name.replace('_', '')}"[:20]
    run_dir = tmp / name
    run_dir.mkdir(parents=True)
    cfg_path = _run_config(run_dir, ident, instrument)
    cfg = load_config(cfg_path)
    port, port_m = free_tcp_ports(2)
    procs: dict[str, subprocess.Popen] = {}
    logs = {s: run_dir / f"{s}.log" for s in ("slave", "master")}
    try:
        _start_sides(cfg_path, run_dir, port, port_m, inject or {}, logs, procs)
        t_fault = _fault_window(cfg, ident, port, procs, signal_to=signal_to, sig=sig, resume_after=resume_after,
                                observe=observe, engaged_for=engaged_for, trigger_side=trigger_side, settle=settle)
        t_stop = time.monotonic()
        rc = _stop_sides(procs)
    finally:
        for p in procs.values():
            if p.poll() is None:
                p.kill()
                p.wait()
    out = FaultRun(name, t_fault, run_dir, {s: logs[s].read_text() for s in logs}, rc, t_stop=t_stop)
    _read_run(out, joints)
    return out
