"""Zenoh transport: two real peers in this process on 127.0.0.1, distinct free ports per test.

Waits are bounded (a few seconds) and end as soon as the condition holds; nothing sleeps for a fixed
time and no assertion is about how long something took.
"""
from __future__ import annotations

import json
import logging
import math

import pytest

from estimator.phase import Phase
from teleop.config.schema import TransportConfig
from teleop.errors import CodecError, ConfigError, TransportError
from teleop.session.entity import RateLimitedLog
from teleop.session.transport import Session, free_tcp_port, free_tcp_ports, loopback_endpoint, zenoh_config
from teleop.timing.clock import FakeClock
from teleop.wire.keys import command_key, estimate_key, liveliness_key, liveliness_pattern
from teleop.wire.messages import Command, Estimate, Side, tendon_estimate

DEADLINE = 5.0     # [s] upper bound of any wait; the waits return as soon as the event happens


def _listener(port: int) -> TransportConfig:
    return TransportConfig(listen=(loopback_endpoint(port),), connect=())


def _connector(port: int) -> TransportConfig:
    return TransportConfig(listen=(), connect=(loopback_endpoint(port),))


@pytest.fixture
def pair():
    """(listening session, connecting session) on a fresh port; both closed afterwards."""
    port = free_tcp_port()
    a = Session(_listener(port))
    b = Session(_connector(port))
    yield a, b
    b.close()
    a.close()


def _publish_until_received(pub, sub, msg, count=1) -> bool:
    """Publish ``msg`` until ``sub`` has ``count`` messages (the first ones may precede route discovery)."""
    for _ in range(int(DEADLINE / 0.05)):
        pub.put(msg)
        if sub.wait(count, timeout=0.05):
            return True
    return False


def test_zenoh_config_defaults_are_loopback_peer_without_multicast():
    cfg = zenoh_config(TransportConfig())
    assert json.loads(cfg.get_json("mode")) == "peer"
    assert json.loads(cfg.get_json("listen/endpoints")) == ["tcp/127.0.0.1:7447"]
    assert json.loads(cfg.get_json("connect/endpoints")) == []
    assert json.loads(cfg.get_json("scouting/multicast/enabled")) is False
    assert json.loads(cfg.get_json("scouting/gossip/enabled")) is True
    over = zenoh_config(TransportConfig(), listen=(), connect=("tcp/127.0.0.1:9",))
    assert json.loads(over.get_json("listen/endpoints")) == []
    assert json.loads(over.get_json("connect/endpoints")) == ["tcp/127.0.0.1:9"]


def test_zenoh_config_names_a_bad_endpoint():
    with pytest.raises(ConfigError, match=r"transport.connect\[1\]: 'nonsense' rejected by zenoh: Endpoints must be"):
        zenoh_config(TransportConfig(connect=("tcp/127.0.0.1:1", "nonsense")))


def test_free_tcp_ports_are_distinct():
    ports = free_tcp_ports(8)
    assert len(set(ports)) == 8 and all(0 < p < 65536 for p in ports)


def test_command_published_is_received_decoded(pair):
    a, b = pair
    sub = a.subscriber(command_key("t1"), expect=Command)
    pub = b.publisher(command_key("t1"))
    assert sub.latest() is None and sub.age(0.0) == math.inf
    msg = Command(42, 1.25, (0.003,), True, 7)
    assert _publish_until_received(pub, sub, msg)
    rec = sub.latest()
    assert rec.message == msg and isinstance(rec.message, Command)
    assert sub.errors == 0 and pub.sent >= sub.count >= 1


def test_latest_wins_and_estimate_profile_survives(pair):
    a, b = pair
    sub = a.subscriber(estimate_key("t2"), expect=Estimate)
    pub = b.publisher(estimate_key("t2"))
    first = tendon_estimate(0, 0, 0.0, 1.0, 0.0, 1.0, 0.0, 0.0, Phase.HOLD)
    assert _publish_until_received(pub, sub, first)
    n = sub.count
    for seq in range(1, 21):
        pub.put(tendon_estimate(seq, seq, 0.1 * seq, 5.0, 0.01, 3.0, 1e-4, 0.0099, Phase.PULL, (5.0, 4.0, 3.0)))
    assert sub.wait(n + 20, timeout=DEADLINE)
    last = sub.latest().message
    assert last.seq == 20 and last.profiles == ((5.0, 4.0, 3.0),) and last.tendons[0].phase is Phase.PULL


def test_garbage_is_counted_not_raised_and_subscriber_survives(pair, caplog):
    a, b = pair
    sub = a.subscriber(command_key("t3"), expect=Command)
    pub = b.publisher(command_key("t3"))
    assert _publish_until_received(pub, sub, Command(1, 0.0, (0.0,)))
    with caplog.at_level(logging.WARNING, logger="teleop.session.transport"):
        pub.put_bytes(b"\x00garbage")
        pub.put_bytes(b"\xa7\x03\x01" + bytes(25))                       # a future wire version
        assert sub.wait_errors(2, timeout=DEADLINE)
    assert sub.latest().message == Command(1, 0.0, (0.0,))                  # garbage did not replace it
    assert "dropped a bad message" in caplog.text
    n = sub.count
    pub.put(Command(2, 0.0, (0.001,)))
    assert sub.wait(n + 1, timeout=DEADLINE)
    assert sub.latest().message.seq == 2 and sub.errors == 2


def test_wrong_message_type_on_a_key_is_an_error(pair):
    a, b = pair
    sub = a.subscriber(command_key("t4"), expect=Command)
    pub = b.publisher(command_key("t4"))
    assert _publish_until_received(pub, sub, Command(1, 0.0, (0.0,)))
    pub.put(tendon_estimate(0, 0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, Phase.HOLD))
    assert sub.wait_errors(1, timeout=DEADLINE)
    assert sub.latest().message == Command(1, 0.0, (0.0,))


