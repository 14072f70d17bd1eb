"""The bimanual instrument over real processes (configs/notes-bimanual.yaml, 16 tendons): the slave and the
master each run both arms in one loop; the left arm's estimate stream is dropped on the slave (``--inject
drop=1,stream=estimate,arm=left``, from SIGUSR1) while both arms track. The left arm's master goes SAFE within
100 ms of the fault and never re-engages on the dropped stream; over the two seconds after the fault the right arm
runs on free of it: its estimates arrive fresh by the master's own rule (younger than two watchdog periods), it is
not SAFE on either side but for a stall's moment, its command echoes are fresh while it is ENGAGED, and it engages
again after each such moment. The in-process tests of the other faults (an impossible tension, a lost device):
tests/live/test_bimanual_faults.py.

Both loops run at 500 Hz here. At 1 kHz the two loops of 16 tendons fill both cores of this 2-core machine at
real-time priority (the slave overruns 18 % of its cycles), the transport's threads, at a real-time priority below the
loops' (docs/how-to/real-time.md), wait behind them, and the command echo lags 0.1-0.4 s: both arms drop to SAFE on
"command echo stale", which is the machine, not the fault under test. The bimanual loop at 1 kHz is measured by
``teleop demo --config configs/notes-bimanual.yaml`` and benchmarks/bench_bimanual_arms.py. At 500 Hz too the kernel
stops real-time threads for up to 50 ms a second when they exceed their budget: a stall past the watchdog makes an
arm safe for a moment, on this machine as on any, and the arm then waits READY until the scripted operator's handle,
moved meanwhile, is aligned again (up to 0.8 s seen). The checks allow for that: a share of the window, not every
row, an arm's recovery rather than its ENGAGED share, and the faulty arm's last state before the fault may be such a
moment's SAFE."""
from __future__ import annotations

import json
import signal
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from slave.calibration_file import calibration_path, save_calibration
from slave.pair_rig import SimulatedInstrument
from teleop.arms import load_arms
from teleop.session.transport import free_tcp_port
from teleop.wire.messages import SideState
from tests.integration.processes import start, stop_all, wait_for
from tests.live.test_bimanual_faults import true_calibration

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[2]
LIMIT_S = 0.100          # the acceptance: the faulty arm safe within 100 ms
WINDOW_S = 2.0           # the right arm is watched this long after the fault [s]
RATE_HZ = 500.0          # both loops' rate (module docstring) [Hz]
RIDE = 0.9               # least fraction of the window the right arm is free of faults
REALIGN_S = 1.5          # a stall's SAFE moment to ENGAGED again, through READY while the handle realigns [s]


def _columns(path: Path) -> dict[str, np.ndarray]:
    lines = [ln for ln in path.read_text(encoding="utf-8").splitlines() if ln and not ln.startswith("#")]
    names = lines[0].split(",")
    data = np.array([[float(v) for v in ln.split(",")] for ln in lines[1:] if ln.count(",") == len(names) - 1])
    return {n: data[:, i] for i, n in enumerate(names)}


def _tail(path: Path, n: int) -> list[list[str]]:
    """The last ``n`` whole rows of a CSV recording being written (fewer early on), as fields. Reads only the end
    of the file: the recordings grow by ~270 kB/s per arm, and parsing them whole at every poll would take half a core
    of this 2-core machine from the two 1 kHz loops under test."""
    try:
        with path.open("rb") as f:
            size = f.seek(0, 2)
            chunk = 512 * (n + 2)
            while True:
                start = max(0, size - chunk)
                f.seek(start)
                lines = f.read(size - start).decode("utf-8", errors="replace").splitlines()
                rows = [ln.split(",") for ln in lines[1 if start else 0:-1] if ln and ln[0] in "0123456789"]
                if len(rows) >= n or start == 0:
                    return rows[-n:]
                chunk *= 4
    except OSError:
        return []


def _last_time(path: Path) -> float:
    """The time of the last whole row of a CSV recording being written (-inf before any)."""
    rows = _tail(path, 1)
    return float(rows[-1][0]) if rows else -np.inf


