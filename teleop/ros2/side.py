"""A side's CRTK topics on ROS 2 (``ros2.enabled``): a publisher thread off the control loop, and ``servo_jp`` in.

The 1 kHz loop keeps the project's own wire format (:mod:`teleop.wire.codec`). Beside it, each cycle the
node hands what the CRTK topics need to :meth:`CrtkSide.offer`: one tuple stored in a latest-value slot
(one reference assignment: the loop never waits on ROS 2). A thread wakes at ``ros2.rate_hz``, takes
the newest tuple, encodes the topics of :mod:`teleop.ros2.crtk` in CDR and puts them on Zenoh the rmw_zenoh
way (:mod:`teleop.ros2.wire`); each encoding is done while the loop sleeps
(:data:`teleop.timing.realtime.IDLE`), so the thread holds the interpreter lock only in the loop's idle time.

With ``ros2.accept_commands`` (off by default: publishing only) the slave also subscribes to ``servo_jp`` and
``state_command`` (:class:`SlaveCrtk`): a valid
``servo_jp`` becomes an engaged :class:`~teleop.wire.messages.Command` that :class:`CommandMerge` offers to
the node beside the master's commands (the newest wins), so a ROS 2 node drives the instrument under
the same watchdog, range and engage rules as the project's master. A ROS 2 driver must stream
``servo_jp`` faster than the slave's watchdog (``slave.watchdog_ms``) and start from where
``measured_js`` says the instrument is (``slave.engage_tolerance``), as the master does. Its
publisher's liveliness token stands in for the master's: while one is present the slave does not
go SAFE for a missing master.
"""
from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable, Iterable
from typing import Any

from teleop.rerun.thread import lower_switch_interval
from teleop.ros2.crtk import (
    STATE_COMMANDS,
    axis_names,
    command_topics,
    master_messages,
    master_topics,
    servo_targets,
    slave_arm,
    slave_messages,
    slave_topics,
)
from teleop.ros2.types import JOINT_STATE, STRING_STAMPED, dds_type_name, decode, stamp_ns, type_hash, warm_up
from teleop.ros2.wire import ADMIN_SPACE, Attachment, RosNode, mangle
from teleop.session.entity import RateLimitedLog
from teleop.session.transport import Received
from teleop.timing.realtime import IDLE
from teleop.wire.codec import next_seq, seq_newer
from teleop.wire.messages import Command, SideState

__all__ = ["TOPIC_COST", "CrtkSide", "SlaveCrtk", "MasterCrtk", "CommandMerge", "attach_slave", "attach_master"]

log = logging.getLogger("teleop.ros2")
TOPIC_COST = 1e-4      # [s] encoding and putting one topic holds the interpreter about this long (~30-60 us)


class CrtkSide:
    """The publisher thread of one side (module docstring).

    Parameters
    ----------
    session : teleop.session.transport.Session
    cfg : Config
        ``ros2`` (domain, rate) and the instrument.
    node_name : str
        The ROS 2 node name.
    topics : dict
        Topic -> ROS 2 type of every published topic.
    messages : callable(t_ns, *offered) -> iterable of (topic, CDR bytes), encoding each topic when reached

    Attributes
    ----------
    published : int
        Publications done (each puts every topic once).
    errors : int
        Publications that failed (logged at a limited rate; the thread goes on).
    """

    def __init__(self, session: Any, cfg: Any, node_name: str, topics: dict[str, str],
                 messages: Callable[..., Iterable[tuple[str, bytes]]]):
        self.cfg = cfg
        self.period = 1.0 / cfg.ros2.rate_hz
        warm_up()      # rosbags' generated code exists before the loop freezes its set-up out of the collector
        self.node = RosNode(session.zenoh_session, cfg.ros2.domain_id, node_name)
        self.publishers = {t: self.node.publisher(t, ty) for t, ty in topics.items()}
        self._messages = messages
        self._slot: tuple | None = None
        self.published = self.errors = 0
        self._log = RateLimitedLog(log, 1.0, session.clock)
        self._stop = threading.Event()
        lower_switch_interval()
        self._thread = threading.Thread(target=self._run, name="crtk-publisher", daemon=True)
        self._thread.start()
        session._track(self)     # closed with the session, before its Zenoh entities

    def offer(self, *values) -> None:
        """Called by the loop: the newest values for the next publication (stored, nothing else)."""
        self._slot = (time.time_ns(), *values)

    def publish_now(self, item: tuple) -> None:
        """Encode and put every topic of ``item`` (``(t_ns, *offered)``) now."""
        topics = iter(self._messages(*item))      # each topic is encoded as the iteration reaches it
        while True:
            IDLE.wait(TOPIC_COST)                  # encode and put in the loop's idle time
            nxt = next(topics, None)
            if nxt is None:
                break
            self.publishers[nxt[0]].put(nxt[1], item[0])
        self.published += 1

    def _run(self) -> None:
        sent = None
        deadline = time.monotonic()
        while not self._stop.wait(max(0.0, deadline - time.monotonic())):
            deadline = max(deadline + self.period, time.monotonic())
            item = self._slot
            if item is None or item is sent:
                continue
            sent = item
            try:
                self.publish_now(item)
            except Exception as e:  # noqa: BLE001 - ROS 2 publishing never ends the side
                self.errors += 1
                self._log.warning("CRTK publication failed: %r", e)

    def close(self) -> None:
        """Stop the thread, then undeclare the node (idempotent)."""
        self._stop.set()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(2.0)
        self.node.close()


