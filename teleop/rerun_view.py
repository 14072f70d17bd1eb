"""The live view's layout (:mod:`teleop.rerun_log`): the sheath route as a 3D polyline, the fixed tension
colour scale along it, the plots' fixed ranges and the blueprint of the views.
"""
from __future__ import annotations

import numpy as np

__all__ = ["TENSION_RANGE", "ELONGATION_RANGE", "WALL", "route_points", "tension_colors", "blueprint"]

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


def tension_colors(T: np.ndarray, vmax: float = TENSION_RANGE[1]) -> np.ndarray:
    """RGBA colours, shape (n, 4) uint8, of tensions ``T`` [N] on a fixed scale 0..``vmax`` (blue -> red)."""
    u = np.clip(np.asarray(T, dtype=float) / vmax, 0.0, 1.0)
    # blue (low) -> yellow -> red (high)
    r = np.clip(2 * u, 0, 1)
    g = np.clip(1.6 * (1 - np.abs(2 * u - 1)), 0, 1) * 0.85 + 0.15 * (u < 0.5)
    b = np.clip(1 - 2 * u, 0, 1)
    return (np.stack([r, g, b, np.ones_like(u)], axis=1) * 255).astype(np.uint8)


def blueprint() -> object:
    """The view sent at the start of a recording: the 3D sheath and the profile bar chart beside the
    fixed-range tension and elongation plots, the master's series and the phase/console/experiment lanes."""
    import rerun.blueprint as rrb

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
