"""The live view's layout (:mod:`teleop.rerun.logger`): the sheath route as a 3D polyline, the fixed tension
colour scale along it, the plots' fixed ranges and the blueprint of the views.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["TENSION_RANGE", "ELONGATION_RANGE", "WALL", "JOINT_SPACING", "JointView", "joint_views", "route_points",
           "route_segments", "tension_colors", "blueprint", "arm_groups"]

#: Height [m] between two joints' tendon pairs in the 3D view (tendon b sits a tenth of it above a).
JOINT_SPACING = 0.12


@dataclass(frozen=True)
class JointView:
    """What the view draws of one joint: its name, the routes of tendons a and b as ``(length, radius)``
    pairs [m] (radius inf: straight), and the fixed ranges of its torque [N m] and angle [rad] plots."""

    name: str
    route_a: tuple[tuple[float, float], ...]
    route_b: tuple[tuple[float, float], ...]
    torque_range: tuple[float, float]
    angle_range: tuple[float, float]


def joint_views(cfg: Any) -> tuple[JointView, ...]:
    """The :class:`JointView` of every joint of ``cfg.instrument`` (empty for a single tendon); the torque
    range is +-1.2 r ``calibration.target_tension``, the angle range the joint's limits."""
    def runs(t: Any) -> tuple[tuple[float, float], ...]:
        return tuple((float(r.length), float(r.radius) if r.radius is not None else float("inf")) for r in t.runs)

    out = []
    for j in cfg.instrument.joints:
        tmax = 1.2 * float(j.pulley_radius) * float(cfg.calibration.target_tension)
        out.append(JointView(j.name, runs(j.tendons.a), runs(j.tendons.b), (-tmax, tmax),
                             (float(j.limits[0]), float(j.limits[1]))))
    return tuple(out)

#: Fixed ranges of the plots (the y axes do not rescale every frame): tension [N], elongation [m].
TENSION_RANGE, ELONGATION_RANGE = (0.0, 25.0), (0.0, 2.0e-3)
WALL = "wall"          # the timeline the time panel shows (monotonic clock: slave.rrd and master.rrd line up)


def route_points(runs, n_per_arc: int = 24) -> np.ndarray:
    """The sheath route as a planar polyline, shape (n, 3) [m], from proximal (origin, heading +x) to
    distal: straight runs go ahead, arcs turn left by ``length / radius``.

    runs : sequence of objects with ``length`` [m] and ``radius`` [m] (inf or None = straight), or
    (length, radius) pairs.
    """
    pts = [np.zeros(3)]
    heading = 0.0
    for r in runs:
        length, radius = (r if isinstance(r, (tuple, list)) else (r.length, getattr(r, "radius", None)))
        p0 = pts[-1]
        if radius is None or not np.isfinite(radius):
            pts.append(p0 + length * np.array([np.cos(heading), np.sin(heading), 0.0]))
            continue
        turn = length / radius
        centre = p0 + radius * np.array([-np.sin(heading), np.cos(heading), 0.0])
        for a in np.linspace(0.0, turn, n_per_arc + 1)[1:]:
            h = heading + a
            pts.append(centre + radius * np.array([np.sin(h), -np.cos(h), 0.0]))
        heading += turn
    return np.array(pts)


def route_segments(route: np.ndarray, route_s: np.ndarray, s: np.ndarray) -> np.ndarray:
    """The polyline ``route`` (shape (m, 3) [m], arc length ``route_s`` (m,)) cut at the profile's nodes
    ``s`` (n,) [m, proximal to distal, scaled onto the route's length]: segments, shape (n - 1, 2, 3)."""
    u = s / s[-1] * route_s[-1]
    pts = np.stack([np.interp(u, route_s, route[:, k]) for k in range(3)], axis=1)
    return np.stack([pts[:-1], pts[1:]], axis=1)


def tension_colors(T: np.ndarray, vmax: float = TENSION_RANGE[1]) -> np.ndarray:
    """RGBA colours, shape (n, 4) uint8, of tensions ``T`` [N] on a fixed scale 0..``vmax`` (blue -> red)."""
    u = np.clip(np.asarray(T, dtype=float) / vmax, 0.0, 1.0)
    # blue (low) -> yellow -> red (high)
    r = np.clip(2 * u, 0, 1)
    g = np.clip(1.6 * (1 - np.abs(2 * u - 1)), 0, 1) * 0.85 + 0.15 * (u < 0.5)
    b = np.clip(1 - 2 * u, 0, 1)
    return (np.stack([r, g, b, np.ones_like(u)], axis=1) * 255).astype(np.uint8)


def blueprint(joints: Sequence[JointView] = ()) -> object:
    """The view sent at the start of a recording: the 3D sheath and the profile bar chart beside the
    fixed-range tension and elongation plots, the master's series and the phase/console/experiment lanes;
    for a joint instrument (``joints``) the tendon pairs in 3D beside each joint's torque and angle; when
    every joint's name carries an arm (``<arm>/<joint>``, both arms of a bimanual platform) one column
    per arm: that hand's rendered force, then its joints' torque and angle."""
    import rerun.blueprint as rrb

    arms = arm_groups(joints)
    if arms:
        return _bimanual_blueprint(rrb, joints, arms)
    if joints:
        return _joint_blueprint(rrb, joints)
    fixed_T = rrb.ScalarAxis(range=TENSION_RANGE, zoom_lock=False)
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.Spatial3DView(origin="sheath", name="Sheath route coloured by tension (0-25 N, blue -> red)"),
                rrb.BarChartView(origin="profile", name="Tension along the sheath: T [N] vs s [m]",
                                 plot_legend=rrb.PlotLegend(corner=rrb.Corner2D.RightTop)),
                row_shares=[3, 2],
            ),
            rrb.Vertical(
                rrb.TimeSeriesView(origin="tension", name="Tension [N]", axis_y=fixed_T),
                rrb.Tabs(rrb.TimeSeriesView(origin="elongation", name="Elongation [m]",
                                            axis_y=rrb.ScalarAxis(range=ELONGATION_RANGE, zoom_lock=False)),
                         rrb.TimeSeriesView(origin="master", name="Master: command, force, round trip"),
                         rrb.TimeSeriesView(origin="displacement", name="Displacement [m]"),
                         rrb.TimeSeriesView(origin="signals", name="Other signals")),
                rrb.StateTimelineView(origin="/", contents=["/phase", "/master/console", "/experiment"],
                                      name="Phase, console, experiment"),
                row_shares=[4, 4, 2],
            ),
            column_shares=[1, 1],
        ),
        rrb.TimePanel(timeline=WALL),
        auto_views=False,
    )