class MasterCrtk(CrtkSide):
    """The master's CRTK topics; the node calls ``offer(state, positions, forces)`` each cycle."""

    def __init__(self, session: Any, cfg: Any):
        super().__init__(session, cfg, f"teleop_{slave_arm(cfg)}_master", master_topics(cfg),
                         lambda t_ns, state, pos, forces: master_messages(cfg, t_ns, state, pos, forces))


class SlaveCrtk(CrtkSide):
    """The slave's CRTK topics and its ``servo_jp`` / ``state_command`` subscriptions.

    The node calls ``offer(state, accepted)`` each cycle (``accepted``: the Received command it
    follows, or None); the estimate comes from the estimate publisher's tee (:meth:`tee`).

    Attributes
    ----------
    servo : Received or None
        The newest ``servo_jp`` as a Command (``t_recv`` on the session's clock).
    servo_admitted : bool
        ``state_command`` enable/resume (True, the start) or disable/pause (False).
    servo_refused : int
        ``servo_jp`` messages refused (wrong joints, non-finite, or while disabled/paused).
    """

    def __init__(self, session: Any, cfg: Any, primary: Any = None):
        names = axis_names(cfg)
        super().__init__(session, cfg, f"teleop_{slave_arm(cfg)}_slave", slave_topics(cfg), self._slave_messages)
        self.names, self.primary, self.clock = names, primary, session.clock
        self.estimate: Any = None
        self.servo: Received[Command] | None = None
        self.servo_admitted = True
        self.servo_refused = 0
        self.state_commands_refused = 0
        self._seq = 0
        self.driver = None
        if not cfg.ros2.accept_commands:
            return
        servo_topic, state_topic = command_topics(cfg)
        self.node.subscription(servo_topic, JOINT_STATE, self._on_servo)
        self.node.subscription(state_topic, STRING_STAMPED, self._on_state_command)
        d = cfg.ros2.domain_id
        self.driver = session.liveliness_watcher(
            f"{ADMIN_SPACE}/{d}/*/*/*/MP/*/*/*/{mangle(servo_topic)}/{dds_type_name(JOINT_STATE)}/"
            f"{type_hash(JOINT_STATE)}/*")

    def _slave_messages(self, t_ns: int, state: SideState, accepted: Any, fault: bool = False) \
            -> Iterable[tuple[str, bytes]]:
        targets = accepted.message.targets if accepted is not None and state == SideState.ENGAGED else None
        return slave_messages(self.cfg, t_ns, state, self.estimate, targets, fault)

    def tee(self, publisher: Any) -> _Tee:
        """The estimate publisher ``publisher`` wrapped so that each estimate put is also kept here."""
        return _Tee(publisher, self)

    def _on_servo(self, cdr: bytes, att: Attachment | None) -> None:
        msg = decode(cdr, JOINT_STATE)
        try:
            targets = servo_targets(msg, self.names)
        except ValueError:
            self.servo_refused += 1
            raise
        if not self.servo_admitted:
            self.servo_refused += 1
            return
        p = None if self.primary is None else self.primary.latest()
        base = p.message.seq if p is not None and seq_newer(p.message.seq, self._seq) else self._seq
        self._seq = next_seq(base)
        t = stamp_ns(msg) or (att.t_ns if att is not None else 0)
        self.servo = Received(Command(self._seq, 1e-9 * t, targets, True, 0), self.clock.now())

    def _on_state_command(self, cdr: bytes, att: Attachment | None) -> None:
        text = str(decode(cdr, STRING_STAMPED).string).strip().lower()
        if text not in STATE_COMMANDS:
            self.state_commands_refused += 1
            raise ValueError(f"state_command {text!r} is not one of {', '.join(STATE_COMMANDS)}")
        admitted = STATE_COMMANDS[text]
        if admitted != self.servo_admitted:     # each change logged once; a repeated command changes nothing
            log.info("state_command %s: servo_jp %s", text, "admitted" if admitted else "refused")
        self.servo_admitted = admitted

    def driver_alive(self) -> bool:
        """A ROS 2 publisher of ``servo_jp`` is present (its liveliness token); never without
        ``ros2.accept_commands``."""
        return self.driver is not None and self.driver.alive


