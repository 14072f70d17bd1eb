"""Scripted operator: follows tension targets in order, carries markers, arm impedance, finishes."""
from __future__ import annotations

import pytest

from master.device import HapticDevice, OperatorView
from master.protocols import PROTOCOLS, Segment, build_protocol
from master.simulated import ScriptedOperator
from teleop.errors import ConfigError

DT = 1e-3
STIFFNESS = 2000.0   # toy plant: T_in = STIFFNESS * max(0, position) [N/m]


def drive(op: ScriptedOperator, t_end: float, force=lambda T: 0.0):
    """Close the loop with a toy plant; return (times, positions, tensions, markers)."""
    t, T = 0.0, 0.0
    log = []
    while t < t_end and not op.finished:
        op.watch(T, engaged=True)
        pos = op.read(t).position
        T = STIFFNESS * max(0.0, pos)
        op.set_force(force(T), t)
        log.append((t, pos, T, op.marker))
        t += DT
    return log


def test_is_a_device_and_an_operator_view():
    op = ScriptedOperator(PROTOCOLS["short"])
    assert isinstance(op, HapticDevice) and isinstance(op, OperatorView)


def test_follows_targets_in_order_and_finishes():
    segs = (Segment(20.0, 1), Segment(5.0, 1), Segment(12.0, 2), Segment(0.3, 2))
    op = ScriptedOperator(segs, speed=0.025, dwell=0.3, start_delay=0.0)
    t, T, markers = 0.0, 0.0, []
    extreme: dict[int, list[float]] = {}
    while t < 30.0 and not op.finished:
        op.watch(T, engaged=True)
        T = STIFFNESS * max(0.0, op.read(t).position)
        if op.index >= 0:
            extreme.setdefault(op.index, []).append(T)
        markers.append(op.marker)
        t += DT
    assert op.finished and op.timeouts == 0
    # the tension each segment turned at (the hand has mass: the operator stops its intention early,
    # anticipating the hand's lag, and the hand lands near the target)
    turned = [max(v) if segs[i].target > (extreme[i - 1][-1] if i else 0.0) else min(v)
              for i, v in sorted(extreme.items())]
    assert turned == pytest.approx([20.0, 5.0, 12.0, 0.3], abs=1.5)      # a stiff toy plant: 2000 N/m of hand
    assert markers[0] == 1 and markers[-1] == 2 and markers.index(2) > 0
    assert sorted(set(markers)) == [1, 2]


def test_does_nothing_until_engaged_and_seeing_tension():
    op = ScriptedOperator(PROTOCOLS["short"], start_delay=0.0)
    for k in range(100):
        op.watch(None, engaged=True)           # nothing seen yet
        assert op.read(k * DT).position == 0.0
    for k in range(100, 200):
        op.watch(0.0, engaged=False)           # not engaged
        assert op.read(k * DT).position == 0.0
    op.watch(0.0, engaged=True)
    op.read(0.2)
    assert op.read(0.3).position > 0.0


def test_static_arm_hand_yields_to_the_force_at_once():
    op = ScriptedOperator(PROTOCOLS["short"], arm_stiffness=250.0, static_arm=True)
    op.set_force(-2.0, 0.0)
    assert op.read(0.0).position == pytest.approx(op.intended - 2.0 / 250.0)
    op.set_force(float("nan"), 0.0)            # a NaN force is not rendered
    assert op.read(0.001).position == op.intended


def test_arm_with_mass_yields_smoothly_and_settles_at_force_over_stiffness():
    from master.arm import ArmParameters
    arm = ArmParameters(mass=1.5, damping=15.0, stiffness=250.0, device_mass=0.1, device_damping=0.5,
                        device_friction=0.0)
    op = ScriptedOperator(PROTOCOLS["short"], arm=arm)
    op.read(0.0)
    op.set_force(-2.0, 0.0)
    first = op.read(DT).position
    assert -1e-5 < first < 0.0                 # a mass does not jump: 1 ms of 2 N on 1.6 kg is ~0.6 um
    for k in range(2, 5000):
        p = op.read(k * DT).position
    assert p == pytest.approx(-2.0 / 250.0, rel=1e-3)