def test_receive_time_comes_from_the_injected_clock():
    port = free_tcp_port()
    clock = FakeClock(100.0)
    with Session(_listener(port), clock=clock) as a, Session(_connector(port)) as b:
        sub = a.subscriber(command_key("t5"))
        pub = b.publisher(command_key("t5"))
        assert _publish_until_received(pub, sub, Command(1, 0.0, (0.0,)))
        assert sub.latest().t_recv == 100.0
        assert sub.age(100.25) == pytest.approx(0.25)


def test_liveliness_token_seen_then_gone_when_peer_session_closes():
    port = free_tcp_port()
    events = []
    with Session(_listener(port)) as a:
        watcher = a.liveliness_watcher(liveliness_key("t6", Side.SLAVE), lambda k, up: events.append((k, up)))
        assert not watcher.alive
        b = Session(_connector(port))
        b.liveliness_token(liveliness_key("t6", Side.SLAVE))
        assert watcher.wait_for(True, timeout=DEADLINE)
        assert watcher.present == {"teleop/t6/slave/alive"}
        b.close()
        assert watcher.wait_for(False, timeout=DEADLINE)
    assert events == [("teleop/t6/slave/alive", True), ("teleop/t6/slave/alive", False)]


def test_liveliness_token_already_present_is_reported_and_undeclare_is_seen():
    port = free_tcp_port()
    with Session(_listener(port)) as a, Session(_connector(port)) as b:
        token = b.liveliness_token(liveliness_key("t7", Side.MASTER))
        watcher = a.liveliness_watcher(liveliness_pattern("t7"))        # history: sees existing tokens
        assert watcher.wait_for(True, timeout=DEADLINE)
        token.close()
        token.close()                                                     # idempotent
        assert watcher.wait_for(False, timeout=DEADLINE)
        assert watcher.changes == 2


def test_a_failing_liveliness_callback_does_not_break_the_watcher():
    port = free_tcp_port()

    def boom(key, up):
        raise RuntimeError("user bug")
    with Session(_listener(port)) as a, Session(_connector(port)) as b:
        watcher = a.liveliness_watcher(liveliness_key("t8", Side.SLAVE), boom)
        tok = b.liveliness_token(liveliness_key("t8", Side.SLAVE))
        assert watcher.wait_for(True, timeout=DEADLINE)
        tok.close()
        assert watcher.wait_for(False, timeout=DEADLINE)


def test_close_is_idempotent_and_use_after_close_is_a_transport_error():
    port = free_tcp_port()
    s = Session(_listener(port))
    pub = s.publisher(command_key("t9"))
    sub = s.subscriber(command_key("t9"))
    s.close()
    s.close()
    assert s.closed and pub.closed and sub.closed
    pub.close()
    with pytest.raises(TransportError, match="closed"):
        pub.put(Command(1, 0.0, (0.0,)))
    with pytest.raises(TransportError, match="session already closed"):
        s.publisher(command_key("t9"))


def test_port_in_use_is_a_transport_error():
    port = free_tcp_port()
    with Session(_listener(port)):
        with pytest.raises(TransportError, match="cannot open zenoh session: .*Address already in use"):
            Session(_listener(port))


def test_encode_errors_reach_the_sender(pair):
    _, b = pair
    pub = b.publisher(command_key("t10"))
    with pytest.raises(CodecError, match=r"Command.targets\[0\] is nan"):
        pub.put(Command(1, 0.0, (math.nan,)))
    assert pub.sent == 0


def test_rate_limited_log_suppresses_and_reports_the_count(caplog):
    clock = FakeClock()
    rl = RateLimitedLog(logging.getLogger("test.rl"), interval=1.0, clock=clock)
    with caplog.at_level(logging.WARNING, logger="test.rl"):
        assert rl.warning("bad %d", 1) is True
        assert rl.warning("bad %d", 2) is False
        assert rl.warning("bad %d", 3) is False
        clock.advance(1.0)
        assert rl.warning("bad %d", 4) is True
    assert [r.getMessage() for r in caplog.records] == ["bad 1", "bad 4 (2 similar suppressed)"]


def test_close_returns_when_zenoh_teardown_blocks(monkeypatch, caplog):
    # a bound on shutdown: the zenoh teardown runs in a daemon thread and close() returns after CLOSE_TIMEOUT_S
    # with a warning
    import threading

    import teleop.session.transport as transport

    release = threading.Event()

    class Blocking:
        closed = 0

        def close(self):
            release.wait(30.0)
            Blocking.closed += 1

    s = Session(_listener(free_tcp_port()))
    real = s._z
    s._z = Blocking()
    monkeypatch.setattr(transport, "CLOSE_TIMEOUT_S", 0.2)
    with caplog.at_level(logging.WARNING, logger="teleop.session.transport"):
        s.close()
    assert s.closed and Blocking.closed == 0
    assert "did not close within 0.2 s" in caplog.text
    s.close()                                   # idempotent: no second teardown
    release.set()
    real.close()
    for _ in range(int(DEADLINE / 0.01)):
        if Blocking.closed:
            break
        threading.Event().wait(0.01)
    assert Blocking.closed == 1


def test_close_raises_what_an_entity_close_raised_in_the_teardown():
    class Broken:
        def close(self):
            raise RuntimeError("undeclare failed")

    s = Session(_listener(free_tcp_port()))
    s._track(Broken())
    real = s._z
    with pytest.raises(RuntimeError, match="undeclare failed"):
        s.close()
    assert s.closed
    real.close()