def _tracking(path: Path, n: int = int(RATE_HZ), last: int = int(RATE_HZ / 5)) -> bool:
    """Whether the arm tracks steadily: the master recording holds ``n`` rows past its start, at least ``RIDE`` of
    them ENGAGED, and its last ``last`` rows all ENGAGED. A stall's SAFE moment (up to 50 ms a second on this
    machine) may fall anywhere in the ``n`` rows but not just before the fault."""
    rows = _tail(path, n)
    engaged = [int(float(r[1])) == int(SideState.ENGAGED) for r in rows]
    return len(rows) == n and all(engaged[-last:]) and sum(engaged) >= RIDE * n


def _engages_after_each_safe(t: np.ndarray, state: np.ndarray, t0: float, t1: float) -> None:
    """Every SAFE row of one arm's recording between ``t0`` and ``t1`` [s] is followed by an ENGAGED one within
    ``REALIGN_S``: the arm recovers from each stall."""
    engaged = t[state == int(SideState.ENGAGED)]
    for ts in t[(t >= t0) & (t <= t1) & (state == int(SideState.SAFE))]:
        k = np.searchsorted(engaged, ts)
        assert k < engaged.size and engaged[k] - ts <= REALIGN_S, \
            f"SAFE at {ts - t0:.3f} s and not ENGAGED again within {REALIGN_S} s"


def _config(tmp_path: Path, port: int, side: str, csv_every: int) -> Path:
    """The bimanual config of one side: its calibration folder, runs and port in ``tmp_path``, a CSV row every
    ``csv_every`` cycles."""
    data = yaml.safe_load((ROOT / "configs" / "notes-bimanual.yaml").read_text(encoding="utf-8"))
    data["calibration"]["dir"] = str(tmp_path / "calibration")
    data["recording"] = {"dir": str(tmp_path / "runs"), "rerun": "off", "csv_every": csv_every}
    data["transport"]["listen"] = [f"tcp/127.0.0.1:{port}"]
    data["rig"]["rate_hz"] = RATE_HZ
    data["master"]["rate_hz"] = RATE_HZ
    path = tmp_path / f"bimanual-{side}.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return path


def _calibrate(cfg: Path) -> None:
    """Each arm's calibration file, the simulator's own (the slave then makes no power-up pulls)."""
    for arm in load_arms(cfg).arms:
        save_calibration(true_calibration(arm.cfg, SimulatedInstrument.from_config(arm.cfg)), calibration_path(arm.cfg))


