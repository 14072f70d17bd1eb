"""What every teleoperation node shares, master or slave, one tendon or a joint instrument.

A node is a :meth:`step` callable once per cycle with the time given by the caller and a
:meth:`NodeBase.run` that only paces it (docs/concepts/architecture.md). Around the side-specific cycle every node
does the same bookkeeping, kept here once:

* its :class:`~teleop.wire.messages.SideState` and the log line of every change; a change from ENGAGED
  to SAFE counts as a *safe event*;
* warnings at most once per second (a real-time loop never floods the log);
* the look at the newest message of a latest-wins subscriber, once per message: accepted when it is
  of the expected kind, newer than the last accepted one (uint32 wrap, :func:`teleop.wire.codec.seq_newer`;
  duplicates and reordered old messages are counted) and within the node's bounds;
* a Heartbeat at ``slave.heartbeat_hz`` carrying the state (both sides use that rate): the first at
  once, then one per period without drifting and without bursts after a stall; and one at every
  state change besides, so that a state held for a single cycle still reaches the peer and the recorder;
* pacing at a fixed rate until :attr:`done` (or a maximum duration), the pacer's figures kept for
  the stats, and the stats written as JSON.

A cycle has two phases: :meth:`~NodeBase.step_send`, the work up to the cycle's message sent (the
master's command, the slave's estimate), then :meth:`~NodeBase.step_after`, what can wait (forces
rendered, recordings, Rerun, heartbeat). :meth:`~NodeBase.step` runs both; a group of nodes stepped in
one loop (:class:`teleop.node_group.NodeGroup`) runs every node's first phase before any node's second,
so no arm's message waits for another arm's recording.

Subclasses set :attr:`side` (:class:`~teleop.wire.messages.Side`), :attr:`log` (their logger) and
:attr:`rate_hz`, and provide ``step_send(now)`` (and ``step_after(now)`` when some work can wait),
``stats()`` and the range check ``_in_range(msg, now)`` (``_fits(msg, now)`` optionally);
``links.heartbeat`` takes the heartbeats.
"""
from __future__ import annotations

import gc
import json
import logging
import math
import os
import time
from pathlib import Path
from typing import Any

from teleop.recording.measured import stop_at_cycle_end
from teleop.timing.clock import Clock, LockedPacer, MonotonicClock, Pacer
from teleop.timing.cycles import CycleStats
from teleop.timing.realtime import IDLE, demote_threads, machine_steal, promote_threads, rt_budget, rt_budget_note
from teleop.wire.codec import next_seq, seq_newer
from teleop.wire.messages import Heartbeat, Side, SideState

__all__ = ["NodeBase", "IDLE_GUARD", "RESYNC"]

IDLE_GUARD = 1e-4    # [s] the helper threads' idle window closes this long before the loop's next deadline
#: Messages in a row older than the last accepted one, each newer than the one before, that resynchronise a
#: stream to them (:meth:`NodeBase._newer`): a restarted peer, or a forged sequence number far ahead.
RESYNC = 3


def _machine_now() -> tuple[float | None, tuple[float, float, float] | None]:
    """(steal [s] since boot or None, load averages or None) now."""
    try:
        load: tuple[float, float, float] | None = os.getloadavg()
    except OSError:
        load = None
    return machine_steal(), load


def _machine_during(start: tuple, duration: float) -> dict[str, Any]:
    """The machine during a loop that began at ``start`` (:func:`_machine_now`) and ran ``duration`` [s]:
    ``steal_ms`` (None: unknown), ``load_start``, ``load_end`` (1-minute load averages), ``cpus``, ``loop_s``."""
    steal0, load0 = start
    steal1, load1 = _machine_now()
    return {"steal_ms": None if steal0 is None or steal1 is None else 1e3 * (steal1 - steal0),
            "load_start": None if load0 is None else load0[0], "load_end": None if load1 is None else load1[0],
            "cpus": os.cpu_count(), "loop_s": duration}


