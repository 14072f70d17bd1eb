"""The figure ``teleop record`` writes at the end: each recorded stream's main signals on one time axis.

One panel per stream that carries signals (the slave's estimates, the master's commands, ...), and one
panel for the states the sides announce in their heartbeats, named (STARTING, CALIBRATING, READY,
ENGAGED, SAFE, STOPPING) rather than numbered. Every panel shares one time axis, the recorder's receive
time from the first message of any stream, so that an event lines up across panels. Each y axis carries
one unit: tensions [N] on the left, lengths [mm] (or angles [deg], torques [N m]) on a right-hand axis,
never two units on one axis. A column's unit is the recorder's ``# units:`` line; the fields whose unit
depends on the axis kind (``effort_hat``, ``position_hat``, the command's ``targets``) take that of a
single tendon (N, m, m) or of an antagonistic pair (N m, rad, rad), told apart by the pair's second
tendon in the estimate's columns.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from teleop.recording.figures import pyplot
from teleop.wire.messages import SideState

__all__ = ["Stream", "read_stream", "streams_plot", "streams_figure"]

_SKIP = ("seq", "cmd_seq", "marker", "side", "engaged", "phase", "count", "alive")
#: plotted unit of a recorded SI unit: (label, scale)
_SHOWN = {"m": ("mm", 1e3), "rad": ("deg", 180.0 / math.pi)}
_AXIS = re.compile(r"^(?:axes\[(\d+)\]\.)?(effort_hat|position_hat)$|^targets\[(\d+)\]$")


@dataclass
class Stream:
    """One recorder CSV: its name, columns, SI unit per column (None when not recorded) and rows."""

    name: str
    names: list[str]
    data: np.ndarray
    units: dict[str, str] = field(default_factory=dict)


def read_stream(path: str | Path) -> Stream:
    """The columns, the ``# units:`` line and the rows of one recorder CSV (no rows: an empty array)."""
    path = Path(path)
    units: dict[str, str] = {}
    with open(path, encoding="utf-8") as fh:
        lines = []
        for ln in fh:
            if ln.startswith("# units:"):
                units = dict(p.strip().split("=", 1) for p in ln[len("# units:"):].split(",") if "=" in p)
            elif ln.strip() and not ln.startswith("#"):
                lines.append(ln)
    if len(lines) < 2:
        return Stream(path.stem, [], np.empty((0, 0)), units)
    names = lines[0].strip().split(",")
    return Stream(path.stem, names, np.loadtxt(lines[1:], delimiter=",", ndmin=2), units)


def _pair_axes(streams: list[Stream]) -> set[int]:
    """The axes that are antagonistic pairs: those with a second tendon in some stream's columns."""
    return {int(m.group(1)) for s in streams for n in s.names if (m := re.match(r"axes\[(\d+)\]\.tendons\[1\]", n))}


def _unit(stream: Stream, name: str, pairs: set[int]) -> str | None:
    if name in stream.units:
        return stream.units[name]
    m = _AXIS.match(name)
    if m is None:
        return None
    axis = int(m.group(1) or m.group(3) or 0)
    kind = m.group(2) or "position_hat"           # a command's target is a position of its axis
    if axis in pairs:
        return "N m" if kind == "effort_hat" else "rad"
    return "N" if kind == "effort_hat" else "m"


def _signals(stream: Stream, pairs: set[int], max_signals: int) -> list[tuple[int, str]]:
    """(column, SI unit) of the signals plotted for one stream, at most two units (one per y axis)."""
    out: list[tuple[int, str]] = []
    for i, n in enumerate(stream.names):
        if i == 0 or n in _SKIP or n.startswith("t_") or "profile" in n or n == "state":
            continue
        u = _unit(stream, n, pairs)
        if u is None or u == "s" or (u not in {x for _, x in out} and len({x for _, x in out}) == 2):
            continue
        out.append((i, u))
    return out[:max_signals]


def _plot_signals(ax, stream: Stream, t: np.ndarray, picked: list[tuple[int, str]]) -> None:
    """The stream's signals against ``t``: the first unit on ``ax``, a second one on a right-hand twin axis."""
    units = list(dict.fromkeys(u for _, u in picked))
    axes = {units[0]: ax}
    if len(units) > 1:
        axes[units[1]] = ax.twinx()
    handles = []
    for k, (i, u) in enumerate(picked):
        label, scale = _SHOWN.get(u, (u, 1.0))
        handles += axes[u].plot(t, stream.data[:, i] * scale, lw=0.8, color=f"C{k}",
                                label=f"{stream.names[i]} [{label}]",
                                ls="-" if u == units[0] else "--")      # dashed: read on the right-hand axis
    for u, a in axes.items():
        a.set_ylabel(f"[{_SHOWN.get(u, (u, 1.0))[0]}]")
    ax.legend(handles=handles, fontsize=7, loc="upper right")


def _plot_states(ax, states: list[tuple[str, np.ndarray, np.ndarray]]) -> None:
    """Each side's announced state over time (step lines), the y axis labelled with the state names."""
    for k, (name, t, code) in enumerate(states):
        ax.step(t, code + 0.06 * (k - (len(states) - 1) / 2), where="post", lw=1.0, label=name)
    ax.set_yticks([s.value for s in SideState], [s.name for s in SideState], fontsize=7)
    ax.set_ylim(min(s.value for s in SideState) - 0.5, max(s.value for s in SideState) + 0.5)
    ax.grid(axis="y", lw=0.3)
    ax.set_title("side states (heartbeats)", fontsize=9)
    ax.legend(fontsize=7, loc="upper right")


def streams_plot(paths, max_signals: int = 4):
    """The figure of :func:`streams_figure` (a matplotlib Figure, the caller closes it).

    One panel per CSV in ``paths`` (a path, or a :class:`Stream` already read) with signals, up to ``max_signals`` of
    its columns (time stamps, counters, profiles and enums left out) in at most two units, and one panel of the
    heartbeats' states; every panel on the shared time axis [s] from the first message of any stream.
    """
    plt = pyplot()
    streams = [s for s in (p if isinstance(p, Stream) else read_stream(p) for p in paths) if s.data.size]
    pairs = _pair_axes(streams)
    t0 = min((float(s.data[0, 0]) for s in streams), default=0.0)
    panels = [(s, picked) for s in streams if (picked := _signals(s, pairs, max_signals))]
    states = [(s.name.removesuffix("_heartbeat"), s.data[:, 0] - t0, s.data[:, s.names.index("state")])
              for s in streams if "state" in s.names]
    n = max(1, len(panels) + bool(states))
    fig, axes = plt.subplots(n, 1, figsize=(10, 2.4 * n), sharex=True, squeeze=False)
    for ax, (s, picked) in zip(axes[:, 0], panels, strict=False):
        _plot_signals(ax, s, s.data[:, 0] - t0, picked)
        ax.set_title(s.name, fontsize=9)
    if states:
        _plot_states(axes[len(panels), 0], states)
    axes[-1, 0].set_xlabel("time since the first recorded message [s]")
    fig.tight_layout()
    return fig


def streams_figure(paths, out: str | Path, max_signals: int = 4) -> Path:
    """Write :func:`streams_plot` of the recorder's per-stream CSVs ``paths`` to ``out`` (PNG); returns ``out``."""
    fig = streams_plot(paths, max_signals)
    fig.savefig(out, dpi=80)
    pyplot().close(fig)
    return Path(out)
