"""The link side of the master node (:mod:`master.node`, one node for every instrument; kept apart for size).

The link side of the master, the same whatever it renders:

* an estimate is *accepted* when it is of the kind the node expects, its seq is newer than the last
  accepted one (duplicates and reordered ones are counted and ignored) and its tensions are within
  ``master.max_tension`` (else counted as rejected, warned at most once a second);
* every command's send time is kept by seq in a ring buffer; an accepted estimate echoing
  ``cmd_seq`` gives the round-trip latency without synchronised clocks;
* link health (:meth:`MasterNodeBase._peer_status`): the slave's heartbeat is fresh (younger than
  ``max(watchdog_ms, 3 heartbeat periods)``) and says READY or ENGAGED, its liveliness token (when
  watched) is present, the last accepted estimate is younger than ``master.watchdog_ms`` and the
  command it echoes was sent less than ``2 watchdog_ms`` ago (one budget per leg);
* STOPPING for ``stop_linger`` seconds once the device reports ``finished``, then :attr:`done`;
* the counters of the run summary that do not depend on the device.
"""
from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from teleop.config.schema import Config
from teleop.node import NodeBase
from teleop.timing.latency import LatencyHistogram
from teleop.wire.codec import next_seq
from teleop.wire.messages import Side, SideState

__all__ = ["MasterLinks", "MasterNodeBase", "RING_SIZE"]

RING_SIZE = 4096            # command send times kept for the latency echo (4 s at 1 kHz)
_SLAVE_OK = (SideState.READY, SideState.ENGAGED)


@dataclass
class MasterLinks:
    """The master's side of the transport (real: :mod:`teleop.session.transport`; tests: in-memory fakes).

    command, heartbeat : objects with ``put(msg)``.
    estimate, slave_heartbeat : latest-wins subscribers with ``latest() -> Received | None``
        (``.message``, ``.t_recv``) and ``age(now) -> float`` [s].
    slave_alive : callable returning whether the slave's liveliness token is present, or None.
    crtk : the CRTK side (:class:`teleop.ros2.side.MasterCrtk`) or None: handed the state, the device
        positions and the rendered forces at the end of each cycle (a thread publishes them on ROS 2).
    """

    command: Any
    heartbeat: Any
    estimate: Any
    slave_heartbeat: Any
    slave_alive: Callable[[], bool] | None = None
    crtk: Any = None    # with ros2.enabled: offer(state, positions, forces) each cycle (teleop/ros2/side.py)


