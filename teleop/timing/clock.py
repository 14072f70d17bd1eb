"""Clocks and the loop pacer.

Every loop is a ``step()`` that takes the time from an injected :class:`Clock`; ``run()`` only paces
it with a :class:`Pacer`. Tests use :class:`FakeClock`, whose ``sleep_until`` jumps instead of
sleeping, so no test ever waits for real time to pass.
"""
from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Protocol, runtime_checkable

__all__ = ["Clock", "MonotonicClock", "FakeClock", "Pacer", "LockedPacer", "MAX_SLEEP"]

#: [s] the longest a pacer sleeps (or waits for a message) at once: a longer wait is made of such slices, and
#: between two the pacer asks its caller whether to stop (``halt``), so a stop request or a maximum duration
#: ends the wait within this time whatever the period
MAX_SLEEP = 0.1


@runtime_checkable
class Clock(Protocol):
    """A monotonic time source that can also wait."""

    def now(self) -> float:
        """Current time [s], monotonic, arbitrary origin."""
        ...

    def sleep_until(self, t: float) -> None:
        """Return at (or just after) time ``t`` [s]; at once if ``t`` has passed."""
        ...


class MonotonicClock:
    """The process's monotonic clock (:func:`time.monotonic`).

    Parameters
    ----------
    spin : float
        Busy-wait the last ``spin`` seconds before a deadline instead of sleeping, >= 0. ``time.sleep``
        wakes up ~0.1 ms late on Linux; spinning trades CPU for jitter. Default 0 (no spinning).
    """

    def __init__(self, spin: float = 0.0):
        if not (math.isfinite(spin) and spin >= 0):
            raise ValueError(f"MonotonicClock spin must be a finite number of seconds >= 0, got {spin!r}")
        self.spin = spin

    def now(self) -> float:
        return time.monotonic()

    def sleep_until(self, t: float) -> None:
        dt = t - time.monotonic() - self.spin
        if dt > 0:
            time.sleep(dt)
        while time.monotonic() < t:
            pass


class FakeClock:
    """A clock that only moves when told to: :meth:`advance`, :meth:`set` or :meth:`sleep_until`.

    Parameters
    ----------
    start : float
        Initial time [s].

    Attributes
    ----------
    sleeps : int
        Number of ``sleep_until`` calls that moved the clock.
    """

    def __init__(self, start: float = 0.0):
        self._t = float(start)
        self.sleeps = 0

    def now(self) -> float:
        return self._t

    def advance(self, dt: float) -> float:
        """Move forward by ``dt`` [s] >= 0 and return the new time.

        Raises
        ------
        ValueError
            ``dt`` negative or not finite (the clock is monotonic).
        """
        if not (math.isfinite(dt) and dt >= 0):
            raise ValueError(f"FakeClock.advance: dt must be finite and >= 0 s, got {dt!r}")
        self._t += dt
        return self._t

    def set(self, t: float) -> None:
        """Jump to time ``t`` [s] >= now.

        Raises
        ------
        ValueError
            ``t`` earlier than the current time.
        """
        if not t >= self._t:
            raise ValueError(f"FakeClock.set: time must not go back ({t!r} < {self._t!r})")
        self._t = float(t)

    def sleep_until(self, t: float) -> None:
        if t > self._t:
            self._t = float(t)
            self.sleeps += 1