def test_resisting_force_makes_the_hand_go_further():
    # the operator closes the loop on the tension it sees, so the hand lag does not change the targets
    op = ScriptedOperator((Segment(10.0, 1),), start_delay=0.0, dwell=0.0)
    drive(op, 10.0, force=lambda T: -0.2 * T)
    assert op.finished
    assert op.intended > 10.0 / STIFFNESS     # intended position beyond the hand position


def test_segment_timeout_moves_on():
    op = ScriptedOperator((Segment(1e6, 1), Segment(5.0, 1)), start_delay=0.0, dwell=0.0, segment_timeout=0.5)
    drive(op, 5.0)
    assert op.finished and op.timeouts == 1


def test_build_protocol():
    assert build_protocol("paper,minor") == PROTOCOLS["paper"] + PROTOCOLS["minor"]
    assert {s.marker for s in PROTOCOLS["paper"]} == {1} and {s.marker for s in PROTOCOLS["minor"]} == {2}
    with pytest.raises(ConfigError, match="unknown protocol 'papr'"):
        build_protocol("papr")
    with pytest.raises(ConfigError):
        build_protocol(" , ")
    with pytest.raises(ConfigError, match="speed"):
        ScriptedOperator(PROTOCOLS["short"], speed=0.0)


def test_the_operator_holds_the_clutch_for_clutch_time_when_the_console_says_align():
    from master.protocols import build_protocol
    from master.simulated import ScriptedOperator
    op = ScriptedOperator(build_protocol("short"), clutch_bit=1, clutch_time=0.05)
    assert op.read(0.0).buttons == 0
    op.on_console("ENGAGED")
    assert op.read(0.001).buttons == 0
    op.on_console("ALIGN")
    held = [op.read(0.002 + 0.001 * k).buttons for k in range(60)]
    assert held[:50] == [0b10] * 50 and set(held[50:]) == {0} and op.clutches == 1


def test_one_operator_over_several_axes_pulls_each_tendon_of_each_pair_and_tags_every_axis():
    from master.device import MultiAxisState
    from master.protocols import joint_marker, paper_protocol
    # two pair axes on a toy plant: + hand motion loads tendon a, - loads tendon b
    op = ScriptedOperator([paper_protocol(0.25, (6.0, 2.0)), paper_protocol(0.25, (4.0,))], start_delay=0.0,
                          dwell=0.05)
    assert op.n_axes == 2
    t, T, peaks, tags = 0.0, [(0.0, 0.0), (0.0, 0.0)], [[0.0, 0.0], [0.0, 0.0]], set()
    while t < 30.0 and not op.finished:
        op.watch(T, engaged=True)
        state = op.read(t)
        assert isinstance(state, MultiAxisState) and len(state.positions) == 2
        T = [(STIFFNESS * max(0.0, p), STIFFNESS * max(0.0, -p)) for p in state.positions]
        for k in range(2):
            peaks[k] = [max(peaks[k][s], T[k][s]) for s in range(2)]
            tags.add((k, joint_marker(op.marker, k)))
        op.set_forces([0.0, 0.0], t)
        t += DT
    assert op.finished and op.timeouts == 0
    assert peaks[0] == pytest.approx([6.0, 6.0], abs=1.0) and peaks[1] == pytest.approx([4.0, 4.0], abs=1.0)
    assert {(0, 1), (0, 2), (1, 1), (1, 2)} <= tags              # tendon a's segments, then b's, on each axis


def test_an_operator_of_several_axes_needs_one_valid_view_per_axis():
    from master.protocols import Segment
    op = ScriptedOperator([(Segment(1.0, 1, 1),), (Segment(1.0, 1),)], start_delay=0.0)
    op.watch([(0.0,), (0.0,)], engaged=True)                     # axis 0 watches tendon b: not in this view
    op.read(0.0)
    assert op.read(0.1).positions == (0.0, 0.0)
    op.watch([(0.0, float("nan")), (0.0,)], engaged=True)        # a non-finite reading: nothing seen
    assert op.read(0.2).positions == (0.0, 0.0)
    with pytest.raises(ConfigError, match="side"):
        ScriptedOperator([(Segment(1.0, 1, 2),)])
    with pytest.raises(ConfigError, match="every axis"):
        ScriptedOperator([PROTOCOLS["short"], ()])


