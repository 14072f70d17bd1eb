"""The joint-axis loop of the 3-joint instrument in one process, for benchmarks/bench_stability.py.

The real nodes of ``teleop demo --config configs/instrument-3dof.yaml`` on one fake clock at 1 kHz:
:class:`slave.node.SlaveNode` (three :class:`slave.pair_axis.PairAxis`, the simulated instrument, the
joint estimators) and :class:`master.node.MasterNode` (per axis the motion map ``motion_scale / r``,
the force map of ``-force_scale torque_hat / r``, the passivity controller) with the scripted
operator (one arm per axis) running the paper protocol on tendon a then b of every joint, all
joints together. The links are in-memory topics that deliver each message ``delay`` seconds after
it was put (each way). The calibration is made once at power-up (:func:`calibration`) and reloaded
for every point, as the demo does.

Per joint and pulled tendon: chatter and transparency from :func:`teleop.timing.loop_metrics.loop_metrics`
on the joint's columns (``x_in`` = r * the commanded angle, ``force`` = the rendered force,
``T_out`` = true torque / r), as the demo computes them.
"""
from __future__ import annotations

import bisect
import dataclasses
import math
import tempfile
from pathlib import Path

import numpy as np

from master.arm import ArmParameters
from master.node import MasterNode
from master.node_base import MasterLinks
from master.protocols import MARKER_PAPER_A, MARKER_PAPER_B, joint_marker, paper_protocol
from master.simulated import ScriptedOperator
from slave.calibration_file import load_calibration
from slave.node import SlaveNode
from slave.node_base import SlaveLinks
from slave.pair_axis import joint_csv_columns
from slave.pair_calibrate import set_tension
from slave.pair_rig import SimulatedInstrument
from teleop.config.load import load_config, with_overrides
from teleop.config.schema import Config
from teleop.session.transport import Received
from teleop.timing.clock import FakeClock

CONFIG = Path(__file__).resolve().parents[1] / "configs" / "instrument-3dof.yaml"
DT = 1e-3


class DelayTopic:
    """Latest-wins in-memory topic that delivers a message ``delay`` [s] after it was put."""

    def __init__(self, clock: FakeClock, delay: float):
        self.clock, self.delay = clock, float(delay)
        self._t: list[float] = []
        self._m: list = []
        self.count, self.errors = 0, 0

    def put(self, msg) -> None:
        self._t.append(self.clock.now() + self.delay)
        self._m.append(msg)
        self.count += 1

    def latest(self):
        k = bisect.bisect_right(self._t, self.clock.now() + 1e-12)
        if k == 0:
            return None
        if k > 1:                     # keep only the newest delivered one
            del self._t[:k - 1], self._m[:k - 1]
        return Received(self._m[0], self._t[0])

    def age(self, now: float) -> float:
        r = self.latest()
        return math.inf if r is None else now - r.t_recv


class _Rows:
    def __init__(self):
        self.rows: list[tuple] = []

    def write(self, row) -> None:
        self.rows.append(tuple(row))


def _config(overrides: dict | None = None, base: Config | None = None):
    """``base`` (a joint instrument's config; None: configs/instrument-3dof.yaml) with ``overrides``."""
    over = {"calibration.speed": 0.01, **(overrides or {})}
    return load_config(CONFIG, over) if base is None else with_overrides(base, over)


def calibration(path: Path | None = None, base: Config | None = None):
    """Calibrate the simulated instrument of ``base`` (None: the 3-joint one) at power-up once (in-process) and
    return the calibration."""
    cfg = _config(base=base)
    d = Path(tempfile.mkdtemp(prefix="bench_joints_")) if path is None else path
    clock = FakeClock(0.0)
    topics = [DelayTopic(clock, 0.0) for _ in range(4)]
    slave = SlaveNode(cfg, SimulatedInstrument.from_config(cfg),
                      SlaveLinks(estimate=topics[0], heartbeat=topics[1], command=topics[2],
                                 master_heartbeat=topics[3]),
                      calibration_file=d / f"{cfg.instrument.id}.yaml", run_dir=d)
    for _ in range(int(120.0 / DT)):
        clock.advance(DT)
        slave.step(clock.now())
        if (d / f"{cfg.instrument.id}.yaml").is_file():
            break
    return load_calibration(d / f"{cfg.instrument.id}.yaml", cfg)