def test_stale_estimate_on_left_arm_makes_it_safe_and_right_arm_keeps_tracking(tmp_path):
    port = free_tcp_port()
    run = tmp_path / "run"
    ep = f"tcp/127.0.0.1:{port}"
    common = ["--run-dir", str(run), "--max-duration", "60"]     # a bound; the test stops both with SIGINT
    # the master's timing reads every row of its CSVs; the slave's are read for their state, at the default rate
    slave_cfg, master_cfg = _config(tmp_path, port, "slave", 10), _config(tmp_path, port, "master", 1)
    _calibrate(slave_cfg)
    slave = start(["slave", "--config", str(slave_cfg), "--listen", ep, "--exit-on-master-stop",
                   "--inject", "drop=1,stream=estimate,arm=left,on=usr1"] + common, tmp_path / "slave.log")
    procs = [slave]
    try:
        # the slave armed its fault injector and is past calibration and its estimators' set-up (their first
        # compilation takes longer than the master's --max-duration on a cold numba cache)
        wait_for(lambda: (tmp_path / "slave.log").is_file() and all(
            line in (tmp_path / "slave.log").read_text() for line in ("fault injection on left", "STARTING -> SAFE")),
            90.0, "the slave's fault injector and start-up")
        master = start(["master", "--config", str(master_cfg), "--connect", ep, "--protocol", "paper"] + common,
                       tmp_path / "master.log")
        procs.append(master)
        # a second of steady tracking: the first moments after engaging can hold a start-up stall (its command echo
        # goes stale and the arm goes SAFE, then engages again), which would leave the left arm SAFE at the fault
        wait_for(lambda: all(_tracking(run / i / "master.csv") for i in ("notes_left", "notes_right")), 45.0,
                 "both arms tracking")
        t_signal = time.monotonic()     # the clock of the recordings' time column (one machine)
        slave.send_signal(signal.SIGUSR1)
        right_csv = run / "notes_right" / "master.csv"
        wait_for(lambda: _last_time(right_csv) >= t_signal + WINDOW_S + REALIGN_S + 0.2, 10.0,
                 "the right arm's rows past the window")
        for p in (master, slave):
            p.send_signal(signal.SIGINT)
        for p in (master, slave):
            p.wait(15.0)
    finally:
        stop_all(procs)
    for name in ("slave", "master"):
        assert "Traceback" not in (tmp_path / f"{name}.log").read_text()
    t_fault = json.loads((run / "slave_faults.json").read_text())["t_fault"]
    assert t_fault is not None
    left, right = (_columns(run / ident / "master.csv") for ident in ("notes_left", "notes_right"))
    after = left["time"] >= t_fault
    # the left arm tracked just before the fault (ENGAGED within the limit before it: a stall's SAFE moment may
    # fall on the fault's instant), is SAFE within the limit after it and never engages again on a dropped stream
    before = ~after & (left["time"] >= t_fault - LIMIT_S)
    assert np.any(left["state"][before] == int(SideState.ENGAGED)), "the left arm was not tracking at the fault"
    safe = left["time"][after & (left["state"] == int(SideState.SAFE))]
    assert safe.size and safe[0] - t_fault <= LIMIT_S, f"left arm safe {safe[:1] - t_fault} s after the fault"
    late = left["time"] > t_fault + LIMIT_S
    assert not np.any(left["state"][late] == int(SideState.ENGAGED)), "the left arm engaged on a dropped stream"
    win = (right["time"] >= t_fault) & (right["time"] <= t_fault + WINDOW_S)
    assert win.sum() > 0.8 * WINDOW_S * RATE_HZ
    # the right arm's fault-free: its estimates keep arriving (younger than the master's bound, two watchdog periods,
    # master/node_base.py), it is never SAFE but for a stall's moment, its command echoes are fresh while ENGAGED, and
    # after every SAFE moment it engages again within REALIGN_S (a stall's SAFE is followed by READY while the
    # scripted operator's handle, moved meanwhile, comes back into alignment)
    fresh = 2.0 * next(a for a in load_arms(master_cfg).arms if a.name == "right").cfg.master.watchdog_ms * 1e-3
    est_age = (right["time"] - right["t_est_recv"])[win]
    assert np.mean((est_age >= 0) & (est_age < fresh)) >= RIDE, \
        f"right arm's estimate age p50 {np.median(est_age):.4f} s, p90 {np.percentile(est_age, 90):.4f} s"
    state = right["state"][win]
    assert np.mean(state != int(SideState.SAFE)) >= RIDE, f"right arm SAFE {np.mean(state == int(SideState.SAFE)):.2f}"
    echo = right["echo_age"][win][state == int(SideState.ENGAGED)]
    assert echo.size and np.mean((echo >= 0) & (echo < fresh)) >= RIDE, \
        f"right arm's echo age p50 {np.median(echo):.4f} s, p90 {np.percentile(echo, 90):.4f} s"
    _engages_after_each_safe(right["time"], right["state"], t_fault, t_fault + WINDOW_S)
    slave_right = _columns(run / "notes_right" / "slave_joints.csv")
    swin = (slave_right["t_node"] >= t_fault) & (slave_right["t_node"] <= t_fault + WINDOW_S)
    assert swin.sum() > 0 and np.mean(slave_right["state"][swin] != int(SideState.SAFE)) >= RIDE
    _engages_after_each_safe(slave_right["t_node"], slave_right["state"], t_fault, t_fault + WINDOW_S)
