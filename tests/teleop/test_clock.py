"""FakeClock and Pacer: deadlines, overrun and skip counting, lateness, all on a fake clock."""
from __future__ import annotations

import math

import numpy as np
import pytest

from teleop.timing.clock import Clock, FakeClock, LockedPacer, MonotonicClock, Pacer


def test_clocks_satisfy_the_protocol():
    assert isinstance(FakeClock(), Clock)
    assert isinstance(MonotonicClock(), Clock)


def test_monotonic_clock_sleep_until_past_returns_at_once_and_never_goes_back():
    c = MonotonicClock()
    t0 = c.now()
    c.sleep_until(t0 - 1.0)
    assert c.now() >= t0
    with pytest.raises(ValueError):
        MonotonicClock(spin=-1e-3)


def test_fake_clock_moves_only_when_told():
    c = FakeClock(5.0)
    assert c.now() == 5.0 == c.now()
    assert c.advance(0.25) == 5.25
    c.sleep_until(6.0)
    assert c.now() == 6.0 and c.sleeps == 1
    c.sleep_until(1.0)                     # in the past: no move
    assert c.now() == 6.0 and c.sleeps == 1
    c.set(7.0)
    assert c.now() == 7.0
    with pytest.raises(ValueError):
        c.advance(-1e-9)
    with pytest.raises(ValueError):
        c.advance(math.nan)
    with pytest.raises(ValueError):
        c.set(6.5)


def test_pacer_sleeps_to_a_fixed_grid_when_on_time():
    c = FakeClock(10.0)
    p = Pacer(c, 100.0)
    times = []
    for _ in range(5):
        c.advance(0.004)                   # the step takes 4 ms of a 10 ms period
        times.append(p.wait())
    assert times == pytest.approx([10.01, 10.02, 10.03, 10.04, 10.05])
    s = p.stats()
    assert s["ticks"] == 5 and s["overruns"] == 0 and s["skipped"] == 0
    assert s["max_lateness"] == 0.0 and s["period"] == pytest.approx(0.01)


def test_pacer_counts_an_overrun_and_restarts_the_grid_a_period_after_the_late_start():
    c = FakeClock(0.0)
    p = Pacer(c, 100.0)                    # deadlines 0.01, 0.02, ...
    c.advance(0.013)                       # overran the first period by 3 ms
    assert p.wait() == pytest.approx(0.013)  # no sleep
    assert p.overruns == 1 and p.skipped == 0 and p.stalls == 0 and p.last_overrun
    assert p.max_lateness == pytest.approx(0.003)
    assert p.next_deadline == pytest.approx(0.023)  # a whole period for the late cycle's successor
    c.advance(0.001)
    assert p.wait() == pytest.approx(0.023)
    assert p.overruns == 1 and p.last_lateness == 0.0 and not p.last_overrun


def test_pacer_skips_whole_missed_periods_instead_of_bursting():
    c = FakeClock(0.0)
    p = Pacer(c, 1000.0)                   # 1 ms period, first deadline 0.001
    c.advance(0.0045)                      # 3.5 ms late: deadlines 0.002, 0.003, 0.004 are gone
    p.wait()
    assert p.overruns == 1 and p.skipped == 3 and p.stalls == 1 and p.late_starts == 1
    assert p.next_deadline == pytest.approx(0.0055)
    assert p.max_lateness == pytest.approx(0.0035)
    c.advance(0.0002)
    assert p.wait() == pytest.approx(0.0055)
    s = p.stats()
    assert s["ticks"] == 2 and s["overrun_fraction"] == 0.5 and s["stalls"] == 1 and s["late_starts"] == 1


def test_a_stall_ending_just_before_a_deadline_is_counted_once():
    # the wait comes 6.99 periods late: on the old grid the next deadline was 0.01 periods away, and the
    # next (ordinary) step overran it: the same stall counted twice
    c = FakeClock(0.0)
    p = Pacer(c, 1000.0)
    c.advance(0.001 + 0.00699)
    p.wait()
    for _ in range(5):
        c.advance(1.5e-4)                  # ordinary steps
        p.wait()
    assert p.overruns == 1 and p.stalls == 1 and p.skipped == 6 and p.ticks == 6


