"""The fault injector on a fake clock: delay, drop, dup, reorder, corruption, triggers, spec parsing."""
from __future__ import annotations

import math
import os
import signal
import struct

import pytest

from estimator.phase import Phase
from live.faults import FaultInjector, corrupt_payload, parse_fault_spec
from teleop.errors import CodecError, ConfigError
from teleop.timing.clock import FakeClock
from teleop.wire.codec import WIRE_VERSION, decode, encode
from teleop.wire.messages import AxisState, Command, Estimate, Heartbeat, Side, SideState, TendonState, tendon_estimate

DT = 1e-3


class Wire:
    """Stands in for a zenoh Publisher: keeps (time, payload) of every put_bytes."""

    def __init__(self, clock):
        self.clock, self.out, self.key = clock, [], "teleop/t/master/command"

    def put_bytes(self, payload):
        self.out.append((self.clock.now(), payload))

    def seqs(self):
        return [decode(p).seq for _, p in self.out]


def run(spec, n=200, stream="command"):
    clock = FakeClock(5.0)
    inj = FaultInjector(spec, clock)
    wire = Wire(clock)
    pub = inj.wrap(wire, stream)
    for k in range(n):
        pub.put(Command(k, clock.now(), (1e-3,), True, 0))
        clock.advance(DT)
    return inj, wire, clock


def test_spec_parsing_units_and_errors():
    s = parse_fault_spec("delay=30ms,drop=0.1,dup=0.05,reorder=0.05,seed=1,stream=command+heartbeat,at=2s,for=0.5")
    assert (s.delay, s.drop, s.dup, s.reorder, s.seed) == (pytest.approx(0.03), 0.1, 0.05, 0.05, 1)
    assert s.streams == ("command", "heartbeat") and s.at == 2.0 and s.duration == 0.5 and not s.on_signal
    assert parse_fault_spec("corrupt=nan,on=usr1").on_signal
    for bad, word in [("dly=3ms", "unknown key 'dly'"), ("drop=1.5", "drop=.1.5."), ("delay=-3ms", "delay"),
                      ("corrupt=zero", "corrupt='zero'"), ("stream=cmd", "stream='cmd'"), ("delay", "key=value"),
                      ("on=usr2", "usr1"), ("seed=x", "seed")]:
        with pytest.raises(ConfigError, match=word):
            parse_fault_spec(bad)


def test_no_fault_passes_everything_at_once_in_order():
    inj, wire, _ = run("")
    assert wire.seqs() == list(range(200)) and inj.counts["passed"] == 200 and inj.pending() == 0


def test_delay_shifts_every_message_by_the_delay():
    inj, wire, clock = run("delay=30ms")
    assert wire.seqs() == list(range(200 - 30))               # the last 30 are still in flight
    t_sent = {decode(p).seq: t for t, p in wire.out}
    assert all(t_sent[k] - (5.0 + k * DT) == pytest.approx(0.03, abs=1e-9) for k in t_sent)
    inj.pump(clock.now() + 1.0)
    assert wire.seqs() == list(range(200)) and inj.counts["delayed"] == 200


def test_drop_rate_and_seed_reproducibility():
    inj, wire, _ = run("drop=0.25,seed=3", n=4000)
    lost = inj.counts["dropped"]
    assert 800 < lost < 1200 and len(wire.out) == 4000 - lost
    inj2, wire2, _ = run("drop=0.25,seed=3", n=4000)
    assert wire2.seqs() == wire.seqs()


def test_duplicates_and_reorders_are_counted_and_happen():
    inj, wire, _ = run("dup=0.1,reorder=0.1,seed=2", n=2000)
    seqs = wire.seqs()
    dups = len(seqs) - len(set(seqs))
    back = sum(1 for a, b in zip(seqs, seqs[1:], strict=False) if b < a)
    assert dups == inj.counts["duplicated"] > 100
    assert back == inj.counts["reordered"] > 100
    assert sorted(set(seqs)) == list(range(2000))              # nothing lost