class _Tee:
    """An estimate publisher that also hands each estimate to a :class:`SlaveCrtk` (one assignment)."""

    def __init__(self, publisher: Any, crtk: SlaveCrtk):
        self._pub, self._crtk = publisher, crtk

    def put(self, msg: Any) -> None:
        self._pub.put(msg)
        self._crtk.estimate = msg

    def __getattr__(self, name: str) -> Any:
        return getattr(self._pub, name)


class CommandMerge:
    """The slave's command source: the master's subscriber and ROS 2 ``servo_jp``, the newest first.

    ``latest()`` returns the very Received object of whichever arrived last (the node looks at each
    once); ``count`` and ``wait`` are the master subscriber's, so a slave locked to the master's
    commands (:class:`~teleop.timing.clock.LockedPacer`) keeps its timing.
    """

    def __init__(self, primary: Any, crtk: SlaveCrtk):
        self.primary, self.crtk = primary, crtk

    def latest(self) -> Received | None:
        p, r = self.primary.latest(), self.crtk.servo
        if r is None or (p is not None and p.t_recv >= r.t_recv):
            return p
        return r

    def age(self, now: float) -> float:
        rec = self.latest()
        return math.inf if rec is None else now - rec.t_recv

    @property
    def count(self) -> int:
        return int(getattr(self.primary, "count", 0))

    @property
    def errors(self) -> int:
        return int(getattr(self.primary, "errors", 0))

    def wait(self, count: int = 1, timeout: float | None = None) -> bool:
        return self.primary.wait(count, timeout)


def attach_slave(session: Any, cfg: Any, links: Any) -> SlaveCrtk | None:
    """With ``ros2.enabled``, the slave's CRTK side wired into ``links`` (a
    :class:`~slave.node_base.SlaveLinks`): estimates teed, ``links.crtk`` set; with ``ros2.accept_commands`` also
    ``servo_jp`` merged into the commands and a ROS 2 driver's liveliness counted as the master's. None when
    disabled."""
    if not cfg.ros2.enabled:
        return None
    crtk = SlaveCrtk(session, cfg, links.command)
    links.estimate = crtk.tee(links.estimate)
    links.crtk = crtk
    if not cfg.ros2.accept_commands:    # publishing only: no ROS 2 node moves the instrument
        return crtk
    links.command = CommandMerge(links.command, crtk)
    master_alive = links.master_alive
    if master_alive is not None:        # a ROS 2 driver's token counts as the master's
        links.master_alive = lambda: master_alive() or crtk.driver_alive()
    return crtk


def attach_master(session: Any, cfg: Any, links: Any) -> MasterCrtk | None:
    """With ``ros2.enabled``, the master's CRTK side set as ``links.crtk``; None when disabled."""
    if not cfg.ros2.enabled:
        return None
    links.crtk = MasterCrtk(session, cfg)
    return links.crtk