class NodeBase:
    """State, warnings, message acceptance, heartbeat, pacing and stats of one node (module docstring).

    Parameters
    ----------
    heartbeat_hz : float
        Heartbeat rate [Hz] (``slave.heartbeat_hz`` on both sides).
    counts : iterable of str
        Names of the node's event counters (all start at 0), reported in the stats.
    """

    side: Side
    log: logging.Logger | logging.LoggerAdapter[logging.Logger]

    links: Any                                 # the subclass's links (``heartbeat`` at least)

    def __init__(self, heartbeat_hz: float, counts=()):
        self.hb_period = 1.0 / heartbeat_hz
        self.state = SideState.STARTING
        self.done = False
        self.seq = 0
        self.hb_seq = 0
        self._next_hb = -math.inf
        self._seen = None                      # last Received object looked at
        self._behind: dict[str, tuple[int, int]] = {}   # noun -> (messages in a row behind the last accepted, seq)
        self._t_warn = -math.inf
        self.safe_events = 0
        self.counts: dict[str, int] = dict.fromkeys(counts, 0)
        self.pacer_stats: dict[str, Any] = {}
        self.cycle_stats: CycleStats | None = None
        self.scheduling = "not run"
        self._t_origin = 0.0                   # [s] clock reading at the loop's start (set by run)
        self._hb_sent_at = -math.inf           # [s] time of the last heartbeat sent

    # ---- state and log -----------------------------------------------------------------------------
    @property
    def rate_hz(self) -> float:
        """The rate :meth:`run` paces :meth:`step` at [Hz]."""
        raise NotImplementedError

    def _set_state(self, state: SideState, now: float | None, why: str) -> None:
        """Change the state (logged with the reason); ENGAGED -> SAFE counts a safe event.

        ``now`` [s] is the loop's clock, None before the loop runs (the constructor). The log gives the
        time since :meth:`run` started the loop and the clock's own reading (the recordings' ``t``)."""
        if state != self.state:
            if now is None:
                when = "at start-up"
            else:
                when = f"at t={now - self._t_origin:.3f} s (clock {now:.3f} s)"
            self.log.info("%s %s -> %s %s: %s", self.side.name.lower(), self.state.name, state.name, when, why)
            if state == SideState.SAFE and self.state == SideState.ENGAGED:
                self.safe_events += 1
            self.state = state
            if now is not None:         # an event: every state reaches the peer and the recording, however short
                self._send_heartbeat(now)

    def _warn(self, now: float, msg: str, *args) -> None:
        """A warning at most once per second (real-time loops never flood the log)."""
        if now - self._t_warn >= 1.0:
            self._t_warn = now
            self.log.warning(msg, *args)

    # ---- incoming messages -------------------------------------------------------------------------
    def _unseen(self, subscriber):
        """The subscriber's newest Received the first time it is looked at, else None."""
        rec = subscriber.latest()
        if rec is None or rec is self._seen:
            return None
        self._seen = rec
        return rec

    def _fits(self, msg, now: float) -> bool:
        """Whether ``msg`` is of the kind this node reads (checked before the order; default True)."""
        return True

    def _in_range(self, msg, now: float) -> bool:
        """Whether the values of ``msg`` are within the node's bounds (else counted and warned)."""
        raise NotImplementedError

    def _take(self, subscriber, last: int | None, noun: str, now: float):
        """The subscriber's newest Received when it is unseen, fits (:meth:`_fits`), is newer than the
        last accepted seq ``last`` (:meth:`_newer`) and is in range (:meth:`_in_range`), in that
        order; else None (each refusal counted by the check that made it)."""
        rec = self._unseen(subscriber)
        if rec is None:
            return None
        msg = rec.message
        if self._fits(msg, now) and self._newer(msg.seq, last, noun) and self._in_range(msg, now):
            return rec
        return None

    def _newer(self, seq: int, last: int | None, noun: str) -> bool:
        """Whether ``seq`` is newer than ``last`` (the last accepted one, None before any); if not,
        counted as ``<noun>_duplicate`` or ``<noun>_out_of_order``.

        :data:`RESYNC` messages in a row older than ``last``, each newer than the one before, are a stream that
        restarted, or a ``last`` far ahead of the stream (a forged or corrupt sequence number): the last of them
        is taken as newer and counted as ``<noun>_resync``, so such a ``last`` holds the real stream back for
        ``RESYNC - 1`` messages, not for the rest of the run."""
        if seq_newer(seq, last):
            self._behind.pop(noun, None)
            return True
        if seq == last:
            self.counts[f"{noun}_duplicate"] += 1
            return False
        run = self._behind.get(noun)
        n = run[0] + 1 if run is not None and seq_newer(seq, run[1]) else 1
        if n >= RESYNC:
            self._behind.pop(noun, None)
            self.counts[f"{noun}_resync"] = self.counts.get(f"{noun}_resync", 0) + 1
            return True
        self._behind[noun] = (n, seq)
        self.counts[f"{noun}_out_of_order"] += 1
        return False

    # ---- outgoing ----------------------------------------------------------------------------------
    def _send_heartbeat(self, now: float) -> None:
        self.links.heartbeat.put(Heartbeat(self.side, self.hb_seq, now, self.state))
        self.hb_seq = next_seq(self.hb_seq)
        self._hb_sent_at = now

    def _heartbeat(self, now: float) -> None:
        """Publish a Heartbeat when one is due (one per ``hb_period``, the first at once); a state change
        publishes one at once besides (:meth:`_set_state`), a state sampled every period could be missed."""
        if now >= self._next_hb:
            if self._hb_sent_at != now:          # not already sent this cycle by a state change
                self._send_heartbeat(now)
            self._next_hb = now + self.hb_period if self._next_hb == -math.inf else max(
                self._next_hb + self.hb_period, now)

    # ---- running -----------------------------------------------------------------------------------
    def run(self, clock: Clock, *, max_duration: float | None = None) -> None:
        """Pace :meth:`step` at :attr:`rate_hz` until :attr:`done` (or ``max_duration`` [s]).

        On the real clock (:class:`~teleop.timing.clock.MonotonicClock`) the loop is prepared first: the
        objects allocated so far are collected once and frozen out of the garbage collector's later
        passes (:func:`gc.freeze`: a full collection then scans only what the loop allocates), the
        threads get their real-time priorities (``<side>.realtime_priority``,
        :func:`teleop.timing.realtime.promote_threads`) and after every step the helper threads are told
        until when the loop sleeps (:data:`teleop.timing.realtime.IDLE`); a node with a :meth:`_cycle_source`
        (the slave: its commands) starts each cycle as a message arrives (:class:`~teleop.timing.clock.LockedPacer`).
        Per-cycle figures:
        :class:`teleop.timing.cycles.CycleStats`, in the stats' ``pacer``; with them ``machine``: the load
        average at the loop's start and end and the hypervisor's steal during the loop
        (:func:`teleop.timing.realtime.machine_steal`, summed over the CPUs), which tells a virtual
        machine's stalls (every process stopped at once) from the loop's own overruns; ``rt_budget_ms`` and
        ``rt_stop_ms``: the kernel's real-time budget (:func:`teleop.timing.realtime.rt_budget`), whose throttling
        stops a ``SCHED_FIFO`` loop for up to ``rt_stop_ms`` (logged at the start when it applies).
        Ctrl-C, SIGTERM and ``max_duration`` end the loop between two steps, and within
        :data:`teleop.timing.clock.MAX_SLEEP` of their time while it sleeps, whatever its period.
        """
        real = isinstance(clock, MonotonicClock)
        if real:
            gc.collect()
            gc.freeze()
            self.scheduling = promote_threads(self._realtime_priority())
            if self.scheduling.startswith("not"):
                self.log.warning("%s loop: real-time priority %s", self.side.name.lower(), self.scheduling)
        budget = rt_budget() if real else None
        note = rt_budget_note(budget) if self.scheduling.startswith("SCHED_FIFO") else None
        if note:
            self.log.info("%s loop: %s", self.side.name.lower(), note)
        source = self._cycle_source() if real else None
        if not (hasattr(source, "wait") and hasattr(source, "count")):
            source = None
        pacer = Pacer(clock, self.rate_hz) if source is None else LockedPacer(clock, self.rate_hz, source)
        cycles = self.cycle_stats = CycleStats(self.side.name.lower())
        perf, cpu = time.perf_counter, time.thread_time
        idle = IDLE.open if real else None
        machine = _machine_now() if real else None
        # the grid starts now: the set-up above (files read, arrays made) is not in the first period
        pacer.reset()
        t0 = self._t_origin = clock.now()
        # Ctrl-C / SIGTERM are held until the running step has finished, then raised after the clean-up
        with stop_at_cycle_end() as stop:
            def halt() -> bool:        # asked while the pacer sleeps: a long period still ends on time
                return stop.pending is not None or (max_duration is not None and clock.now() - t0 >= max_duration)

            try:
                while not self.done and stop.pending is None:
                    now = pacer.wait(halt)
                    if pacer.halted:
                        break
                    state = self.state.name
                    c_step, t_step = cpu(), perf()
                    self.step(now)
                    t_end = perf()
                    cycles.add(now, pacer.last_lateness, pacer.last_overrun, t_end - t_step, state, cpu() - c_step)
                    if idle is not None:
                        idle(pacer.next_wake - IDLE_GUARD)
                    if max_duration is not None and now - t0 >= max_duration:
                        break
            finally:
                if real:
                    IDLE.release()
                    demote_threads()
                self.pacer_stats = {**pacer.stats(), **cycles.stats(), "scheduling": self.scheduling}
                if machine is not None:
                    self.pacer_stats["machine"] = _machine_during(machine, clock.now() - t0)
                if budget is not None:
                    self.pacer_stats.update(budget.stats())
                cycles.dump()
                self._run_ended(clock)
        stop.reraise()

    def _cycle_source(self):
        """A subscriber whose messages start the cycles (:class:`~teleop.timing.clock.LockedPacer`), or None: the
        fixed grid (default)."""
        return None

    def _realtime_priority(self) -> int:
        """``<side>.realtime_priority`` of the node's config (0 without one)."""
        section = getattr(getattr(self, "cfg", None), self.side.name.lower(), None)
        return int(getattr(section, "realtime_priority", 0) or 0)

    def _run_ended(self, clock: Clock) -> None:
        """Called once when :meth:`run` returns or raises (default: nothing)."""

    def step(self, now: float) -> None:
        """One cycle at ``now`` [s]: :meth:`step_send`, then :meth:`step_after`."""
        self.step_send(now)
        self.step_after(now)

    def step_send(self, now: float) -> None:  # pragma: no cover - abstract
        """The cycle's first phase at ``now`` [s]: everything up to its message sent."""
        raise NotImplementedError

    def step_after(self, now: float) -> None:
        """The cycle's second phase at ``now`` [s]: what can wait until the message is sent (default: nothing)."""

    def stats(self) -> dict[str, Any]:  # pragma: no cover - abstract
        raise NotImplementedError

    def write_stats(self, path: str | Path) -> None:
        """Write :meth:`stats` as JSON to ``path``."""
        Path(path).write_text(json.dumps(self.stats(), indent=2) + "\n", encoding="utf-8")