class _StallingClock(FakeClock):
    """A FakeClock whose next sleep returns ``extra`` seconds late (the process stalled while asleep)."""

    def __init__(self):
        super().__init__(0.0)
        self.extra = 0.0

    def sleep_until(self, t):
        super().sleep_until(t + self.extra)
        self.extra = 0.0


@pytest.mark.parametrize("oversleep, overrun, late", [(2.5e-3, True, True), (0.7e-3, False, True),
                                                     (0.9e-3, True, True), (0.2e-3, False, False)])
def test_a_stall_while_sleeping_is_one_overrun_when_the_period_is_lost(oversleep, overrun, late):
    c = _StallingClock()
    p = Pacer(c, 1000.0)
    starts = []
    for k in range(6):
        c.extra = oversleep if k == 2 else 0.0
        starts.append(p.wait())
        c.advance(1.5e-4)                  # the step
    assert p.overruns == int(overrun) and p.late_starts == int(late)
    assert p.stalls == int(oversleep >= 1e-3) and p.skipped == int(oversleep // 1e-3)
    assert np.diff(starts)[3:] == pytest.approx([1e-3] * 2)   # after the late cycle(s), one per period again
    assert p.max_lateness == pytest.approx(oversleep)


def test_pacer_max_lateness_keeps_the_worst():
    c = FakeClock(0.0)
    p = Pacer(c, 10.0)
    c.advance(0.15)
    p.wait()                               # 50 ms late; next deadline 0.25
    c.advance(0.16)
    p.wait()                               # deadline 0.25, now 0.31: 60 ms late
    c.advance(0.001)
    p.wait()
    assert p.overruns == 2
    assert p.max_lateness == pytest.approx(0.06)


def test_pacer_reset_starts_a_new_grid_and_zeroes_stats():
    c = FakeClock(0.0)
    p = Pacer(c, 10.0)
    c.advance(1.0)
    p.wait()
    p.reset()
    assert p.stats()["overruns"] == 0 and p.next_deadline == pytest.approx(1.1)


@pytest.mark.parametrize("rate", [0, -5.0, math.inf, math.nan, True, "100"])
def test_pacer_rejects_bad_rates(rate):
    with pytest.raises(ValueError, match="rate_hz"):
        Pacer(FakeClock(), rate)


class _Arrivals:
    """Messages arriving at given times on a FakeClock, with the count/wait of a LatestSubscriber."""

    def __init__(self, clock, times):
        self.clock, self.times, self.count = clock, list(times), 0

    def _deliver(self):
        while self.times and self.times[0] <= self.clock.now():
            self.times.pop(0)
            self.count += 1

    def wait(self, count, timeout):
        self._deliver()
        if self.count >= count:
            return True
        end = self.clock.now() + timeout
        if self.times and self.times[0] <= end:
            self.clock.set(self.times[0])
            self._deliver()
            return self.count >= count
        self.clock.set(end)
        return False


def test_locked_pacer_starts_each_cycle_as_its_message_arrives():
    c = FakeClock(0.0)
    src = _Arrivals(c, [0.0013 + 1e-3 * k for k in range(20)])   # 0.3 ms after the slave's grid
    p = LockedPacer(c, 1000.0, src)
    assert p.wait() == pytest.approx(0.001)                       # the first cycle: on the grid
    starts = []
    for _ in range(20):
        starts.append(p.wait())
        c.advance(2e-4)                                           # the step
    # the first message came before half a period had passed: it starts the cycle then; locked from there on
    assert starts == pytest.approx([0.0015] + [0.0023 + 1e-3 * k for k in range(19)])
    assert p.locked == 20 and p.overruns == 0 and p.max_lateness == 0.0


def test_locked_pacer_without_messages_keeps_the_grid_and_counts_overruns():
    c = FakeClock(0.0)
    p = LockedPacer(c, 1000.0, _Arrivals(c, []))
    starts = [p.wait() for _ in range(4)]
    assert starts == pytest.approx([0.001, 0.002, 0.003, 0.004]) and p.locked == 0
    c.advance(1.5e-3)                                             # a cycle longer than a period
    p.wait()
    assert p.overruns == 1 and p.last_overrun and p.stats()["locked"] == 0


def test_locked_pacer_never_runs_two_cycles_closer_than_half_a_period():
    c = FakeClock(0.0)
    src = _Arrivals(c, [0.0021, 0.00215, 0.0022, 0.0032])         # a burst of three, then one on time
    p = LockedPacer(c, 1000.0, src)
    starts = [p.wait() for _ in range(4)]
    # grid (no message yet), grid, the burst half a period after the previous start, the next message
    assert starts == pytest.approx([0.001, 0.002, 0.0025, 0.0032]) and p.locked == 2
    with pytest.raises(ValueError):
        LockedPacer(c, 1000.0, src, min_gap=0.0)


@pytest.mark.parametrize("stall", [0.040, 0.220])
def test_one_long_stall_is_one_overrun_and_both_pacers_resynchronise_without_a_burst(stall):
    # a 40 ms stall (the process stopped) counts one missed deadline, and the next cycles are on time:
    # no catch-up cycles run back to back, none of them counted late
    c = FakeClock(0.0)
    p = Pacer(c, 1000.0)
    p.wait()
    c.advance(stall)
    p.wait()
    starts = []
    for _ in range(5):
        c.advance(2e-4)
        starts.append(p.wait())
    assert p.overruns == 1 and p.stalls == 1 and p.skipped == round(stall * 1e3) - 1
    assert np.diff(starts) == pytest.approx([1e-3] * 4)
    c = FakeClock(0.0)
    src = _Arrivals(c, [0.0013 + 1e-3 * k for k in range(300)])  # the master kept sending during the stall
    q = LockedPacer(c, 1000.0, src)
    for _ in range(5):
        q.wait()
        c.advance(2e-4)
    c.advance(stall)
    resumed = q.wait()
    starts = [resumed]
    for _ in range(5):
        c.advance(2e-4)
        starts.append(q.wait())
    assert q.overruns == 1 and q.skipped == round(stall * 1e3) - 1 and q.stalls == 1
    gaps = np.diff(starts)                  # the next message starts the next cycle (never before half a period),
    assert gaps[0] >= 0.5e-3 and gaps[1:] == pytest.approx([1e-3] * 4)   # then one per period


def test_locked_pacer_counts_a_stall_while_waiting_once():
    # the slave stalls while waiting: the messages kept arriving, the cycle starts 5 periods late
    c = _StallingClock()
    src = _Arrivals(c, [0.0013 + 1e-3 * k for k in range(40)])
    q = LockedPacer(c, 1000.0, src)
    for _ in range(5):
        q.wait()
        c.advance(2e-4)
    before = q.ticks
    c.advance(5e-3)                          # stalled in the wait (a message arrived meanwhile)
    q.wait()
    for _ in range(5):
        c.advance(2e-4)
        q.wait()
    assert q.ticks == before + 6 and q.overruns == 1 and q.stalls == 1 and q.skipped >= 4


def test_the_idle_window_ends_when_the_next_message_is_due_not_at_the_locked_deadline():
    c = FakeClock(0.0)
    p = Pacer(c, 1000.0)
    assert p.next_wake == p.next_deadline == pytest.approx(0.001)
    src = _Arrivals(c, [0.0013 + 1e-3 * k for k in range(5)])
    q = LockedPacer(c, 1000.0, src)
    q.wait()                                                      # on the grid at 1 ms
    start = q.wait()                                              # the message at 1.5 ms (half a period)
    assert q.next_deadline == pytest.approx(start + 1.25e-3)      # the deadline if no message comes
    assert q.next_wake == pytest.approx(start + 1e-3)             # but the next message is due a period later
