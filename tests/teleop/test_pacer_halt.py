"""A loop of any period ends within MAX_SLEEP of a stop request or of its maximum duration: the pacers sleep and
wait for messages in slices (teleop/timing/clock.py) and the node's loop asks between them (teleop/node.py).

The process-level tests run a node whose period is 11 days (1e-6 Hz, past what a config accepts: the pacer's own
robustness) on the real clock in a child process, and check that SIGTERM, Ctrl-C and the maximum duration end it
within a second."""
from __future__ import annotations

import signal
import subprocess
import sys
import time

import pytest

from teleop.timing.clock import MAX_SLEEP, FakeClock, LockedPacer, Pacer


class _Silent:
    """A message source (count / wait of a LatestSubscriber) on a FakeClock that never receives anything."""

    def __init__(self, clock: FakeClock):
        self.clock, self.count, self.timeouts = clock, 0, []

    def wait(self, count: int, timeout: float) -> bool:
        self.timeouts.append(timeout)
        self.clock.advance(timeout)
        return False


def test_a_long_sleep_is_sliced_and_ends_on_halt():
    c = FakeClock(0.0)
    p = Pacer(c, 1e-6)                              # first deadline 1e6 s away
    now = p.wait(lambda: c.now() >= 0.35)
    assert p.halted and now == pytest.approx(0.4) and c.sleeps == 4
    assert p.ticks == 0                             # no cycle counted


def test_a_short_period_sleeps_once_and_never_asks():
    c = FakeClock(0.0)
    p = Pacer(c, 1000.0)

    def never() -> bool:
        raise AssertionError("halt asked on a period shorter than MAX_SLEEP")
    assert p.wait(never) == pytest.approx(1e-3) and not p.halted and c.sleeps == 1 and p.ticks == 1


def test_without_halt_a_long_period_still_reaches_its_deadline():
    c = FakeClock(0.0)
    p = Pacer(c, 2.0)                               # 0.5 s period: five slices
    assert p.wait() == pytest.approx(0.5) and not p.halted and p.ticks == 1


def test_the_locked_pacer_waits_for_messages_in_slices_and_ends_on_halt():
    c = FakeClock(0.0)
    src = _Silent(c)
    p = LockedPacer(c, 1.0, src)                    # 1 s period, no message ever
    assert p.wait() == pytest.approx(1.0)           # the first cycle: on the grid
    c.advance(0.01)                                 # the step
    now = p.wait(lambda: c.now() >= 1.75)
    assert p.halted and now < 1.75 + MAX_SLEEP + 1e-9 and p.ticks == 1
    assert max(src.timeouts) <= MAX_SLEEP


NODE = """
import logging, sys
from teleop.timing.clock import MonotonicClock
from teleop.wire.messages import Side
from teleop.node import NodeBase
from teleop.recording.measured import Terminated

class Slow(NodeBase):
    side = Side.SLAVE
    log = logging.getLogger("slow")

    @property
    def rate_hz(self):
        return 1e-6

    def step_send(self, now):
        raise AssertionError("a step of an 11-day period")

    def stats(self):
        return {}

node = Slow(heartbeat_hz=50.0)
print("ready", flush=True)
try:
    node.run(MonotonicClock(), max_duration=MAX_DURATION)
except KeyboardInterrupt as e:
    sys.exit(143 if isinstance(e, Terminated) else 130)
"""


def _started(max_duration: float | None) -> tuple[subprocess.Popen, float]:
    proc = subprocess.Popen([sys.executable, "-c", NODE.replace("MAX_DURATION", repr(max_duration))],
                            stdout=subprocess.PIPE, text=True)
    assert proc.stdout is not None and proc.stdout.readline().strip() == "ready"
    return proc, time.monotonic()


@pytest.mark.parametrize("sig, code", [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_a_signal_ends_a_node_asleep_in_a_long_period_within_a_second(sig, code):
    proc, _ = _started(None)
    try:
        time.sleep(0.3)                             # into the loop's sleep
        t0 = time.monotonic()
        proc.send_signal(sig)
        assert proc.wait(10) == code
        assert time.monotonic() - t0 < 1.0
    finally:
        proc.kill()
        proc.wait()


def test_max_duration_ends_a_node_asleep_in_a_long_period_within_a_second():
    proc, t0 = _started(0.3)
    try:
        assert proc.wait(10) == 0
        assert time.monotonic() - t0 < 0.3 + 1.0
    finally:
        proc.kill()
        proc.wait()