def _joint_eye(rrb: Any, joints: Sequence[JointView]) -> object:
    """A camera that sees every pair: from the front, above and a little behind the routes' centre."""
    pts = np.vstack([route_points(j.route_a) - np.array([0.0, 0.0, k * JOINT_SPACING]) for k, j in enumerate(joints)])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    centre, extent = 0.5 * (lo + hi), float(np.max(hi - lo))
    return rrb.EyeControls3D(position=centre + extent * np.array([0.0, -1.4, 1.6]), look_target=centre,
                             eye_up=(0.0, 0.0, 1.0))


def _joint_row(rrb: Any, j: JointView) -> object:
    """One joint's torque [N m] and angle [rad] plots side by side, on the joint's fixed ranges."""
    return rrb.Horizontal(
        rrb.TimeSeriesView(origin=f"joints/{j.name}/torque", name=f"{j.name}: torque [N m]",
                           axis_y=rrb.ScalarAxis(range=j.torque_range, zoom_lock=False)),
        rrb.TimeSeriesView(origin=f"joints/{j.name}/angle", name=f"{j.name}: angle [rad]",
                           axis_y=rrb.ScalarAxis(range=j.angle_range, zoom_lock=False)))


def _pairs_view(rrb: Any, joints: Sequence[JointView]) -> object:
    return rrb.Spatial3DView(origin="instrument", eye_controls=_joint_eye(rrb, joints),
                             name="Tendon pairs coloured by tension (0-25 N, blue -> red), one pair per joint")


def _console_lanes(rrb: Any) -> object:
    """The console state and the experiment marker as lanes."""
    return rrb.StateTimelineView(origin="/", contents=["/master/console", "/experiment"], name="Console, experiment")


def _joint_blueprint(rrb: Any, joints: Sequence[JointView]) -> object:
    rows = [_joint_row(rrb, j) for j in joints]
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                _pairs_view(rrb, joints),
                _console_lanes(rrb),
                row_shares=[5, 1],
            ),
            rrb.Vertical(*rows, rrb.Tabs(rrb.TimeSeriesView(origin="master", name="Master: commands, forces, round trip"),
                                         rrb.TimeSeriesView(origin="signals", name="Other signals")),
                         row_shares=[3] * len(rows) + [2]),
            column_shares=[2, 3],
        ),
        rrb.TimePanel(timeline=WALL),
        auto_views=False,
    )


def arm_groups(joints: Sequence[JointView]) -> dict[str, tuple[str, ...]]:
    """The joints' names grouped by arm, arms in order of first appearance: ``{arm: (joint, ...)}`` for names
    ``<arm>/<joint>``; empty when ``joints`` is empty or any name carries no arm (a single-arm instrument)."""
    out: dict[str, tuple[str, ...]] = {}
    for j in joints:
        arm, sep, joint = j.name.partition("/")
        if not sep:
            return {}
        out[arm] = (*out.get(arm, ()), joint)
    return out


def _hand_column(rrb: Any, arm: str, names: Sequence[str], joints: Sequence[JointView]) -> object:
    """One arm's column: the rendered force [N] of its hand on every joint axis (``master/<arm>/<joint>/force``,
    ``master/<arm>/force`` for a one-axis hand), a tab with the hand's command and mapped force, then each
    joint's torque and angle."""
    forces = [f"/master/{arm}/force", *(f"/master/{arm}/{n}/force" for n in names)]
    hand = rrb.Tabs(rrb.TimeSeriesView(origin=f"master/{arm}", contents=forces, name=f"{arm} hand: rendered force [N]"),
                    rrb.TimeSeriesView(origin=f"master/{arm}", name=f"{arm} hand: command [m], rendered and mapped force [N]"))
    rows = [_joint_row(rrb, j) for j in joints if j.name.partition("/")[0] == arm]
    return rrb.Vertical(hand, *rows, row_shares=[4] + [3] * len(rows), name=f"{arm} arm")


def _bimanual_blueprint(rrb: Any, joints: Sequence[JointView], arms: dict[str, tuple[str, ...]]) -> object:
    """Both arms: the tendon pairs in 3D with the console lanes and the round trip, beside one column per arm."""
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                _pairs_view(rrb, joints),
                _console_lanes(rrb),
                rrb.Tabs(rrb.TimeSeriesView(origin="master/rtt", name="Round trip [s]"),
                         rrb.TimeSeriesView(origin="signals", name="Other signals")),
                row_shares=[5, 1, 2],
            ),
            *(_hand_column(rrb, arm, names, joints) for arm, names in arms.items()),
            column_shares=[2] + [2] * len(arms),
        ),
        rrb.TimePanel(timeline=WALL),
        auto_views=False,
    )