def test_a_held_message_goes_out_even_without_a_next_one():
    clock = FakeClock(0.0)
    inj = FaultInjector("reorder=1", clock)
    wire = Wire(clock)
    inj.wrap(wire, "command").put(Command(7, 0.0, (0.0,)))
    assert wire.out == [] and inj.pending() == 1
    clock.advance(0.2)
    assert inj.pump() == 1 and wire.seqs() == [7]


def test_fault_window_at_and_for_and_other_streams_untouched():
    clock = FakeClock(0.0)
    inj = FaultInjector("drop=1,at=50ms,for=20ms,stream=command", clock)
    cmd, hb = Wire(clock), Wire(clock)
    pc, ph = inj.wrap(cmd, "command"), inj.wrap(hb, "heartbeat")
    for k in range(100):
        pc.put(Command(k, clock.now(), (0.0,)))
        ph.put(Heartbeat(Side.MASTER, k, clock.now(), SideState.ENGAGED))
        clock.advance(DT)
    assert cmd.seqs() == list(range(50)) + list(range(70, 100)) and len(hb.out) == 100
    assert inj.t_fault == pytest.approx(0.05)


def test_sigusr1_triggers_the_fault():
    clock = FakeClock(0.0)
    inj = FaultInjector("drop=1,on=usr1", clock)
    old = signal.getsignal(signal.SIGUSR1)
    try:
        inj.install_signal()
        wire = Wire(clock)
        pub = inj.wrap(wire, "command")
        for k in range(10):
            pub.put(Command(k, clock.now(), (0.0,)))
            clock.advance(DT)
        assert len(wire.out) == 10 and inj.t_fault is None
        os.kill(os.getpid(), signal.SIGUSR1)
        pub.put(Command(10, clock.now(), (0.0,)))
        assert len(wire.out) == 10 and inj.t_fault == pytest.approx(0.01)
    finally:
        signal.signal(signal.SIGUSR1, old)


EST = tendon_estimate(3, 2, 1.0, 10.0, 0.004, 5.0, 1e-4, 0.0039, Phase.PULL, (1.0, 2.0))


@pytest.mark.parametrize("msg", [Command(1, 0.5, (0.002,), True, 1), EST,
                                 Heartbeat(Side.SLAVE, 4, 2.0, SideState.READY)])
@pytest.mark.parametrize("kind, error", [("nan", "nan"), ("inf", "inf"), ("version", f"version {WIRE_VERSION + 1}")])
def test_byte_level_corruptions_are_refused_by_the_codec(msg, kind, error):
    bad = corrupt_payload(encode(msg), kind)
    assert len(bad) == len(encode(msg))
    with pytest.raises(CodecError, match=error):
        decode(bad)


def test_range_corruption_decodes_to_an_impossible_value():
    assert decode(corrupt_payload(encode(Command(1, 0.5, (0.002,))), "range")).targets == (100.0,)
    assert decode(corrupt_payload(encode(EST), "range")).tendons[0].T_out_hat == 1e4
    raw = corrupt_payload(encode(Command(1, 0.5, (0.002,))), "nan")
    assert math.isnan(struct.unpack_from("<d", raw, len(raw) - 8)[0])       # the last field: the target


def test_corrupt_stream_counts_every_message():
    inj, wire, _ = run("corrupt=version", n=20)
    assert inj.counts["corrupted"] == 20 and all(p[1] == WIRE_VERSION + 1 for _, p in wire.out)
    assert inj.stats()["spec"] == "corrupt=version"


def test_messages_of_a_joint_instrument_are_corrupted_too():
    t = TendonState(5.0, 0.001, 4.0, 1e-4, Phase.PULL)
    cmd = Command(3, 1.0, (0.1, -0.2, 0.3), True, 0)
    est = Estimate(4, 3, 1.0, tuple(AxisState(0.01, 0.1, (t, t)) for _ in range(3)))
    for msg in (cmd, est):
        for kind in ("nan", "inf", "version"):
            with pytest.raises(CodecError):
                decode(corrupt_payload(encode(msg), kind))
    assert decode(corrupt_payload(encode(cmd), "range")).targets == (100.0, -0.2, 0.3)
    bad = decode(corrupt_payload(encode(est), "range"))
    assert bad.axes[0].tendons[0].T_out_hat == 1e4 and bad.axes[0].tendons[1] == t and bad.axes[1:] == est.axes[1:]