class Pacer:
    """Sleeps a loop to a fixed-rate grid of deadlines and counts the periods it misses.

    Deadlines are ``t0 + k / rate_hz`` with ``t0`` the time of construction (or :meth:`reset`).
    :meth:`wait` sleeps to the next deadline and returns; the loop then runs one cycle. A sleep longer than
    :data:`MAX_SLEEP` is sliced and ends early when ``halt()`` says so (:attr:`halted`; no cycle is counted).

    **Overrun** (a missed period): the cycle did not start in its period, either because :meth:`wait`
    was called after its deadline (the previous cycle's work, or a stall during it, ran past the
    deadline; :meth:`wait` then returns at once) or because the sleep returned one period or more late
    (a stall while sleeping swallowed the next deadline). Either way one overrun is counted, the
    deadlines that passed without a cycle are counted in ``skipped``, and the grid restarts one period
    after the late cycle's start: no catch-up cycles back to back, and the cycle after a stall has a
    whole period, so that *one stall is one overrun* whatever its length or phase. (Catching up on the
    old grid instead left the next cycle only the rest of a period, and a step longer than that rest
    counted the same stall a second time.) An overrun that lost at least one whole period is also a
    *stall* (``stalls``). A wake-up later than its deadline by less than a period whose cycle still
    ends before the next deadline is not an overrun, and the grid stays; ``late_starts`` counts every
    cycle that started more than half a period after its deadline, overrun or not, and
    ``max_lateness`` keeps the worst start.

    Parameters
    ----------
    clock : Clock
    rate_hz : float
        Loop rate [Hz], finite and > 0.

    Raises
    ------
    ValueError
        ``rate_hz`` not a finite positive number.
    """

    def __init__(self, clock: Clock, rate_hz: float):
        if isinstance(rate_hz, bool) or not (isinstance(rate_hz, (int, float)) and math.isfinite(rate_hz)
                                             and rate_hz > 0):
            raise ValueError(f"Pacer rate_hz must be a finite number > 0, got {rate_hz!r}")
        self.clock = clock
        self.rate_hz = float(rate_hz)
        self.period = 1.0 / self.rate_hz
        self.reset()

    def reset(self) -> None:
        """Start a new grid at the current time and zero the statistics."""
        self._next = self.clock.now() + self.period
        self.ticks = 0             # wait() calls: cycles run
        self.overruns = 0          # cycles that missed their period (class docstring)
        self.stalls = 0            # overruns that lost one whole period or more
        self.skipped = 0           # deadlines that passed without a cycle
        self.late_starts = 0       # cycles started more than half a period after their deadline
        self.max_lateness = 0.0    # [s] worst (return time - deadline), overruns and oversleeps alike
        self.last_lateness = 0.0   # [s]
        self.last_overrun = False  # whether the last wait() came after its deadline
        self.halted = False        # whether the last wait() ended early on its halt() (no cycle to run)

    @property
    def next_deadline(self) -> float:
        """The deadline the next :meth:`wait` sleeps to [s]."""
        return self._next

    @property
    def next_wake(self) -> float:
        """When the next :meth:`wait` is expected to return [s]: the next deadline (the loop's helper
        threads work until then, :data:`teleop.timing.realtime.IDLE`)."""
        return self._next

    def _count(self, lateness: float, missed: bool, behind: float | None = None) -> None:
        """Book one cycle that started ``lateness`` [s] after its deadline; ``missed``: an overrun;
        ``behind`` [s]: the time from which whole lost periods are counted (default ``lateness``)."""
        P = self.period
        self.ticks += 1
        self.last_overrun = missed
        if missed:
            self.overruns += 1
            lost = math.floor(max(lateness if behind is None else behind, 0.0) / P)
            if lost > 0:
                self.skipped += lost
                self.stalls += 1
        if lateness > 0.5 * P:
            self.late_starts += 1
        self.last_lateness = lateness
        if lateness > self.max_lateness:
            self.max_lateness = lateness

    def _sleep_until(self, t: float, halt: Callable[[], bool] | None) -> bool:
        """Sleep until ``t`` [s] in slices of at most :data:`MAX_SLEEP`, asking ``halt()`` after each slice
        that leaves time to sleep; False (and :attr:`halted` set) when it said to stop."""
        while True:
            now = self.clock.now()
            if t - now <= MAX_SLEEP:
                self.clock.sleep_until(t)
                return True
            self.clock.sleep_until(now + MAX_SLEEP)
            if halt is not None and halt():
                self.halted = True
                return False

    def wait(self, halt: Callable[[], bool] | None = None) -> float:
        """Sleep until the next deadline (or not at all if it has passed) and return the time [s].

        ``halt``: asked between the slices of a sleep longer than :data:`MAX_SLEEP`; when it returns True the
        wait returns at once with :attr:`halted` set, counting no cycle."""
        self.halted = False
        deadline = self._next
        now = self.clock.now()
        missed = now > deadline
        if not missed:
            if not self._sleep_until(deadline, halt):
                return self.clock.now()
            now = self.clock.now()
            missed = now - deadline >= self.period
        lateness = max(0.0, now - deadline)
        self._next = now + self.period if missed else deadline + self.period
        self._count(lateness, missed)
        return now

    def stats(self) -> dict[str, float]:
        """Counters for logs and summaries.

        Returns
        -------
        dict
            ``rate_hz``, ``period`` [s], ``ticks``, ``overruns``, ``stalls``, ``skipped``,
            ``late_starts``, ``max_lateness`` [s], ``overrun_fraction`` (overruns / ticks, 0 before
            the first tick); the definitions in the class docstring.
        """
        return {
            "rate_hz": self.rate_hz,
            "period": self.period,
            "ticks": self.ticks,
            "overruns": self.overruns,
            "stalls": self.stalls,
            "skipped": self.skipped,
            "late_starts": self.late_starts,
            "max_lateness": self.max_lateness,
            "overrun_fraction": self.overruns / self.ticks if self.ticks else 0.0,
        }


