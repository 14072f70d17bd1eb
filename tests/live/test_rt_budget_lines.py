"""The demo summary's line on the kernel's real-time budget and its note on throttling stalls."""
from __future__ import annotations

from live.demo.run import loop_lines, rt_budget_lines


def _pc(worst_lateness_s: float, budget="limited", scheduling="SCHED_FIFO 20", step_max_ms=0.3) -> dict:
    pc = {"ticks": 11000, "rate_hz": 1000.0, "overruns": 3, "overrun_fraction": 0.0003,
          "max_lateness": worst_lateness_s, "step_ms": {"max": step_max_ms}, "scheduling": scheduling}
    if budget == "limited":
        pc.update(rt_budget_ms=950.0, rt_stop_ms=50.0)
    elif budget == "unlimited":
        pc.update(rt_budget_ms="unlimited", rt_stop_ms=0.0)
    return pc


def _summary(master: dict, slave: dict) -> dict:
    return {"master": {"pacer": master}, "slave": {"pacer": slave}}


def test_a_limited_budget_is_named_with_its_longest_stop():
    lines = rt_budget_lines(_summary(_pc(0.0012), _pc(0.0019)))
    assert len(lines) == 1
    assert "950 ms of a CPU per second" in lines[0] and "up to 50 ms" in lines[0]


def test_a_stall_of_40_to_60_ms_under_a_limited_budget_gets_the_throttling_note():
    lines = rt_budget_lines(_summary(_pc(0.0012), _pc(0.051)))
    assert len(lines) == 2
    assert lines[1].startswith("slave stall of 51.0 ms: likely the kernel holding the real-time threads back")
    assert "docs/how-to/real-time.md" in lines[1]


def test_a_long_step_counts_as_a_stall_too():
    lines = rt_budget_lines(_summary(_pc(0.0012, step_max_ms=44.0), _pc(0.0019)))
    assert len(lines) == 2 and lines[1].startswith("master stall of 44.0 ms")


def test_stalls_outside_the_window_get_no_note():
    for worst in (0.0019, 0.035, 0.065, 0.2):
        assert len(rt_budget_lines(_summary(_pc(worst), _pc(worst)))) == 1, worst


def test_an_unlimited_budget_still_notes_a_stall_of_the_fair_servers_length():
    """Linux 6.12 and later also run ordinary tasks for up to 50 ms a second on a CPU that real-time threads
    hold (the fair server), whatever sched_rt_runtime_us says."""
    lines = rt_budget_lines(_summary(_pc(0.0012, budget="unlimited"), _pc(0.053, budget="unlimited")))
    assert lines[0] == "kernel real-time budget: unlimited (sched_rt_runtime_us = -1)"
    assert len(lines) == 2 and lines[1].startswith("slave stall of 53.0 ms") and "fair server" in lines[1]
    assert len(rt_budget_lines(_summary(_pc(0.002, budget="unlimited"), _pc(0.002, budget="unlimited")))) == 1


def test_a_loop_at_normal_scheduling_is_not_throttled():
    lines = rt_budget_lines(_summary(_pc(0.0012), _pc(0.051, scheduling="not permitted (EPERM): normal scheduling")))
    assert len(lines) == 1
    # neither side real-time (the demo's sides on a small machine): the budget holds nothing back, no line
    assert rt_budget_lines(_summary(_pc(0.051, scheduling="off"), _pc(0.051, scheduling="off"))) == []


def test_no_budget_in_the_stats_gives_no_line_and_the_detailed_summary_carries_it():
    assert rt_budget_lines(_summary(_pc(0.051, budget=None), _pc(0.051, budget=None))) == []
    s = _summary(_pc(0.0012), _pc(0.052))
    detailed = loop_lines(s, detailed=True)
    assert any(ln.startswith("kernel real-time budget") for ln in detailed)
    assert any(ln.startswith("slave stall of 52.0 ms") for ln in detailed)
    assert not any("kernel" in ln for ln in loop_lines(s, detailed=False))