def run_joints(cal, force_scale: float = 0.2, delay: float = 0.001, arm: ArmParameters | None = None,
               passivity: bool = True, reserve: float | None = None, t_max: float = 40.0,
               overrides: dict | None = None, base: Config | None = None) -> dict:
    """One closed-loop run of the 3-joint instrument (or of ``base``'s joint instrument, an arm of a bimanual
    config, say); per joint and pulled tendon the loop metrics. ``overrides``: further config keys (dotted),
    e.g. ``{"pair_control.backlash_compensation": True}``.

    Returns ``{"finished", "safe_events", "duration_s", "<joint> (pull a|b)": loop_metrics row}``.
    """
    from teleop.timing.loop_metrics import loop_metrics
    # the watchdogs allow the injected delay (estimate age d, command echo 2 d + a period)
    wd = 50.0 + 2e3 * delay
    over: dict = {"master.mapping.force_scale": force_scale, "master.mapping.passivity": passivity,
                  "master.watchdog_ms": wd, "slave.watchdog_ms": wd}
    if reserve is not None:
        over["master.mapping.passivity_reserve"] = reserve
    over.update(overrides or {})
    # the study runs the loop past the hard bounds on purpose (long delays, no passivity controller, no reserve)
    over["safety.override"] = ["master.watchdog_ms", "slave.watchdog_ms", "master.mapping.passivity",
                               "master.mapping.passivity_reserve"]
    cfg = _config(over, base)
    clock = FakeClock(0.0)
    cmd, est, shb, mhb = (DelayTopic(clock, delay) for _ in range(4))
    srows, mrows = _Rows(), _Rows()
    slave = SlaveNode(cfg, SimulatedInstrument.from_config(cfg),
                      SlaveLinks(estimate=est, heartbeat=shb, command=cmd, master_heartbeat=mhb), recorder=srows,
                      calibration=cal, stop_on_master_stop=True)
    arm = arm or ArmParameters.from_config(cfg.master.device.arm)
    op = ScriptedOperator([paper_protocol(set_tension(cfg, j)) for j in cfg.instrument.joints], arm=arm,
                          clutch_bit=cfg.master.mapping.clutch_button)
    master = MasterNode(cfg, op, MasterLinks(command=cmd, heartbeat=mhb, estimate=est, slave_heartbeat=shb),
                        recorder=mrows)
    while clock.now() < t_max and not master.done:
        clock.advance(DT)
        now = clock.now()
        slave.step(now)
        master.step(now)
    names = [j.name for j in cfg.instrument.joints]
    sc = dict(zip(joint_csv_columns(names, True), np.array(srows.rows, float).T, strict=False))
    mc = dict(zip(master.axes.csv_columns(), np.array(mrows.rows, float).T, strict=False))
    out: dict = {"finished": bool(op.finished), "safe_events": master.safe_events, "duration_s": clock.now()}
    for j, joint in enumerate(cfg.instrument.joints):
        n, r = joint.name, joint.pulley_radius
        m = {"time": mc["time"], "x_in": r * mc[f"{n}.cmd"], "force": mc[f"{n}.force"], "cmd_seq": mc["cmd_seq"],
             "state": mc["state"], "force_cmd": mc[f"{n}.force_cmd"]}
        s = {"t_node": sc["t_node"], "T_out": sc[f"{n}.torque"] / r, "cmd_seq": sc["cmd_seq"],
             "T_out_hat": sc[f"{n}.torque_hat"] / r,
             "marker": np.array([joint_marker(int(v), j) for v in sc["marker"]])}
        out.update(loop_metrics(m, s, force_scale, {MARKER_PAPER_A: f"{n} (pull a)", MARKER_PAPER_B: f"{n} (pull b)"}))
    return out


def summarize(r: dict) -> dict:
    """One sweep point: stable (finished, no safe event, every joint's worst windows below
    :data:`teleop.timing.loop_metrics.CHATTER_LIMITS`), the worst windows and per joint the worst
    transparency RMS over its two pulls."""
    from teleop.timing.loop_metrics import CHATTER_LIMITS
    rows = {k: v for k, v in r.items() if isinstance(v, dict)}
    xw = max(v["chatter"]["x_in_cmd_worst_m"] for v in rows.values())
    fw = max(v["chatter"]["force_worst_N"] for v in rows.values())
    worst_at = max(rows, key=lambda k: rows[k]["chatter"]["force_worst_N"])
    joints: dict[str, float] = {}
    for k, v in rows.items():
        j = k.split(" ")[0]
        joints[j] = max(joints.get(j, 0.0), v["transparency"]["force_error_rms_fs"])
    stable = bool(r["finished"] and r["safe_events"] == 0 and len(rows) == 6
                  and xw < CHATTER_LIMITS["x_in_cmd_m"] and fw < CHATTER_LIMITS["force_N"])
    return {"stable": stable, "x_worst_um": 1e6 * xw, "force_worst_N": fw, "worst_at": worst_at,
            "transparency_rms_fs": joints,
            "finished": r["finished"], "safe_events": r["safe_events"]}


def arm_with(stiffness: float) -> ArmParameters:
    """The configured arm with another stiffness [N/m]."""
    return dataclasses.replace(ArmParameters.from_config(_config().master.device.arm), stiffness=float(stiffness))