class LockedPacer(Pacer):
    """A :class:`Pacer` whose cycles start when a new message arrives: a slave locked to its master's commands.

    Paced by the grid alone, a slave looks at a command up to one period after it arrived (the two
    1 kHz loops are not in phase) and the round trip carries that wait. Here :meth:`wait` returns as
    soon as ``source`` has received a message since the previous cycle started, but never earlier
    than ``min_gap`` periods after it (a burst of late commands does not run cycles back to back).
    Without a message the deadline starts the cycle as in :class:`Pacer`: ``guard`` periods later
    than one period after a cycle a message started (its next message is due one period later, so
    the jitter of its arrival does not let the deadline come first), on the plain grid otherwise.

    An *overrun* is a cycle that missed its period: :meth:`wait` called more than one period after
    the previous cycle started (the cycle, step and everything else until the next wait, took longer
    than a period: the same budget a grid cycle that woke on time has), or a cycle that started one
    period or more after its deadline (a stall while waiting: that period's message waited). One
    overrun per stall; the periods lost since the previous cycle's period ended are ``skipped``, and
    an overrun that lost one or more is a *stall* (``stalls``). The lateness of a cycle is its start
    less its deadline (0 for a cycle a message started in time); ``late_starts`` as in :class:`Pacer`.

    Parameters
    ----------
    clock : Clock
    rate_hz : float
        The rate of the messages and of the loop [Hz].
    source : object with ``count`` (messages received) and ``wait(count, timeout)`` (block until
        ``count`` messages or ``timeout`` [s] of real time; True if reached), e.g. a
        :class:`teleop.session.transport.LatestSubscriber`.
    guard, min_gap : float
        In periods, > 0 and in (0, 1].

    Attributes
    ----------
    locked : int
        Cycles started by a message (the others by their deadline).
    """

    def __init__(self, clock: Clock, rate_hz: float, source, *, guard: float = 0.25, min_gap: float = 0.5):
        if not (guard > 0 and 0 < min_gap <= 1):
            raise ValueError(f"LockedPacer: guard must be > 0 and min_gap in (0, 1], got {guard!r}, {min_gap!r}")
        self.source = source
        self.guard, self.min_gap = float(guard), float(min_gap)
        super().__init__(clock, rate_hz)

    def reset(self) -> None:
        super().reset()
        self.locked = 0
        self._start: float | None = None
        self._seen = int(self.source.count)

    def wait(self, halt: Callable[[], bool] | None = None) -> float:
        if self._start is None:                       # the first cycle: on the grid
            now = super().wait(halt)
            if not self.halted:
                self._start, self._seen = now, int(self.source.count)
            return now
        self.halted = False
        P = self.period
        now = self.clock.now()
        ran_over = now > self._start + P
        earliest = self._start + self.min_gap * P
        if now < earliest and not self._sleep_until(earliest, halt):
            return self.clock.now()
        deadline = self._next
        while True:                                   # the message, or the deadline, in slices of MAX_SLEEP
            left = deadline - self.clock.now()
            arrived = self.source.wait(self._seen + 1, max(0.0, min(left, MAX_SLEEP)))
            if arrived or left <= MAX_SLEEP:
                break
            if halt is not None and halt():
                self.halted = True
                return self.clock.now()
        now = self.clock.now()
        lateness = max(0.0, now - deadline)
        # a cycle that ran longer than a period, or one that started a period or more after its
        # deadline (a stall while waiting: the messages of that period waited): one overrun, and the
        # periods lost are counted from the previous cycle's end of period
        missed = ran_over or lateness >= P
        if arrived:
            self.locked += 1
            self._next = now + (1.0 + self.guard) * P
        else:
            self._next = max(deadline + P, now + self.min_gap * P)
        gap = now - self._start - P
        self._start = now
        self._seen = int(self.source.count)
        self._count(lateness, missed, behind=gap)
        return now

    @property
    def next_wake(self) -> float:
        """When the next message is due [s]: one period after the previous cycle started (the deadline
        if earlier). The deadline itself is later (``1 + guard`` periods) and a helper thread working
        until then would hold up the cycle the next message starts."""
        return self._next if self._start is None else min(self._next, self._start + self.period)

    def stats(self) -> dict[str, float]:
        """:meth:`Pacer.stats` and ``locked`` (cycles a message started)."""
        return {**super().stats(), "locked": self.locked}
