"""The live view's layout (:mod:`teleop.rerun.logger`): the sheath route as a 3D polyline, the fixed tension
colour scale along it, the plots' fixed ranges and the blueprint of the views.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["TENSION_RANGE", "ELONGATION_RANGE", "SESSION", "JOINT_SPACING", "JointView", "joint_views", "route_points",
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
#: The timeline the time panel shows: the session's time [s] since the run began (teleop.rerun.logger: timelines).
SESSION = "session"


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
    """The view of the session, sent by every mode (save, spawn, serve): the slave's columns beside the master's.

    The slave: the 3D sheath (or the tendon pairs of a joint instrument, one per joint) and the profile bar chart,
    the tension [N] (or each joint's torque [N m] and angle [rad]), elongation [m], displacement [m] and the phase
    lane. The master: the hand's rendered and mapped force [N], its command [m], the round trip [s] and the lane of
    the operator's state at the console (deadman, clutch, engaged) and the experiment. When every joint's name
    carries an arm (``<arm>/<joint>``, a bimanual platform) one column per arm. Every plot holds one unit, named
    in its title; the time axis is the ``session`` timeline [s]."""
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
                rrb.Spatial3DView(origin="sheath",
                                  name="Slave: sheath route coloured by tension (0-25 N, blue -> red)"),
                rrb.BarChartView(origin="profile", name="Slave: tension along the sheath, T [N] vs s [m]",
                                 plot_legend=rrb.PlotLegend(corner=rrb.Corner2D.RightTop)),
                row_shares=[3, 2], name="Slave",
            ),
            rrb.Vertical(
                rrb.TimeSeriesView(origin="tension", name="Slave: tension [N]", axis_y=fixed_T),
                rrb.Tabs(rrb.TimeSeriesView(origin="elongation", name="Slave: elongation [m]",
                                            axis_y=rrb.ScalarAxis(range=ELONGATION_RANGE, zoom_lock=False)),
                         rrb.TimeSeriesView(origin="displacement", name="Slave: displacement [m]"),
                         rrb.TimeSeriesView(origin="signals", name="Slave: other signals")),
                _phase_lane(rrb),
                row_shares=[4, 4, 1], name="Slave signals",
            ),
            _master_column(rrb, ("",)),
            column_shares=[3, 3, 2],
        ),
        rrb.TimePanel(timeline=SESSION),
        auto_views=False,
    )


def _phase_lane(rrb: Any) -> Any:
    return rrb.StateTimelineView(origin="/", contents=["/phase"], name="Slave: transmission phase")


def _console_lane(rrb: Any) -> Any:
    """The operator's state at the console (deadman, clutch, engaged) and the experiment marker, as lanes."""
    return rrb.StateTimelineView(origin="/", contents=["/master/console", "/experiment"],
                                 name="Master: operator (deadman, clutch, engaged), experiment")


def _master_column(rrb: Any, axes: Sequence[str], arm: str = "", unit: str = "m") -> Any:
    """The master's column: rendered and mapped force [N] and command [``unit``: m of tendon, rad of joint angle]
    of every axis in ``axes`` (entities
    ``master/[<arm>/][<axis>/]<name>``; "" for the axis of a single tendon), the round trip [s] and the
    console lane (none under an arm: the bimanual view has one for both)."""
    def paths(*names: str) -> list[str]:
        base = "/master" + (f"/{arm}" if arm else "")
        return [f"{base}{'/' + a if a else ''}/{n}" for a in axes for n in names]

    who = f"{arm} hand" if arm else "Master"
    views = [rrb.TimeSeriesView(origin="/", contents=paths("force", "force_cmd"),
                                name=f"{who}: rendered and mapped force [N]"),
             rrb.TimeSeriesView(origin="/", contents=paths("x_in_cmd"), name=f"{who}: command [{unit}]")]
    if arm:
        return rrb.Vertical(*views, row_shares=[1, 1], name=who)
    return rrb.Vertical(*views, rrb.TimeSeriesView(origin="/", contents=["/master/rtt"], name="Master: round trip [s]"),
                        _console_lane(rrb), row_shares=[3, 3, 2, 2], name="Master")


def _joint_eye(rrb: Any, joints: Sequence[JointView]) -> Any:
    """A camera that sees every pair: from the front, above and a little behind the routes' centre."""
    pts = np.vstack([route_points(j.route_a) - np.array([0.0, 0.0, k * JOINT_SPACING]) for k, j in enumerate(joints)])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    centre, extent = 0.5 * (lo + hi), float(np.max(hi - lo))
    return rrb.EyeControls3D(position=centre + extent * np.array([0.0, -1.4, 1.6]), look_target=centre,
                             eye_up=(0.0, 0.0, 1.0))


def _joint_row(rrb: Any, j: JointView) -> Any:
    """One joint's torque [N m] and angle [rad] plots side by side: the torque on its fixed range, the angle's range
    from the data (a recorded run's joint may go past the configured limits)."""
    return rrb.Horizontal(
        rrb.TimeSeriesView(origin=f"joints/{j.name}/torque", name=f"{j.name}: torque [N m]",
                           axis_y=rrb.ScalarAxis(range=j.torque_range, zoom_lock=False)),
        rrb.TimeSeriesView(origin=f"joints/{j.name}/angle", name=f"{j.name}: angle [rad]"))


def _pairs_view(rrb: Any, joints: Sequence[JointView]) -> Any:
    return rrb.Spatial3DView(origin="instrument", eye_controls=_joint_eye(rrb, joints),
                             name="Tendon pairs coloured by tension (0-25 N, blue -> red), one pair per joint")


def _joint_blueprint(rrb: Any, joints: Sequence[JointView]) -> object:
    rows = [_joint_row(rrb, j) for j in joints]
    names = [j.name for j in joints]
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(_pairs_view(rrb, joints), rrb.TimeSeriesView(origin="signals", name="Slave: other signals"),
                         row_shares=[4, 1], name="Slave"),
            rrb.Vertical(*rows, row_shares=[1] * len(rows), name="Slave: joints"),
            _master_column(rrb, names if len(names) > 1 else ("",), unit="rad"),
            column_shares=[3, 3, 2],
        ),
        rrb.TimePanel(timeline=SESSION),
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


def _hand_column(rrb: Any, arm: str, names: Sequence[str], joints: Sequence[JointView]) -> Any:
    """One arm's column: its joints' torque and angle, then its hand's forces [N] and commands [m] on every joint
    axis (``master/<arm>/<joint>/...``)."""
    rows = [_joint_row(rrb, j) for j in joints if j.name.partition("/")[0] == arm]
    hand = _master_column(rrb, ("", *names), arm, unit="rad")   # "": a one-axis hand logs master/<arm>/<name>
    return rrb.Vertical(*rows, hand, row_shares=[3] * len(rows) + [4], name=f"{arm} arm")


def _bimanual_blueprint(rrb: Any, joints: Sequence[JointView], arms: dict[str, tuple[str, ...]]) -> object:
    """Both arms: the tendon pairs in 3D with the console lanes and the round trip, beside one column per arm."""
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                _pairs_view(rrb, joints),
                _console_lane(rrb),
                rrb.Tabs(rrb.TimeSeriesView(origin="/", contents=["/master/rtt"], name="Master: round trip [s]"),
                         rrb.TimeSeriesView(origin="signals", name="Slave: other signals")),
                row_shares=[5, 1, 2],
            ),
            *(_hand_column(rrb, arm, names, joints) for arm, names in arms.items()),
            column_shares=[2] + [2] * len(arms),
        ),
        rrb.TimePanel(timeline=SESSION),
        auto_views=False,
    )
