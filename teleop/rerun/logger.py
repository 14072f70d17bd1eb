"""Rerun logging of the live tendon-sheath state (rerun-sdk 0.41, one explicit RecordingStream).

Over 400 lines: one logger of every mode (save, spawn, serve), its timelines and the entity layout it writes.

Timelines (durations in seconds): ``session``, the time since the run began, the one the view shows: the wall
clock (``time.time``) since the time stamp of the run id (``YYYYmmdd-HHMMSS[-n]``, the recording id every process
of the run shares), so that slave and master line up, on one machine or on two with synchronised clocks; when the
recording id is not a run id, since the logger's first log (``wall_clock``: the caller's clock since its first
``t``, a replay's recording time). ``time``: the caller's ``t`` where it is a clock of its own (the rig's time
on the slave). The slave's ``slave.rrd`` and the master's ``master.rrd`` share the application and recording id,
so ``rerun slave.rrd master.rrd`` shows one recording.

Entity layout::

    profile/T_hat          BarChart  tension along the sheath [N] over arc length [m], estimated
    profile/T_true         BarChart  the same, ground truth (simulation or instrumented rig)
    tension/<name>         Scalars   names starting with "T": T_in, T_out_true, T_out_hat, ... [N]
    elongation/<name>      Scalars   names starting with "elongation" [m]
    displacement/<name>    Scalars   names starting with "x_" [m]
    signals/<name>         Scalars   anything else
    phase                  StateChange  the transmission phase label (readable: estimator/readable_phase.py), on change
    sheath/route           LineStrips3D the sheath route from the config (static, grey), when ``route`` is given
    sheath/tension         LineStrips3D the route coloured by the estimated tension along it [N]
    sheath/tension_true    LineStrips3D the same from the truth, drawn beside it
    sheath/distal          Points3D     the distal joint: estimated and true T_out in its label
    master/<name>          Scalars      master-side series: x_in_cmd [m], force and force_cmd [N], rtt [s]
    master/console, experiment  StateChange  the operator's state at the console (WAIT_OPERATOR: deadman open,
                                         CLUTCH, ENGAGED, ...) and the experiment marker, on change

A joint instrument (``joints``: :class:`teleop.rerun.layout.JointView` per joint) logs instead, per joint
(:meth:`RerunLogger.log_joint`): ``joints/<j>/torque/{hat,true}`` and ``joints/<j>/angle/{hat,true}``
(Scalars), ``instrument/<j>/<a|b>/route`` (static grey) and ``/tension`` (LineStrips3D coloured by the
estimated tension along the tendon), and ``instrument/<j>/tip`` (Points3D labelled with the joint's
estimated and true torque and angle); the pairs are stacked :data:`~teleop.rerun.layout.JOINT_SPACING` apart.

The bar chart is the only 0.41 view with real numeric x and y axes for non-time data (a
``TimeSeriesView`` always plots against a timeline; a ``Spatial2DView`` has no axis ticks and a
downward y axis), so the profile is two bar charts overlaid in one ``BarChartView``: the truth as
wide translucent blue bars, the estimate as narrow orange bars on top. The blueprint sent at start
shows that view, the tension and elongation plots, the other signals and the phase lanes.

A bar-chart log costs ~0.1 ms (tensor conversion in the SDK), a scalar ~0.02 ms; use
``profile_every`` to decimate profiles when the caller logs at high rate.

Saved to a file (``save``), the stream gathers each entity's rows for :data:`SAVE_FLUSH` before it writes
them as one chunk: every chunk carries ~1.4 kB of its own (schema, metadata), so the SDK's default of a
chunk every few hundredths of a second made the .rrd of a session two to three times the size of its
rows. A viewer (``spawn``) and a served stream (``serve``) get the SDK's default, which keeps them live.

Served (``serve``, :mod:`teleop.rerun.serve`), the stream goes to a gRPC server in this process (bounded memory,
for late viewers) and, with a path, to the .rrd file too, one file for the whole session (not segmented: the
server's port stays the same from the first log to the last); the web viewer runs as a child process.

A saved recording is written in .rrd segments of :data:`~teleop.rerun.segments.SEGMENT_S`
(:mod:`teleop.rerun.segments`).
"""
from __future__ import annotations