class MasterNodeBase(NodeBase):
    """The link side of a master node (module docstring).

    Subclasses implement ``step(now)``, ``_in_range(est, now)`` (tensions within
    ``master.max_tension``), :meth:`_stats_detail` and :meth:`_disengage_all`; ``_fits(est, now)``
    and ``_run_ended(clock)`` (zero force) as needed.

    Parameters
    ----------
    cfg : Config
        ``master`` (rate, watchdog, max_tension) and ``slave.heartbeat_hz`` are used here.
    device : the haptic device (``finished``, ``timeouts``, ``segment_events`` read when present).
    links : MasterLinks
    stop_linger : float
        Time the STOPPING state is announced before :attr:`done` [s].
    counts : iterable of str
        The node's event counters.
    """

    side = Side.MASTER
    log = logging.getLogger("teleop.master")

    def __init__(self, cfg: Config, device, links: MasterLinks, *, stop_linger: float, counts):
        super().__init__(cfg.slave.heartbeat_hz, counts)
        self.cfg = cfg
        self.device = device
        self.links = links
        self.max_tension = cfg.master.max_tension
        self.watchdog = cfg.master.watchdog_ms * 1e-3
        self.hb_timeout = max(self.watchdog, 3.0 * self.hb_period)
        self.stop_linger = float(stop_linger)
        self._accepted = None                  # last accepted Received estimate
        self._last_est_seq: int | None = None
        self._t_echo: float | None = None      # send time of the last echoed command [s]
        self._last_echo: int | None = None
        self._t_stop: float | None = None
        self._t_prev: float | None = None
        self._sent_seq = np.full(RING_SIZE, -1, dtype=np.int64)
        self._sent_t = np.zeros(RING_SIZE)
        self.rtt = LatencyHistogram()          # round trips [s], constant memory over any session length
        self.commands_sent = 0
        self.estimates_new = 0
        self.engage_count = 0
        self.last_reason = "starting"

    @property
    def rate_hz(self) -> float:
        return self.cfg.master.rate_hz

    # ---- links -------------------------------------------------------------------------------------
    def _receive(self, now: float) -> None:
        """Accept the newest estimate (kind, order, range); the echo gives the round trip."""
        rec = self._take(self.links.estimate, self._last_est_seq, "estimates", now)
        if rec is None:
            return
        est = rec.message
        self._accepted = rec
        self._last_est_seq = est.seq
        self.estimates_new += 1
        i = est.cmd_seq % RING_SIZE
        if self._sent_seq[i] != est.cmd_seq:
            return
        self._t_echo = self._sent_t[i]
        if est.cmd_seq == self._last_echo:
            return
        self._last_echo = est.cmd_seq
        self.rtt.add(getattr(rec, "t_recv", now) - self._sent_t[i])

    def _peer_status(self, now: float) -> tuple[Any, bool, str]:
        """(latest accepted estimate or None, all links healthy, reason if not)."""
        rec = self._accepted
        est = None if rec is None else rec.message
        hb_rec = self.links.slave_heartbeat.latest()
        if hb_rec is None or self.links.slave_heartbeat.age(now) > self.hb_timeout:
            return est, False, "slave heartbeat missing"
        if self.links.slave_alive is not None and not self.links.slave_alive():
            return est, False, "slave liveliness token gone"
        if hb_rec.message.state not in _SLAVE_OK:
            return est, False, f"slave {hb_rec.message.state.name}"
        if est is None or now - rec.t_recv > self.watchdog:
            return est, False, "estimate stale"
        if self._t_echo is None or now - self._t_echo > 2.0 * self.watchdog:
            return est, False, "command echo stale"
        return est, True, "ok"

    def _send_command(self, msg, now: float) -> None:
        """Publish ``msg`` (built with seq :attr:`seq`) and keep its send time for the echo."""
        self.links.command.put(msg)
        i = self.seq % RING_SIZE
        self._sent_seq[i], self._sent_t[i] = self.seq, now
        self.seq = next_seq(self.seq)
        self.commands_sent += 1

    # ---- stopping ----------------------------------------------------------------------------------
    def _disengage_all(self) -> None:
        """Forces off at once (and whatever else the node disengages) when STOPPING begins."""
        raise NotImplementedError

    def _stopping(self, now: float, finished: bool) -> bool:
        """STOPPING once ``finished``, :attr:`done` after ``stop_linger``; whether the node is stopping."""
        if not (finished or self._t_stop is not None):
            return False
        if self._t_stop is None:
            self._t_stop = now
            self._disengage_all()
            self._set_state(SideState.STOPPING, now, "protocol finished")
        if now - self._t_stop >= self.stop_linger:
            self.done = True
        return True

    # ---- summary -----------------------------------------------------------------------------------
    def latency_stats(self) -> dict[str, float | int | None]:
        """Round-trip latency from the command echo [ms]: n, p50, p99, max (None without samples;
        :class:`teleop.timing.latency.LatencyHistogram`)."""
        return self.rtt.stats()

    def _stats_detail(self) -> dict[str, Any]:
        """The node's own counters, between the link counters and the pacer in :meth:`stats`."""
        raise NotImplementedError

    def refusals(self) -> dict[str, int]:
        """Every estimate-class message refused, by reason (the stats' ``refusals``): ``decode_error`` (estimates
        and slave heartbeats that did not decode), ``wrong_instrument``, ``out_of_range`` (a tension beyond
        ``master.max_tension``), ``out_of_order``, ``duplicate``. A peer without the installation's credentials
        never links (teleop/session/credentials.py)."""
        c = self.counts
        return {"decode_error": int(getattr(self.links.estimate, "errors", 0))
                + int(getattr(self.links.slave_heartbeat, "errors", 0)),
                "wrong_instrument": c["estimates_wrong_instrument"], "out_of_range": c["estimates_rejected_range"],
                "out_of_order": c["estimates_out_of_order"], "duplicate": c["estimates_duplicate"]}

    def stats(self) -> dict[str, Any]:
        """Counters for the run summary (JSON-serialisable)."""
        est_sub = self.links.estimate
        return {
            "side": "master",
            "state": self.state.name,
            "commands_sent": self.commands_sent,
            "estimates_received": int(getattr(est_sub, "count", self.estimates_new)),
            "estimate_decode_errors": int(getattr(est_sub, "errors", 0)),
            "estimates_new_seen": self.estimates_new,
            "engage_count": self.engage_count,
            "safe_events": self.safe_events,
            "last_reason": self.last_reason,
            **self._stats_detail(),
            "refusals": self.refusals(),
            "pacer": dict(self.pacer_stats),
            "operator_timeouts": int(getattr(self.device, "timeouts", 0)),
            "operator_segments": getattr(self.device, "segment_events", []),
            "finished": bool(getattr(self.device, "finished", False)),
        }
