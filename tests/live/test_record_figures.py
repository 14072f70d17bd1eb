"""The recorder's streams figure: one shared time axis, named states, one unit per y axis."""
from __future__ import annotations

import numpy as np
import pytest

from live.record.figures import read_stream, streams_figure, streams_plot
from teleop.recording.figures import pyplot
from teleop.wire.messages import SideState


def write_stream(path, names, rows, units):
    head = "# source: teleop record\n# units: " + ", ".join(f"{k}={v}" for k, v in units.items()) + "\n"
    body = "\n".join(",".join(f"{v:.9g}" for v in r) for r in rows)
    path.write_text(head + ",".join(names) + "\n" + body + "\n", encoding="utf-8")
    return path


@pytest.fixture
def tendon_run(tmp_path):
    """A single tendon: estimates from t = 100 s, commands from 102 s, heartbeats from 99.5 s (recorder clock)."""
    t = np.arange(100.0, 110.0, 0.01)
    est = write_stream(tmp_path / "slave_estimate.csv",
                       ["time", "seq", "effort_hat", "position_hat", "T_in", "x_in", "phase"],
                       [(ti, k, 5.0, 0.004, 10.0, 0.005, 1) for k, ti in enumerate(t)],
                       {"time": "s", "T_in": "N", "x_in": "m"})
    tc = np.arange(102.0, 110.0, 0.01)
    cmd = write_stream(tmp_path / "master_command.csv", ["time", "seq", "targets[0]", "engaged"],
                       [(ti, k, 0.003, 1) for k, ti in enumerate(tc)], {"time": "s"})
    hb = write_stream(tmp_path / "slave_heartbeat.csv", ["time", "side", "seq", "t_sender", "state"],
                      [(99.5 + 0.1 * k, 1, k, 0.1 * k, 4 if k < 30 else 3) for k in range(100)],
                      {"time": "s", "t_sender": "s"})
    return [est, cmd, hb]


def test_every_panel_shares_one_time_axis_from_the_first_message(tendon_run):
    fig = streams_plot(tendon_run)
    try:
        panels = [ax for ax in fig.axes if ax.get_title()]
        assert len(panels) == 3                      # estimate, command, the states
        for ax in fig.axes[1:]:
            assert fig.axes[0].get_shared_x_axes().joined(fig.axes[0], ax)
        starts = {ax.get_title(): min(ln.get_xdata()[0] for ln in ax.get_lines()) for ax in panels}
        # the heartbeat came first (99.5 s): the estimates start 0.5 s later, the commands 2.5 s later
        assert starts["side states (heartbeats)"] == pytest.approx(0.0)
        assert starts["slave_estimate"] == pytest.approx(0.5)
        assert starts["master_command"] == pytest.approx(2.5)
    finally:
        pyplot().close(fig)


def test_states_are_named_and_each_axis_has_one_unit(tendon_run):
    fig = streams_plot(tendon_run)
    try:
        states = next(ax for ax in fig.axes if ax.get_title().startswith("side states"))
        assert [t.get_text() for t in states.get_yticklabels()] == [s.name for s in SideState]
        est = [ax for ax in fig.axes if ax.bbox.bounds == next(a for a in fig.axes if a.get_title() == "slave_estimate")
               .bbox.bounds]
        labels = sorted(ax.get_ylabel() for ax in est)
        assert labels == ["[N]", "[mm]"]             # tensions left, lengths on the right-hand axis
        for ax in est:
            unit = ax.get_ylabel()
            assert all(ln.get_label().endswith(unit) for ln in ax.get_lines())
        mm = next(ax for ax in est if ax.get_ylabel() == "[mm]")
        assert {ln.get_label() for ln in mm.get_lines()} == {"position_hat [mm]", "x_in [mm]"}
        x_in = next(ln for ln in mm.get_lines() if ln.get_label().startswith("x_in"))
        assert x_in.get_ydata()[0] == pytest.approx(5.0)       # 0.005 m shown in mm
    finally:
        pyplot().close(fig)


def test_a_pair_s_effort_and_position_are_torque_and_angle(tmp_path):
    t = np.arange(0.0, 1.0, 0.01)
    est = write_stream(tmp_path / "slave_estimate.csv",
                       ["time", "effort_hat", "position_hat", "axes[0].tendons[0].T_in", "axes[0].tendons[1].T_in"],
                       [(ti, 0.02, 0.1, 3.0, 2.0) for ti in t],
                       {"time": "s", "axes[0].tendons[0].T_in": "N", "axes[0].tendons[1].T_in": "N"})
    s = read_stream(est)
    assert s.units["axes[0].tendons[1].T_in"] == "N"
    fig = streams_plot([est])
    try:
        labels = {ln.get_label() for ax in fig.axes for ln in ax.get_lines()}
        assert {"effort_hat [N m]", "position_hat [deg]"} <= labels
        # at most two units on one panel: the tendon tensions [N] are the third and are left out
        assert len({ax.get_ylabel() for ax in fig.axes}) == 2
    finally:
        pyplot().close(fig)


def test_the_png_is_written(tendon_run, tmp_path):
    out = streams_figure(tendon_run, tmp_path / "streams.png")
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