import os
import sys
import tempfile
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from teleop.errors import ConfigError
from teleop.rerun.joints import ORANGE, JointLogging, arc_length
from teleop.rerun.layout import SESSION, TENSION_RANGE, route_points, route_segments, tension_colors
from teleop.rerun.layout import blueprint as view_blueprint
from teleop.rerun.segments import SEGMENT_S, SegmentedSave
from teleop.rerun.serve import ServeSpec, start_web_viewer

if TYPE_CHECKING:
    import rerun as rr

__all__ = ["RerunLogger", "signal_path", "display_available", "session_origin", "MODES"]

MODES = ("save", "spawn", "serve", "off")
SAVE_FLUSH = 2.0            # [s] an .rrd file's chunks gather this long of each entity's rows
TIMELINE = "time"
_BLUE, _BLUE_SEE_THROUGH = (31, 119, 180, 255), (31, 119, 180, 110)
_ORANGE, _GREY = ORANGE, (150, 150, 150, 255)


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


def session_origin(recording_id: str | None) -> float | None:
    """The start of the run [s since the epoch] from a run id ``YYYYmmdd-HHMMSS[-n]`` (local time, as
    ``live.sides.default_run_dir`` names it); None for any other id."""
    import re
    if not recording_id or not re.fullmatch(r"\d{8}-\d{6}(-\d+)?", recording_id):
        return None
    try:
        return time.mktime(time.strptime(recording_id[:15], "%Y%m%d-%H%M%S"))
    except (ValueError, OverflowError):
        return None


def display_available() -> bool:
    """Whether a viewer window can open here (X11 or Wayland on Linux/BSD; assumed elsewhere)."""
    if sys.platform.startswith(("linux", "freebsd", "openbsd")):
        return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
    return True


