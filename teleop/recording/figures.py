"""Where report figures are drawn and written: matplotlib's pyplot on the Agg backend (no display
needed) and the output directory of a figure option, created or refused with one clear error."""
from __future__ import annotations

from pathlib import Path

from teleop.errors import ConfigError

__all__ = ["pyplot", "output_dir", "save_figure"]


def pyplot():
    """matplotlib.pyplot on the non-interactive Agg backend (imported on first use: start-up stays fast)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def output_dir(directory: str | Path, option: str) -> Path:
    """``directory`` created with its parents, for the command-line ``option`` that named it.

    Raises
    ------
    ConfigError
        The directory cannot be created ("<option> <dir>: cannot create the directory (<reason>)").
    """
    d = Path(directory)
    try:
        d.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise ConfigError(f"{option} {d}: cannot create the directory ({e.strerror})") from None
    return d


def save_figure(fig, path: str | Path, dpi: int, rect: tuple[float, float, float, float] | None = None) -> Path:
    """Lay ``fig`` out (``rect``: the area of the figure the axes keep, for a legend or title below or above them),
    write it to ``path`` at ``dpi`` and close it; returns ``path`` as a Path. Raises OSError when it cannot be
    written."""
    if rect is None:
        fig.tight_layout()
    else:
        fig.tight_layout(rect=rect)
    out = Path(path)
    fig.savefig(out, dpi=dpi)
    pyplot().close(fig)
    return out
