"""The master node of a joint instrument: device axes -> JointCommand, JointEstimate -> axis forces.

One :meth:`JointMasterNode.step` per cycle (``master.rate_hz``), given the time by the caller. The
single-tendon :class:`master.node.MasterNode` for several joints at once:

1. safety from the links, as the single-tendon master: slave heartbeat fresh and READY/ENGAGED, its
   liveliness token present, the latest accepted JointEstimate (newer, for this many joints, every
   tension within ``master.max_tension``) younger than ``master.watchdog_ms``, the command echo
   within twice that. All true and the operator present: ENGAGED - on entry each axis's motion map
   is anchored at the slave's estimated angle of its joint (no joint jumps) and the forces ramp in.
   Any false while engaged: SAFE, forces 0 at once, commands with ``engaged=False`` carrying the
   slave's latest estimated angles (a valid hold command whatever the hand did);
2. axis -> joint (``pair_control.axes``: device axis of each joint, default joint i on axis i):

       theta_cmd,j = theta_anchor,j + (motion_scale / r_j) (p_axis - p_anchor)      [rad]

   so a device displacement moves a tendon by ``motion_scale`` times it, as for one tendon;
3. forces: F_axis = -force_scale torque_hat_j / r_j (the net distal tension difference, the
   single-tendon rendering with T_out,a - T_out,b for T_out), through one
   :class:`master.mapping.ForceMap` per axis (ramp, clamp, slew) and one passivity controller
   (:mod:`master.passivity`), clamped again;
4. Heartbeat at ``slave.heartbeat_hz``; the echo of ``cmd_seq`` gives the round-trip latency.

When the device reports ``finished`` the node announces STOPPING for ``stop_linger`` s and is done.
"""
from __future__ import annotations

import json
import logging
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from master.mapping import ForceMap, MotionMap, clamp_force
from master.passivity import PassivityController
from teleop.clock import Clock, Pacer
from teleop.codec import next_seq, seq_newer
from teleop.config import Config
from teleop.messages import Heartbeat, JointCommand, JointEstimate, Side, SideState

__all__ = ["JointMasterLinks", "JointMasterNode"]

log = logging.getLogger("teleop.master")
RING_SIZE = 4096
_SLAVE_OK = (SideState.READY, SideState.ENGAGED)


@dataclass
class JointMasterLinks:
    """command, heartbeat: ``put(msg)``; estimate, slave_heartbeat: latest-wins subscribers
    (``latest()``, ``age(now)``); slave_alive: callable or None."""

    command: Any
    heartbeat: Any
    estimate: Any
    slave_heartbeat: Any
    slave_alive: Callable[[], bool] | None = None