def test_readings_that_arrive_late_and_together_do_not_end_a_pull_early():
    """Estimates held up for 50 ms and then delivered at once (a stalled slave or link) carry the motion
    of those 50 ms: the operator still turns at the target, as with a reading every cycle."""
    turned = {}
    for stall in (False, True):
        op = ScriptedOperator((Segment(20.0, 1), Segment(5.0, 1)), speed=0.025, dwell=0.3, start_delay=0.0)
        t, T, seen, peak = 0.0, 0.0, 0.0, 0.0
        while t < 10.0 and op.index < 1:
            if not stall or (round(t / DT) % 100) >= 50:   # no reading in the first 50 ms of every 100
                seen = T
            op.watch(seen, engaged=True)
            T = STIFFNESS * max(0.0, op.read(t).position)
            peak = max(peak, T)
            t += DT
        turned[stall] = peak
    assert turned[False] == pytest.approx(20.0, abs=1.5)
    assert turned[True] == pytest.approx(turned[False], abs=1.5)



def _dead_zone_plant(pos: float) -> float:
    """Play, a capstan dead zone, free travel, then a load: the read-out stays at 12 N over the first 1 mm of hand
    travel (the hand up to speed), races to 15.3 N over the next 0.8 mm (the tendon stretching, its tip stuck:
    ~100 N/s at 25 mm/s), stays there for 3 mm (the tip swinging free), then rises 500 N/m (the tip on the
    load) [N]."""
    p = max(0.0, pos - 1e-3)
    return 12.0 + 3.3 * min(p, 8e-4) / 8e-4 + 500.0 * max(0.0, p - 3.8e-3)


def _pull(op: ScriptedOperator, plant, T0: float) -> float:
    """Close the loop on ``plant`` until the operator starts its second segment; the peak read-out [N]."""
    t, T, peak = 0.0, T0, T0
    while t < 10.0 and op.index < 1:
        op.watch(T, engaged=True)
        T = plant(op.read(t).position)
        peak = max(peak, T)
        t += DT
    return peak


def test_a_pull_stopped_in_a_dead_zone_short_of_its_target_pulls_on_after_the_dwell():
    """Carried on at the dead zone's rate for the hand's lag, the read-out crosses 20 N at ~15 N and the operator
    stops; looking again after the dwell it finds the read-out more than APPROACH_BAND short of the target and
    pulls on in the same segment, turning at 20 N."""
    op = ScriptedOperator((Segment(20.0, 1), Segment(12.5, 1)), speed=0.025, dwell=0.2, start_delay=0.0)
    peak = _pull(op, _dead_zone_plant, 12.0)
    first = op.axes[0].events
    assert op.index == 1 and op.timeouts == 0
    assert first[0]["T_in"] < 17.0 and first[0]["resumed"]       # stopped by the rate, then went on
    assert not first[-1]["resumed"] and peak == pytest.approx(20.0, abs=1.5)


def test_a_pull_that_settles_within_the_approach_band_goes_on_to_the_next_segment():
    op = ScriptedOperator((Segment(20.0, 1), Segment(5.0, 1)), speed=0.025, dwell=0.2, start_delay=0.0)
    peak = _pull(op, lambda p: 500.0 * max(0.0, p), 0.0)
    assert op.index == 1 and [e["resumed"] for e in op.axes[0].events] == [False]
    assert peak == pytest.approx(20.0, abs=1.0)


def test_a_pull_that_reached_the_band_and_relaxed_at_rest_is_not_pulled_on():
    """Friction that grows with sliding speed (saturating at 2 mm/s) holds the read-out up while the hand moves
    and lets it go at rest: it reaches 20 N, then settles about 2.5 N lower. The reading came within APPROACH_BAND
    of the target, so the operator goes on to the next segment instead of pulling again."""
    last = [0.0]

    def viscous(p: float) -> float:
        v, last[0] = (p - last[0]) / DT, p
        return 500.0 * max(0.0, p) + 2.5 * min(1.0, max(0.0, v) / 2e-3)

    op = ScriptedOperator((Segment(20.0, 1), Segment(5.0, 1)), speed=0.025, dwell=0.2, start_delay=0.0)
    peak = _pull(op, viscous, 0.0)
    assert op.index == 1 and [e["resumed"] for e in op.axes[0].events] == [False]
    assert peak > 19.0 and viscous(last[0]) < 18.5               # reached the band, then settled below it