class RerunLogger(JointLogging, SegmentedSave):
    """Live tension distribution, signals and phase to a Rerun recording.

    Parameters
    ----------
    application_id : str
        Rerun application id (groups recordings and blueprints in the viewer).
    recording_id : str or None
        Rerun recording id; None picks a fresh random one. Two loggers with different ids coexist.
    mode : {'save', 'spawn', 'serve', 'off'}
        'save' writes an .rrd file at ``path``; 'spawn' opens a viewer when a display exists and
        otherwise saves (to ``path``, or ``<tmp>/<application_id>-<recording_id>.rrd``) after a
        note on stderr; 'serve' serves the stream as ``serve`` says (and writes ``path`` when given);
        'off' makes every method a no-op and does not import rerun.
    path : Path or None
        The .rrd file for 'save' (required) and for the 'spawn' fallback.
    profile_every : int
        Log one profile in this many :meth:`log_profile` calls (>= 1); scalars are never dropped.
    route : sequence of runs (``length`` [m], ``radius`` [m] or inf), optional
        The sheath route (``cfg.sheath.runs``): draws ``sheath/*`` in 3D, coloured by the tension.
    wall_clock : bool
        The caller's ``t`` is a clock of the caller's (the master's monotonic clock, a replay's recording
        time), not a timeline of its own: ``session`` is ``t`` mapped onto the run's start (module docstring);
        otherwise (the slave, whose ``t`` is the rig's time) ``t`` goes on ``time`` and ``session`` is the
        wall clock at the call.
    serve : ServeSpec, optional
        Where 'serve' serves the stream and the web viewer (:func:`teleop.rerun.serve.serve_spec`).

    Attributes
    ----------
    mode : str
        What actually happens: 'save', 'spawn' or 'off' (after any fallback).
    path : Path or None
        The .rrd being written, if any.

    Raises
    ------
    ConfigError
        Unknown mode, 'save' without a path, 'serve' without ``serve``, or ``profile_every`` < 1.
    OSError
        'serve': the port is taken or the address cannot be bound.
    """

    def __init__(self, application_id: str, recording_id: str | None = None,
                 mode: Literal["save", "spawn", "off"] = "save", path: str | Path | None = None,
                 *, profile_every: int = 1, route=None, wall_clock: bool = False, joints=(),
                 segment_s: float | None = SEGMENT_S, serve: ServeSpec | None = None) -> None:
        if mode not in MODES:
            raise ConfigError(f"recording.rerun: expected one of {', '.join(MODES)}, got {mode!r}")
        if mode == "save" and path is None:
            raise ConfigError("recording.rerun: mode 'save' needs a path for the .rrd file")
        if mode == "serve" and serve is None:
            raise ConfigError("recording.rerun: mode 'serve' needs recording.rerun_serve (address, ports)")
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
        self._states: dict[str, str] = {}
        self._route: np.ndarray | None = None
        self._route_s: np.ndarray | None = None
        self._started = False
        self._wall_is_t = bool(wall_clock)
        self._origin = session_origin(recording_id)        # [s since the epoch] of the run's start, or None
        self._t_offset: float | None = None                 # session = t - offset (wall_clock), set at the first log
        self.web_viewer: Any = None                         # 'serve': the web viewer's process
        self._init_segments(None if mode == "serve" else segment_s)
        if route is not None and len(route):
            self._route = route_points(route)
            self._route_s = arc_length(self._route)
        self._init_joints(joints)
        if mode == "off":
            return

        import rerun as rr

        self._rr = rr
        from datetime import timedelta
        batch = None if mode != "save" else rr.ChunkBatcherConfig(
            flush_tick=timedelta(seconds=SAVE_FLUSH), flush_num_bytes=8 << 20, flush_num_rows=1 << 20)
        rec = rr.RecordingStream(application_id, recording_id=recording_id, batcher_config=batch)
        blueprint: Any = view_blueprint(tuple(joints))
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
        if mode == "serve":
            assert serve is not None
            self._serve(rec, serve, blueprint)
        if self.mode == "save":
            assert self.path is not None
            self.path.parent.mkdir(parents=True, exist_ok=True)
            rec.save(self.path, default_blueprint=blueprint)
            self._begin_segments(blueprint)
        self._rec = rec

    def _serve(self, rec: rr.RecordingStream, spec: ServeSpec, blueprint: Any) -> None:
        """The stream to a gRPC server on ``spec`` (and the .rrd at ``path``, if any); the web viewer started."""
        rr = self._rr
        sinks: list[Any] = [rr.GrpcServerSink(bind_ip=spec.bind, port=spec.port,
                                              server_memory_limit=f"{int(spec.memory_limit)}B")]
        if self.path is not None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            sinks.append(rr.FileSink(str(self.path)))
        import socket
        try:                             # the SDK only logs a port it cannot listen on: try it here first
            with socket.socket(socket.AF_INET6 if ":" in spec.bind else socket.AF_INET) as probe:
                probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                probe.bind((spec.bind, spec.port))
            rec.set_sinks(*sinks, default_blueprint=blueprint)
        except Exception as exc:         # OSError, or the SDK's own error types
            raise OSError(f"recording.rerun: serve: cannot serve on {spec.bind}:{spec.port} ({exc})") from exc
        self.web_viewer = start_web_viewer(spec)

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
        self._start(t)
        self._set_time(rec, t)
        self._log_sheath(s, est, true)
        if self._abscissa is None or not np.array_equal(self._abscissa, s):
            # The grid rarely changes: send it only then (temporal: earlier profiles keep theirs).
            self._abscissa = s.copy()
            ds = np.abs(np.gradient(s)) if s.size >= 2 else np.ones_like(s)
            for entity, w, color in (("profile/T_hat", 0.45, _ORANGE),
                                     ("profile/T_true", 0.9, _BLUE_SEE_THROUGH)):
                self._grid[entity] = dict(abscissa=s, widths=w * ds, color=color)
        for entity, values in (("profile/T_hat", est), ("profile/T_true", true)):
            if values is None:
                continue
            grid = self._grid.pop(entity, None)
            rec.log(entity, rr.BarChart.from_fields(values=values, **(grid or {})))

    def _set_time(self, rec, t: float) -> None:
        """The ``session`` timeline at this log and, unless the caller's ``t`` is a clock of its own
        (``wall_clock``), ``t`` on ``time`` (module docstring: timelines)."""
        now = time.monotonic()
        if now >= self._segment_end:
            self._next_segment(now)
        if self._t_offset is None:         # the first log: where the session's time starts
            since = 0.0 if self._origin is None else time.time() - self._origin
            self._t_offset = (float(t) if self._wall_is_t else time.time()) - since
        if self._wall_is_t:
            rec.set_time(SESSION, duration=float(t) - self._t_offset)
            return
        rec.set_time(TIMELINE, duration=float(t))
        rec.set_time(SESSION, duration=time.time() - self._t_offset)

    def _start(self, t: float) -> None:
        """At the first log: the static pieces (route, fixed profile range) and a rest profile at ``t``,
        so that every view has data from where the recording starts."""
        if self._started or self._rec is None:
            return
        self._started = True
        self._log_statics()
        self._log_joint_routes(t)
        if self._route is not None:
            L = float(self._route_s[-1]) if self._route_s is not None else 1.0
            s = np.linspace(0.0, L, 50)
            self.log_profile(t, s, np.zeros_like(s))          # the rest profile: bars and route at 0 N
            self._profile_calls -= 1                           # not counted by the decimation

    def _log_statics(self) -> None:
        """The timeless pieces: the profile plot's fixed range, the sheath's and the tendons' routes."""
        rec, rr = self._rec, self._rr
        if rec is None:
            return
        # an invisible bar pair fixes the profile plot's y range (the bar chart view has no axis setting)
        L = float(self._route_s[-1]) if self._route_s is not None else 1.0
        rec.log("profile/range", rr.BarChart.from_fields(values=np.array(TENSION_RANGE), abscissa=np.array([0.0, L]),
                                                          widths=np.array([1e-6, 1e-6]), color=(0, 0, 0, 0)),
                static=True)
        if self._route is not None:
            rec.log("sheath/route", rr.LineStrips3D([self._route], radii=0.002, colors=[(120, 120, 120, 255)]),
                    static=True)
        self._log_joint_statics()

    def _log_sheath(self, s: np.ndarray, est: np.ndarray, true: np.ndarray | None) -> None:
        """The route coloured by the estimated (and beside it the true) tension; the distal joint."""
        rr, rec = self._rr, self._rec
        if rec is None or self._route is None or self._route_s is None or s.size < 2:
            return
        segs = route_segments(self._route, self._route_s, s)
        pts = segs[:, 1]
        for entity, T, dz in (("sheath/tension", est, 0.0), ("sheath/tension_true", true, 0.02)):
            if T is None:
                continue
            Tm = 0.5 * (T[:-1] + T[1:])
            rec.log(entity, rr.LineStrips3D(segs + np.array([0.0, 0.0, dz]), radii=0.006 if dz == 0 else 0.003,
                                            colors=tension_colors(Tm)))
        label = f"distal T_out est {est[-1]:.2f} N" + ("" if true is None else f" / true {true[-1]:.2f} N")
        rec.log("sheath/distal", rr.Points3D([pts[-1]], radii=0.004 + 0.001 * float(est[-1]),
                                             colors=tension_colors(est[-1:]), labels=[label], show_labels=True))

    def log_state(self, t: float, entity: str, label: str) -> None:
        """A state label (console state, experiment) on ``entity`` at ``t`` [s], logged on change only."""
        rec = self._rec
        label = str(label)
        if rec is None or self._states.get(entity) == label:
            return
        self._states[entity] = label
        self._start(t)
        self._set_time(rec, t)
        rec.log(entity, self._rr.StateChange(state=label))

    def log_master(self, t: float, *, x_in_cmd: float, force: float, force_cmd: float, rtt: float | None,
                   console: str, experiment: str, axis: str | None = None) -> None:
        """Master-side series at ``t`` [s]: command [m], rendered and mapped force [N], round trip [s]
        (None: none yet), console state and experiment name (on change). ``axis``: the instrument axis
        the command and forces belong to (entities ``master/<axis>/...``; None: ``master/...``)."""
        rec = self._rec
        if rec is None:
            return
        self._start(t)
        rr = self._rr
        self._set_time(rec, t)
        for name, v in (("x_in_cmd", x_in_cmd), ("force", force), ("force_cmd", force_cmd), ("rtt", rtt)):
            if v is None:
                continue
            entity = f"master/{name}" if axis is None or name == "rtt" else f"master/{axis}/{name}"
            if entity not in self._paths:
                self._paths[entity] = entity
                label = name if axis is None or name == "rtt" else f"{axis} {name}"
                rec.log(entity, rr.SeriesLines(names=label, widths=1.5), static=True)
            rec.log(entity, rr.Scalars.from_fields(scalars=[float(v)]))
        self.log_state(t, "master/console", console)
        self.log_state(t, "experiment", experiment)

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
        self._start(t)
        self._set_time(rec, t)
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
        self._set_time(rec, t)
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
        viewer, self.web_viewer = self.web_viewer, None
        if viewer is not None:
            viewer.terminate()
            try:
                viewer.wait(5.0)
            except Exception:  # noqa: BLE001 - subprocess.TimeoutExpired: it is killed
                viewer.kill()
                viewer.wait()

    def __enter__(self) -> RerunLogger:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
