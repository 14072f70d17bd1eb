"""The figure ``teleop record`` writes at the end: each recorded stream's main signals over time."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from teleop.figure_files import pyplot

__all__ = ["streams_figure"]

_SKIP = ("seq", "cmd_seq", "marker", "side", "engaged", "phase", "count")


def _read(path: Path) -> tuple[list[str], np.ndarray]:
    with open(path, encoding="utf-8") as fh:
        lines = [ln for ln in fh if ln.strip() and not ln.startswith("#")]
    if len(lines) < 2:
        return [], np.empty((0, 0))
    names = lines[0].strip().split(",")
    return names, np.loadtxt(lines[1:], delimiter=",", ndmin=2)


def streams_figure(paths, out: str | Path, max_signals: int = 4) -> Path:
    """One panel per CSV in ``paths`` (the recorder's per-stream files): up to ``max_signals`` of its
    columns against ``time`` [s] (time stamps, counters, profiles and enums left out; the heartbeat
    ``state`` kept). Returns ``out`` (PNG)."""
    plt = pyplot()

    tables = [(Path(p), *_read(Path(p))) for p in paths]
    tables = [t for t in tables if t[2].size]
    fig, axes = plt.subplots(max(1, len(tables)), 1, figsize=(10, 2.6 * max(1, len(tables))), squeeze=False)
    for ax, (path, names, arr) in zip(axes[:, 0], tables):
        t = arr[:, 0] - arr[0, 0]
        picked = [i for i, n in enumerate(names) if i and n not in _SKIP and not n.startswith("t_")
                  and "profile" not in n][:max_signals]
        for i in picked:
            ax.plot(t, arr[:, i], lw=0.8, label=names[i])
        ax.set_title(path.stem, fontsize=9)
        ax.set_xlabel("recorder time [s]")
        if picked:
            ax.legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    fig.savefig(out, dpi=80)
    plt.close(fig)
    return Path(out)
