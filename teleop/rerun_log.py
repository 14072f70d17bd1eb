"""Rerun logging of the live tendon-sheath state (rerun-sdk 0.41, one explicit RecordingStream).

Entity layout (timeline ``time``, a duration in seconds)::

    profile/T_hat          BarChart  tension along the sheath [N] over arc length [m], estimated
    profile/T_true         BarChart  the same, ground truth (simulation or instrumented rig)
    tension/<name>         Scalars   names starting with "T": T_in, T_out_true, T_out_hat, ... [N]
    elongation/<name>      Scalars   names starting with "elongation" [m]
    displacement/<name>    Scalars   names starting with "x_" [m]
    signals/<name>         Scalars   anything else
    phase                  StateChange  the transmission phase label, logged on change only

The bar chart is the only 0.41 view with real numeric x and y axes for non-time data (a
``TimeSeriesView`` always plots against a timeline; a ``Spatial2DView`` has no axis ticks and a
downward y axis), so the profile is two bar charts overlaid in one ``BarChartView``: the truth as
wide translucent blue bars, the estimate as narrow orange bars on top. The blueprint sent at start
shows that view, the tension and elongation plots, the other signals and the phase lanes.

A bar-chart log costs ~0.1 ms (tensor conversion in the SDK), a scalar ~0.02 ms; use
``profile_every`` to decimate profiles when the caller logs at high rate.
"""
from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from teleop.errors import ConfigError

if TYPE_CHECKING:
    import rerun as rr

__all__ = ["RerunLogger", "signal_path", "display_available", "MODES"]

MODES = ("save", "spawn", "off")
TIMELINE = "time"
_BLUE, _BLUE_SEE_THROUGH = (31, 119, 180, 255), (31, 119, 180, 110)
_ORANGE, _GREY = (255, 127, 14, 255), (150, 150, 150, 255)


def signal_path(name: str) -> str:
    """Entity path of the scalar signal ``name`` (see the module docstring for the rule)."""
    if name.startswith("elongation"):
        return f"elongation/{name}"
    if name.startswith("T"):
        return f"tension/{name}"
    if name.startswith("x_"):
        return f"displacement/{name}"
    return f"signals/{name}"


def _series_color(name: str) -> tuple[int, int, int, int] | None:
    if name.endswith(("_hat", "_est")):
        return _ORANGE
    if name.endswith(("_true", "_meas")):
        return _BLUE
    if name in ("T_in", "x_in"):
        return _GREY
    return None  # let the viewer pick


def display_available() -> bool:
    """Whether a viewer window can open here (X11 or Wayland on Linux/BSD; assumed elsewhere)."""
    if sys.platform.startswith(("linux", "freebsd", "openbsd")):
        return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
    return True


def _blueprint() -> object:
    import rerun.blueprint as rrb

    return rrb.Blueprint(
        rrb.Vertical(
            rrb.BarChartView(origin="profile", name="Tension along the sheath: T [N] vs s [m]",
                             plot_legend=rrb.PlotLegend(corner=rrb.Corner2D.RightTop)),
            rrb.Horizontal(
                rrb.TimeSeriesView(origin="tension", name="Tension [N]"),
                rrb.Tabs(rrb.TimeSeriesView(origin="elongation", name="Elongation [m]"),
                         rrb.TimeSeriesView(origin="displacement", name="Displacement [m]"),
                         rrb.TimeSeriesView(origin="signals", name="Other signals")),
            ),
            rrb.StateTimelineView(origin="phase", name="Phase"),
            row_shares=[4, 4, 1],
        ),
        rrb.TimePanel(timeline=TIMELINE),
        auto_views=False,
    )


