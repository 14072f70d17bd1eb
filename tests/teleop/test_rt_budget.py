"""The kernel's real-time budget: reading it, the start-up note and the side's stats."""
from __future__ import annotations

import logging
import math

import pytest

from teleop.timing.realtime import CO_LOCATED_MIN_CPUS, RtBudget, co_located_priority, rt_budget, rt_budget_note


def _kernel(tmp_path, runtime: str, period: str = "1000000"):
    (tmp_path / "sched_rt_runtime_us").write_text(runtime + "\n")
    (tmp_path / "sched_rt_period_us").write_text(period + "\n")
    return str(tmp_path)


def test_the_default_budget_is_950_ms_a_second_with_stops_up_to_50_ms(tmp_path):
    b = rt_budget(_kernel(tmp_path, "950000"))
    assert b == RtBudget(0.95, 1.0)
    assert b.limited and b.per_second == pytest.approx(0.95) and b.longest_stop == pytest.approx(0.05)
    assert b.stats() == {"rt_budget_ms": 950.0, "rt_stop_ms": 50.0}


def test_a_negative_runtime_is_unlimited(tmp_path):
    b = rt_budget(_kernel(tmp_path, "-1"))
    assert b is not None and not b.limited and math.isinf(b.per_second) and b.longest_stop == 0.0
    assert b.stats() == {"rt_budget_ms": "unlimited", "rt_stop_ms": 0.0}
    assert rt_budget_note(b) is None


def test_a_runtime_equal_to_the_period_never_throttles(tmp_path):
    b = rt_budget(_kernel(tmp_path, "500000", "500000"))
    assert b is not None and not b.limited and b.stats()["rt_budget_ms"] == "unlimited"


def test_absent_or_unreadable_files_give_none(tmp_path):
    assert rt_budget(str(tmp_path / "missing")) is None
    assert rt_budget(_kernel(tmp_path, "lots")) is None
    assert rt_budget(_kernel(tmp_path, "950000", "0")) is None
    assert rt_budget_note(None) is None


def test_the_note_names_the_budget_the_stop_and_the_sysctl_line():
    note = rt_budget_note(RtBudget(0.95, 1.0))
    assert note is not None
    assert "950 ms" in note and "up to 50 ms" in note
    assert "sysctl -w kernel.sched_rt_runtime_us=-1" in note and "docs/how-to/real-time.md" in note


def _run_one_cycle(monkeypatch, caplog, scheduling: str, side) -> tuple[list[str], dict]:
    """A node of ``side`` whose loop obtains ``scheduling``, on the real clock for one cycle under a 950 ms
    budget: the log lines naming sched_rt_runtime_us and the loop's stats."""
    import gc

    import teleop.node as node_mod
    from teleop.timing.clock import MonotonicClock

    monkeypatch.setattr(gc, "freeze", lambda: None)                  # the test process keeps its collector
    monkeypatch.setattr(node_mod, "promote_threads", lambda priority: scheduling)
    monkeypatch.setattr(node_mod, "demote_threads", lambda: None)
    monkeypatch.setattr(node_mod, "rt_budget", lambda: RtBudget(0.95, 1.0))
    name = f"test-rt-budget-{side.name.lower()}"

    class Idle(node_mod.NodeBase):
        rate_hz = 1000.0
        log = logging.getLogger(name)

        def step(self, now):
            self.done = True

    Idle.side = side
    node = Idle(10.0)
    with caplog.at_level(logging.INFO, logger=name):
        node.run(MonotonicClock(), max_duration=1.0)
    return [r.getMessage() for r in caplog.records if "sched_rt_runtime_us" in r.getMessage()], node.pacer_stats


def test_a_real_time_loop_logs_the_budget_and_reports_it_in_its_stats(monkeypatch, caplog):
    from teleop.wire.messages import Side
    notes, stats = _run_one_cycle(monkeypatch, caplog, "SCHED_FIFO 20", Side.SLAVE)
    assert len(notes) == 1 and notes[0].startswith("slave loop: the kernel stops real-time threads")
    assert stats["rt_budget_ms"] == 950.0 and stats["rt_stop_ms"] == 50.0


def test_a_loop_without_real_time_priority_logs_no_budget_note(monkeypatch, caplog):
    from teleop.wire.messages import Side
    notes, stats = _run_one_cycle(monkeypatch, caplog, "off", Side.MASTER)
    assert not notes
    assert stats["rt_budget_ms"] == 950.0               # the host's budget is reported all the same


def test_sides_sharing_a_small_machine_with_the_recorder_run_with_normal_scheduling():
    # two SCHED_FIFO loops with their transport threads hold a 2-CPU machine; the kernel then stops them for up to
    # 50 ms so that the recorder runs, and both links go stale past the watchdog
    priority, why = co_located_priority(20, cpus=2)
    assert priority == 0 and why is not None and why.startswith("2 CPUs for master, slave and recorder")
    assert "normal scheduling" in why and "SCHED_FIFO 20" in why and "docs/how-to/real-time.md" in why
    assert co_located_priority(20, cpus=CO_LOCATED_MIN_CPUS) == (20, None)        # room for both loops and the rest
    assert co_located_priority(0, cpus=1) == (0, None)                             # normal scheduling already
    assert co_located_priority(20, cpus=1)[1].startswith("1 CPU for")
