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

import math
from typing import Any

from master.mapping import ForceMap, MotionMap, clamp_force
from master.node_base import MasterLinks, MasterNodeBase
from master.passivity import PassivityController
from teleop.clock import Clock
from teleop.config import Config
from teleop.messages import JointCommand, JointEstimate, SideState

__all__ = ["JointMasterLinks", "JointMasterNode"]

#: The joint master's links: the same streams as one tendon's (:class:`master.node_base.MasterLinks`);
#: command, heartbeat: ``put(msg)``; estimate, slave_heartbeat: latest-wins subscribers (``latest()``,
#: ``age(now)``); slave_alive: callable or None.
JointMasterLinks = MasterLinks


class JointMasterNode(MasterNodeBase):
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
        super().__init__(cfg, device, links, stop_linger=stop_linger,
                         counts=("estimates_duplicate", "estimates_out_of_order", "estimates_rejected_range",
                                 "estimates_wrong_joints"))
        joints = cfg.instrument.joints
        self.n = len(joints)
        self.r = [j.pulley_radius for j in joints]
        self.axes = tuple(cfg.pair_control.axes) or tuple(range(self.n))
        m = cfg.master.mapping
        self.motion = [MotionMap(m.motion_scale / r) for r in self.r]
        self.forces = [ForceMap.from_config(m) for _ in joints]
        self.passivity = [PassivityController(m.force_limit, enabled=m.passivity) for _ in joints]
        self.limit = m.force_limit
        self._p_prev: list[float] | None = None
        self.force = [0.0] * self.n
        self.max_abs_force = 0.0

    # ---- links -------------------------------------------------------------------------------------
    def _fits(self, est, now: float) -> bool:
        if isinstance(est, JointEstimate) and len(est.joints) == self.n:
            return True
        self.counts["estimates_wrong_joints"] += 1
        return False

    def _in_range(self, est: JointEstimate, now: float) -> bool:
        if not any(abs(v) > self.max_tension for j in est.joints for t in j.tendons for v in (t.T_in, t.T_out_hat)):
            return True
        self.counts["estimates_rejected_range"] += 1
        self._warn(now, "rejected estimate %d: a tension beyond master.max_tension %g N", est.seq, self.max_tension)
        return False

    def _disengage_all(self) -> None:
        for f in self.forces:
            f.disengage()

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
        if not self._stopping(now, bool(getattr(self.device, "finished", False))):
            self._engagement(now, est, healthy, reason, dev.operator_present, pos)
        engaged = self.state == SideState.ENGAGED
        # ---- command ----
        if engaged:
            angles = tuple(mm.command(p) for mm, p in zip(self.motion, pos))
        else:   # not engaged: hold where the slave says the joints are (always a valid command)
            angles = tuple(mm.last for mm in self.motion) if est is None else tuple(j.angle_hat for j in est.joints)
        marker = int(getattr(self.device, "marker", 0)) if engaged else 0
        self._send_command(JointCommand(self.seq, now, angles, engaged, marker), now)
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
        self._heartbeat(now)

    def _engagement(self, now: float, est: JointEstimate | None, healthy: bool, reason: str, present: bool,
                    pos: list[float]) -> None:
        """ENGAGED when the links are healthy, the operator present and every axis read; else SAFE or READY."""
        if healthy and present and all(math.isfinite(p) for p in pos):
            if self.state != SideState.ENGAGED:
                for mm, f, pc, p, j in zip(self.motion, self.forces, self.passivity, pos, est.joints):
                    mm.anchor(p, j.angle_hat)     # engaging never turns a joint
                    f.engage()
                    pc.reset()
                self.engage_count += 1
                self._set_state(SideState.ENGAGED, now, "slave ready, links fresh")
        else:
            self.last_reason = reason if not healthy else "operator not present"
            if self.state == SideState.ENGAGED:      # a safe event
                for f, mm in zip(self.forces, self.motion):
                    f.disengage()
                    mm.open_clutch()
                self._set_state(SideState.SAFE, now, self.last_reason)
            elif self.state == SideState.STARTING:
                self._set_state(SideState.READY, now, "device read")

    # ---- running -----------------------------------------------------------------------------------
    def _run_ended(self, clock: Clock) -> None:
        self.device.set_forces([0.0] * (max(self.axes, default=-1) + 1), clock.now())

    def _stats_detail(self) -> dict[str, Any]:
        return {"max_abs_force_N": self.max_abs_force, "latency_rtt": self.latency_stats(), **self.counts}
