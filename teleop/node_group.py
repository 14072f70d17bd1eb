"""Several nodes of one side stepped in one loop: the arms of a bimanual instrument (:mod:`teleop.arms`).

A :class:`NodeGroup` is a node (:class:`teleop.node.NodeBase`: the same pacing, real-time set-up and
per-cycle figures) whose :meth:`~NodeGroup.step` steps each arm's node with the same ``now``: first every
arm's first phase (up to its command or estimate sent), then every arm's second (forces, recordings,
Rerun, heartbeat), so the last arm's message does not wait for the first arm's recording.
Every arm's node stays whole: its own links, watchdog, state (SAFE, READY, ENGAGED ...), heartbeat,
recordings and counters, so a fault on one arm (its estimates stale, a tendon at its limit, its hand's
device lost) makes that arm safe and leaves the other's cycle untouched; a lost peer process makes
each arm's node safe by its own watchdog. An arm whose node is done is no longer stepped; the group
is done when every arm is.

A slave group's cycles start when the last arm's command arrives (:class:`teleop.timing.clock.LockedPacer`, as a
single slave's start on its command): the master group sends the arms' commands in arm order.

The group times each arm's step (:meth:`arm_step_stats`: p50, p99, max [ms]) so the cost of each arm
in the shared period is visible, and after the loop gives each node the loop's pacer figures, so
each arm's stats read like a single instrument's. The group's own state, which only labels the loop's
per-state figures, is ENGAGED while any arm is, else the first arm's.

Each arm's node logs under its arm's name (:class:`ArmLog`): ``[master] INFO right master ENGAGED -> SAFE at ...:
command echo stale`` says which arm went safe, where both arms share one process's log.
"""
from __future__ import annotations

import logging
import time
from array import array
from collections.abc import Sequence
from typing import Any

import numpy as np

from teleop.node import NodeBase
from teleop.timing.clock import Clock
from teleop.wire.messages import Side, SideState

__all__ = ["ArmLog", "NodeGroup"]


class ArmLog(logging.LoggerAdapter[logging.Logger]):
    """One arm's node log in a process that runs several arms: the arm's name (``extra["arm"]``) before each
    message."""

    def process(self, msg: Any, kwargs: Any) -> tuple[Any, Any]:
        return f"{self.extra['arm']} {msg}" if self.extra else msg, kwargs


class NodeGroup(NodeBase):
    """The nodes of one side's arms, stepped in one loop (module docstring).

    Parameters
    ----------
    nodes : sequence of NodeBase
        One node per arm, all of ``side``.
    names : sequence of str
        The arms' names, one per node.
    side : Side
    rate_hz : float
        The loop's rate [Hz] (``rig.rate_hz`` of the slave, ``master.rate_hz`` of the master).
    cfg : Config, optional
        Whose ``<side>.realtime_priority`` the loop takes (the first arm's).

    Raises
    ------
    ValueError
        No node, or not one name per node.
    """

    def __init__(self, nodes: Sequence[NodeBase], names: Sequence[str], side: Side, rate_hz: float, cfg: Any = None):
        if not nodes or len(nodes) != len(names):
            raise ValueError(f"NodeGroup: expected one name per node, got {len(nodes)} node(s), {len(names)} name(s)")
        super().__init__(heartbeat_hz=1.0)        # each arm's node sends its own heartbeats
        self.nodes = list(nodes)
        self.names = tuple(names)
        for node, name in zip(self.nodes, self.names, strict=True):
            base = node.log if isinstance(node.log, logging.Logger) else node.log.logger
            node.log = ArmLog(base, {"arm": name})
        self.side = side
        self.cfg = cfg
        self.log = logging.getLogger(f"teleop.{side.name.lower()}")
        self._rate = float(rate_hz)
        self._steps = [array("d") for _ in self.nodes]
        self._started = False

    @property
    def rate_hz(self) -> float:
        """The loop's rate [Hz]."""
        return self._rate

    def step(self, now: float) -> None:
        """Step every arm's node that is not done at ``now`` [s]: every node's first phase (its message
        sent), then every node's second; done when all are."""
        if not self._started:
            self._started = True
            for n in self.nodes:
                n._t_origin = self._t_origin
        perf = time.perf_counter
        active = [(node, times) for node, times in zip(self.nodes, self._steps, strict=False) if not node.done]
        for node, times in active:
            t0 = perf()
            node.step_send(now)
            times.append(perf() - t0)
        for node, times in active:
            t0 = perf()
            node.step_after(now)
            times[-1] += perf() - t0
        self.done = all(n.done for n in self.nodes)
        # the loop's figures by state (cycles, overruns) count a cycle ENGAGED when any arm is
        engaged = any(n.state == SideState.ENGAGED for n in self.nodes)
        self.state = SideState.ENGAGED if engaged else self.nodes[0].state

    def _cycle_source(self):
        """The last arm's cycle source (the slave's: its command subscriber): the peer group publishes the
        arms' messages in arm order within one cycle, so when the last arm's has arrived every arm's has."""
        return self.nodes[-1]._cycle_source()

    def _run_ended(self, clock: Clock) -> None:
        for n in self.nodes:
            n.pacer_stats = dict(self.pacer_stats)
            n.scheduling = self.scheduling
            n._run_ended(clock)

    def arm_step_stats(self) -> dict[str, dict[str, float]]:
        """Per arm: ``{"cycles", "p50_ms", "p99_ms", "max_ms"}`` of its node's step time."""
        out = {}
        for name, times in zip(self.names, self._steps, strict=False):
            a = np.frombuffer(times, dtype=float) if len(times) else np.zeros(1)
            out[name] = {"cycles": len(times), "p50_ms": float(1e3 * np.percentile(a, 50)),
                         "p99_ms": float(1e3 * np.percentile(a, 99)), "max_ms": float(1e3 * a.max())}
        return out

    def stats(self) -> dict[str, Any]:
        """The loop's figures (``pacer``), each arm's step time (``arm_steps``) and each arm's own stats (``arms``)."""
        return {"side": self.side.name.lower(),
                "arms": {n: node.stats() for n, node in zip(self.names, self.nodes, strict=False)},
                "arm_steps": self.arm_step_stats(), "pacer": dict(self.pacer_stats),
                "safe_events": sum(getattr(n, "safe_events", 0) for n in self.nodes)}