class JointMasterNode:
    """Master side of a joint instrument's loop (module docstring).

    Parameters
    ----------
    cfg : Config
        ``instrument.joints`` (pulley radii), ``pair_control.axes``, ``master`` (rate, mapping,
        watchdog, max_tension), ``slave.heartbeat_hz``.
    device : a multi-axis device: ``read(t) -> MultiAxisState``, ``set_forces(forces, t)``; optionally
        ``watch(T_in per joint, engaged)``, ``finished``, ``marker`` (e.g.
        :class:`master.joint_operator.MultiAxisOperator`).
    links : JointMasterLinks
    stop_linger : float
        How long STOPPING is announced before :attr:`done` [s].
    """

    def __init__(self, cfg: Config, device, links: JointMasterLinks, *, stop_linger: float = 0.2):
        self.cfg, self.device, self.links = cfg, device, links
        joints = cfg.instrument.joints
        self.n = len(joints)
        self.r = [j.pulley_radius for j in joints]
        self.axes = tuple(cfg.pair_control.axes) or tuple(range(self.n))
        m = cfg.master.mapping
        self.motion = [MotionMap(m.motion_scale / r) for r in self.r]
        self.forces = [ForceMap.from_config(m) for _ in joints]
        self.passivity = [PassivityController(m.force_limit, enabled=m.passivity) for _ in joints]
        self.limit = m.force_limit
        self.watchdog = cfg.master.watchdog_ms * 1e-3
        self.hb_period = 1.0 / cfg.slave.heartbeat_hz
        self.hb_timeout = max(self.watchdog, 3.0 * self.hb_period)
        self.max_tension = cfg.master.max_tension
        self.stop_linger = float(stop_linger)
        self.state = SideState.STARTING
        self.done = False
        self.seq = self.hb_seq = 0
        self._next_hb = -math.inf
        self._t_stop: float | None = None
        self._sent_seq = np.full(RING_SIZE, -1, dtype=np.int64)
        self._sent_t = np.zeros(RING_SIZE)
        self._accepted = self._seen = None
        self._last_est_seq: int | None = None
        self._last_echo: int | None = None
        self._t_echo: float | None = None
        self._t_prev: float | None = None
        self._p_prev: list[float] | None = None
        self.rtts: list[float] = []
        self.force = [0.0] * self.n
        self.max_abs_force = 0.0
        self.commands_sent = self.estimates_new = self.safe_events = self.engage_count = 0
        self.counts = dict.fromkeys(("estimates_duplicate", "estimates_out_of_order", "estimates_rejected_range",
                                     "estimates_wrong_joints"), 0)
        self.last_reason = "starting"
        self.pacer_stats: dict[str, float] = {}
        self._t_warn = -math.inf

    # ---- links -------------------------------------------------------------------------------------
    def _receive(self, now: float) -> None:
        rec = self.links.estimate.latest()
        if rec is None or rec is self._seen:
            return
        self._seen = rec
        est = rec.message
        if not isinstance(est, JointEstimate) or len(est.joints) != self.n:
            self.counts["estimates_wrong_joints"] += 1
            return
        if not seq_newer(est.seq, self._last_est_seq):
            self.counts["estimates_duplicate" if est.seq == self._last_est_seq else "estimates_out_of_order"] += 1
            return
        if any(abs(v) > self.max_tension for j in est.joints for t in j.tendons for v in (t.T_in, t.T_out_hat)):
            self.counts["estimates_rejected_range"] += 1
            if now - self._t_warn >= 1.0:
                self._t_warn = now
                log.warning("rejected estimate %d: a tension beyond master.max_tension %g N", est.seq, self.max_tension)
            return
        self._accepted, self._last_est_seq = rec, est.seq
        self.estimates_new += 1
        i = est.cmd_seq % RING_SIZE
        if self._sent_seq[i] != est.cmd_seq:
            return
        self._t_echo = self._sent_t[i]
        if est.cmd_seq != self._last_echo:
            self._last_echo = est.cmd_seq
            self.rtts.append(getattr(rec, "t_recv", now) - self._sent_t[i])

    def _peer_status(self, now: float) -> tuple[JointEstimate | None, bool, str]:
        rec = self._accepted
        est = None if rec is None else rec.message
        hb = self.links.slave_heartbeat.latest()
        if hb is None or self.links.slave_heartbeat.age(now) > self.hb_timeout:
            return est, False, "slave heartbeat missing"
        if self.links.slave_alive is not None and not self.links.slave_alive():
            return est, False, "slave liveliness token gone"
        if hb.message.state not in _SLAVE_OK:
            return est, False, f"slave {hb.message.state.name}"
        if est is None or now - rec.t_recv > self.watchdog:
            return est, False, "estimate stale"
        if self._t_echo is None or now - self._t_echo > 2.0 * self.watchdog:
            return est, False, "command echo stale"
        return est, True, "ok"

    # ---- the cycle ---------------------------------------------------------------------------------
    def step(self, now: float) -> None:
        """One master cycle at time ``now`` [s] (module docstring)."""
        if self.done:
            return
        self._receive(now)
        est, healthy, reason = self._peer_status(now)
        watch = getattr(self.device, "watch", None)
        if watch is not None:
            watch(None if est is None else [(j.tendons[0].T_in, j.tendons[1].T_in) for j in est.joints],
                  self.state == SideState.ENGAGED)
        dev = self.device.read(now)
        pos = [dev.positions[a] if a < len(dev.positions) else math.nan for a in self.axes]
        if bool(getattr(self.device, "finished", False)) or self._t_stop is not None:
            if self._t_stop is None:
                self._t_stop = now
                for f in self.forces:
                    f.disengage()
                self._set_state(SideState.STOPPING, now, "protocol finished")
            if now - self._t_stop >= self.stop_linger:
                self.done = True
        elif healthy and dev.operator_present and all(math.isfinite(p) for p in pos):
            if self.state != SideState.ENGAGED:
                for mm, f, pc, p, j in zip(self.motion, self.forces, self.passivity, pos, est.joints):
                    mm.anchor(p, j.angle_hat)     # engaging never turns a joint
                    f.engage()
                    pc.reset()
                self.engage_count += 1
                self._set_state(SideState.ENGAGED, now, "slave ready, links fresh")
        else:
            self.last_reason = reason if not healthy else "operator not present"
            if self.state == SideState.ENGAGED:
                self.safe_events += 1
                for f, mm in zip(self.forces, self.motion):
                    f.disengage()
                    mm.open_clutch()
                self._set_state(SideState.SAFE, now, self.last_reason)
            elif self.state == SideState.STARTING:
                self._set_state(SideState.READY, now, "device read")
        engaged = self.state == SideState.ENGAGED
        # ---- command ----
        if engaged:
            angles = tuple(mm.command(p) for mm, p in zip(self.motion, pos))
        else:   # not engaged: hold where the slave says the joints are (always a valid command)
            angles = tuple(mm.last for mm in self.motion) if est is None else tuple(j.angle_hat for j in est.joints)
        marker = int(getattr(self.device, "marker", 0)) if engaged else 0
        self.links.command.put(JointCommand(self.seq, now, angles, engaged, marker))
        i = self.seq % RING_SIZE
        self._sent_seq[i], self._sent_t[i] = self.seq, now
        self.seq = next_seq(self.seq)
        self.commands_sent += 1
        # ---- forces: map -> passivity -> clamp, per axis ----
        dt = 1.0 / self.cfg.master.rate_hz if self._t_prev is None else max(now - self._t_prev, 1e-9)
        prev = self._p_prev or pos
        for k, (fm, pc, r) in enumerate(zip(self.forces, self.passivity, self.r)):
            torque = math.nan if est is None else est.joints[k].torque_hat
            cmd = fm.step(torque / r, now, fresh=engaged and healthy)
            v = (pos[k] - prev[k]) / dt if math.isfinite(pos[k]) and math.isfinite(prev[k]) else math.nan
            self.force[k] = clamp_force(pc.step(cmd, v, dt), self.limit)
            self.max_abs_force = max(self.max_abs_force, abs(self.force[k]))
        self._t_prev, self._p_prev = now, pos
        out = [0.0] * max(self.axes, default=-1) + [0.0]
        for a, f in zip(self.axes, self.force):
            out[a] = f
        self.device.set_forces(out, now)
        # ---- heartbeat ----
        if now >= self._next_hb:
            self.links.heartbeat.put(Heartbeat(Side.MASTER, self.hb_seq, now, self.state))
            self.hb_seq = next_seq(self.hb_seq)
            self._next_hb = now + self.hb_period if self._next_hb == -math.inf else max(self._next_hb + self.hb_period,
                                                                                        now)

    def _set_state(self, state: SideState, now: float, why: str) -> None:
        if state != self.state:
            log.info("master %s -> %s at t=%.3f s: %s", self.state.name, state.name, now, why)
            self.state = state

    # ---- running -----------------------------------------------------------------------------------
    def run(self, clock: Clock, *, max_duration: float | None = None) -> None:
        """Pace :meth:`step` at ``master.rate_hz`` until :attr:`done` (or ``max_duration`` [s])."""
        pacer = Pacer(clock, self.cfg.master.rate_hz)
        t0 = clock.now()
        try:
            while not self.done:
                now = pacer.wait()
                self.step(now)
                if max_duration is not None and now - t0 >= max_duration:
                    break
        finally:
            self.pacer_stats = pacer.stats()
            self.device.set_forces([0.0] * (max(self.axes, default=-1) + 1), clock.now())

    def latency_stats(self) -> dict[str, float | int | None]:
        """Round-trip latency from the command echo [ms]: n, p50, p99, max (None without samples)."""
        if not self.rtts:
            return {"n": 0, "p50_ms": None, "p99_ms": None, "max_ms": None}
        r = np.asarray(self.rtts) * 1e3
        return {"n": int(r.size), "p50_ms": float(np.percentile(r, 50)), "p99_ms": float(np.percentile(r, 99)),
                "max_ms": float(r.max())}

    def stats(self) -> dict[str, Any]:
        """Counters for the run summary (JSON-serialisable)."""
        est = self.links.estimate
        return {"side": "master", "state": self.state.name, "commands_sent": self.commands_sent,
                "estimates_received": int(getattr(est, "count", self.estimates_new)),
                "estimate_decode_errors": int(getattr(est, "errors", 0)), "estimates_new_seen": self.estimates_new,
                "engage_count": self.engage_count, "safe_events": self.safe_events, "last_reason": self.last_reason,
                "max_abs_force_N": self.max_abs_force, "latency_rtt": self.latency_stats(), **self.counts,
                "pacer": dict(self.pacer_stats), "operator_timeouts": int(getattr(self.device, "timeouts", 0)),
                "finished": bool(getattr(self.device, "finished", False))}

    def write_stats(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.stats(), indent=2) + "\n", encoding="utf-8")