class RerunLogger:
    """Live tension distribution, signals and phase to a Rerun recording.

    Parameters
    ----------
    application_id : str
        Rerun application id (groups recordings and blueprints in the viewer).
    recording_id : str or None
        Rerun recording id; None picks a fresh random one. Two loggers with different ids coexist.
    mode : {'save', 'spawn', 'off'}
        'save' writes an .rrd file at ``path``; 'spawn' opens a viewer when a display exists and
        otherwise saves (to ``path``, or ``<tmp>/<application_id>-<recording_id>.rrd``) after a
        note on stderr; 'off' makes every method a no-op and does not import rerun.
    path : Path or None
        The .rrd file for 'save' (required) and for the 'spawn' fallback.
    profile_every : int
        Log one profile in this many :meth:`log_profile` calls (>= 1); scalars are never dropped.

    Attributes
    ----------
    mode : str
        What actually happens: 'save', 'spawn' or 'off' (after any fallback).
    path : Path or None
        The .rrd being written, if any.

    Raises
    ------
    ConfigError
        Unknown mode, 'save' without a path, or ``profile_every`` < 1.
    """

    def __init__(self, application_id: str, recording_id: str | None = None,
                 mode: Literal["save", "spawn", "off"] = "save", path: str | Path | None = None,
                 *, profile_every: int = 1) -> None:
        if mode not in MODES:
            raise ConfigError(f"recording.rerun: expected one of {', '.join(MODES)}, got {mode!r}")
        if mode == "save" and path is None:
            raise ConfigError("recording.rerun: mode 'save' needs a path for the .rrd file")
        if int(profile_every) < 1:
            raise ConfigError(f"RerunLogger: profile_every must be >= 1, got {profile_every}")
        self.mode: str = mode
        self.path: Path | None = Path(path) if path is not None else None
        self.profile_every = int(profile_every)
        self._rec: rr.RecordingStream | None = None
        self._profile_calls = 0
        self._abscissa: np.ndarray | None = None
        self._grid: dict[str, dict] = {}  # per bar-chart entity: grid fields still to send
        self._paths: dict[str, str] = {}
        self._phase: str | None = None
        if mode == "off":
            return

        import rerun as rr

        self._rr = rr
        rec = rr.RecordingStream(application_id, recording_id=recording_id)
        blueprint: Any = _blueprint()
        if mode == "spawn":
            if display_available():
                beside = Path(sys.executable).with_name("rerun")  # venv not on PATH
                try:
                    rr.spawn(recording=rec, default_blueprint=blueprint,
                             executable_path=str(beside) if beside.is_file() else None)
                except Exception as exc:  # viewer binary missing or failed to start
                    self._fall_back(application_id, rec, f"could not spawn the viewer ({exc})")
            else:
                self._fall_back(application_id, rec, "no display (DISPLAY/WAYLAND_DISPLAY unset)")
        if self.mode == "save":
            assert self.path is not None
            self.path.parent.mkdir(parents=True, exist_ok=True)
            rec.save(self.path, default_blueprint=blueprint)
        self._rec = rec

    def _fall_back(self, application_id: str, rec: rr.RecordingStream, why: str) -> None:
        if self.path is None:
            name = f"{application_id}-{rec.get_recording_id()}.rrd"
            self.path = Path(tempfile.gettempdir()) / name
        print(f"rerun: {why}; saving to {self.path} instead (open it with `rerun {self.path}`)",
              file=sys.stderr)
        self.mode = "save"

    @property
    def enabled(self) -> bool:
        """False in 'off' mode and after :meth:`close`."""
        return self._rec is not None

    @property
    def recording(self) -> rr.RecordingStream | None:
        """The underlying stream (None when off or closed), for extra custom logging."""
        return self._rec

    def log_profile(self, t: float, s_positions: np.ndarray, T_estimated: np.ndarray,
                    T_true: np.ndarray | None = None) -> None:
        """Log the tension distribution along the sheath at time ``t``.

        Parameters
        ----------
        t : float [s], time on the ``time`` timeline.
        s_positions : ndarray, shape (n_nodes,) [m], arc length from the proximal end, increasing.
        T_estimated : ndarray, shape (n_nodes,) [N], estimated tension at each node.
        T_true : ndarray, shape (n_nodes,) [N], or None, ground-truth tension.

        Raises
        ------
        ValueError
            If the arrays are not 1-D of the same length.
        """
        rec = self._rec
        if rec is None:
            return
        self._profile_calls += 1
        if (self._profile_calls - 1) % self.profile_every:
            return
        s = np.asarray(s_positions, dtype=np.float64)
        est = np.asarray(T_estimated, dtype=np.float64)
        true = None if T_true is None else np.asarray(T_true, dtype=np.float64)
        if s.ndim != 1 or est.shape != s.shape or (true is not None and true.shape != s.shape):
            raise ValueError(f"log_profile: s_positions {s.shape}, T_estimated {est.shape} and "
                             f"T_true {None if true is None else true.shape} must be equal (n,)")
        rr = self._rr
        rec.set_time(TIMELINE, duration=float(t))
        if self._abscissa is None or not np.array_equal(self._abscissa, s):
            # The grid rarely changes: send it only then (temporal: earlier profiles keep theirs).
            first, self._abscissa = self._abscissa is None, s.copy()
            ds = np.abs(np.gradient(s)) if s.size >= 2 else np.ones_like(s)
            for entity, w, color in (("profile/T_hat", 0.45, _ORANGE),
                                     ("profile/T_true", 0.9, _BLUE_SEE_THROUGH)):
                self._grid[entity] = dict(abscissa=s, widths=w * ds, color=color if first else None)
        for entity, values in (("profile/T_hat", est), ("profile/T_true", true)):
            if values is None:
                continue
            grid = self._grid.pop(entity, None)
            rec.log(entity, rr.BarChart.from_fields(values=values, **(grid or {})))

    def log_scalars(self, t: float, **values: float | None) -> None:
        """Log scalar signals at time ``t``, one entity per name (see :func:`signal_path`).

        Parameters
        ----------
        t : float [s]
        **values : float or None
            SI values, e.g. ``T_in=12.0, T_out_hat=9.1, elongation_hat=4e-4``; None is skipped.
        """
        rec = self._rec
        if rec is None:
            return
        rr = self._rr
        rec.set_time(TIMELINE, duration=float(t))
        for name, value in values.items():
            if value is None:
                continue
            entity = self._paths.get(name)
            if entity is None:
                entity = self._paths[name] = signal_path(name)
                color = _series_color(name)
                style = rr.SeriesLines(names=name, colors=color, widths=1.5)
                rec.log(entity, style, static=True)
            rec.log(entity, rr.Scalars.from_fields(scalars=[float(value)]))

    def log_phase(self, t: float, phase_label: str) -> None:
        """Log the transmission phase label (or a ``Phase``, via ``.label``) at ``t`` on change."""
        rec = self._rec
        label = str(getattr(phase_label, "label", phase_label))
        if rec is None or label == self._phase:
            return
        self._phase = label
        rec.set_time(TIMELINE, duration=float(t))
        rec.log("phase", self._rr.StateChange(state=self._phase))

    def flush(self) -> None:
        """Block until everything logged so far reached the sink."""
        if self._rec is not None:
            self._rec.flush()

    def close(self) -> None:
        """Flush, finalise the .rrd (footer) and disconnect; safe to call more than once."""
        rec, self._rec = self._rec, None
        if rec is not None:
            rec.flush()
            rec.disconnect()

    def __enter__(self) -> RerunLogger:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
