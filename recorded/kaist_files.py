"""Where the KAIST recordings are: the one place that knows both layouts of the data and names each file by
its configuration N (the insertion tube's bend [deg]).

* The project's folder (``kaist-tsm/``, SOURCE.md there): ``sine_config_<N>.txt``.
* The source repository (a plain clone of https://github.com/nhoyh/hysteresis_compensation_ROS):
  ``optimization/selected/<N>.txt``, beside longer recordings of another layout (``conf0_60.txt``, ...) that are
  not configurations.

:func:`kaist_files` takes either folder, or the clone's root, and returns the folder and its configurations;
the default folder is the data folder's (:func:`recorded.folders.dataset_dir`, ``TSM_TELEOP_DATA``).
"""
from __future__ import annotations

import re
from pathlib import Path

from estimator.errors import DataError
from recorded.folders import KAIST, dataset_dir, not_found

__all__ = ["SELECTED", "default_kaist_dir", "kaist_files", "find_configs", "find_kaist_dir", "config_of",
           "is_kaist_file", "kaist_path"]

#: Where a clone of the source repository keeps the configurations, from its root.
SELECTED = Path("optimization", "selected")
_NAME = re.compile(r"sine_config_(\d+(?:\.\d+)?)\.txt")
_BARE = re.compile(r"(\d+(?:\.\d+)?)\.txt")


def default_kaist_dir() -> Path:
    """The KAIST folder of the data folder: ``kaist-tsm`` or a clone ``hysteresis_compensation_ROS``
    (:func:`recorded.folders.dataset_dir`)."""
    return dataset_dir(KAIST)


def _num(text: str) -> float:
    v = float(text)
    return int(v) if v.is_integer() else v


def _fmt(n: float) -> str:
    return str(int(n)) if float(n).is_integer() else str(n)


def _in_folder(d: Path) -> list[tuple[float, Path]]:
    """The configurations of one folder: its ``sine_config_<N>.txt`` files, else its ``<N>.txt`` files."""
    files = [p for p in d.iterdir() if p.is_file()] if d.is_dir() else []
    for pattern in (_NAME, _BARE):
        found = [(_num(m.group(1)), p) for p in files if (m := pattern.fullmatch(p.name))]
        if found:
            return sorted(found, key=lambda x: x[0])
    return []


def kaist_files(root: str | Path) -> tuple[Path, list[tuple[float, Path]]]:
    """The KAIST recordings under ``root``, each named by its configuration N [deg].

    ``root`` is the project's folder (``sine_config_<N>.txt``), a clone's ``optimization/selected`` folder or
    any folder of ``<N>.txt`` files, or a clone's root (its ``optimization/selected``). In a folder the
    ``sine_config_<N>.txt`` files win over ``<N>.txt`` ones.

    Returns
    -------
    (folder, [(N, path), ...] sorted by N): the folder that holds them; ``(root, [])`` when none is found.
    """
    d = Path(root)
    for folder in (d, d / SELECTED):
        found = _in_folder(folder)
        if found:
            return folder, found
    return d, []


def find_configs(directory: str | Path) -> list[tuple[float, Path]]:
    """Every configuration under ``directory`` as (N [deg], path), sorted by N (:func:`kaist_files`)."""
    return kaist_files(directory)[1]


def find_kaist_dir(path: str | Path | None = None) -> Path:
    """The folder holding the KAIST recordings under ``path`` (default :func:`default_kaist_dir`).

    Raises
    ------
    DataError
        ``path`` is a file, or no configuration is found under it: one line naming the folder, what is expected
        there and docs/how-to/get-the-data.md.
    """
    d = Path(path) if path is not None else default_kaist_dir()
    if d.is_file():
        raise DataError(f"{d}: a file, not a folder: --kaist takes the folder of the sine_config_<N>.txt files "
                        "or a clone of the source repository (one file: teleop analyze FILE [--bend DEG])")
    folder, found = kaist_files(d)
    if not found:
        raise DataError(not_found(KAIST, d))
    return folder


def config_of(path: str | Path | None) -> float | None:
    """The configuration N [deg] a file's name gives: ``sine_config_<N>.txt``, or ``<N>.txt`` in a folder named
    ``selected`` (the source repository's layout); None for any other name."""
    if path is None:
        return None
    p = Path(path)
    m = _NAME.fullmatch(p.name) or (_BARE.fullmatch(p.name) if p.parent.name == SELECTED.name else None)
    return _num(m.group(1)) if m else None


def is_kaist_file(path: str | Path | None) -> bool:
    """True when the file's name gives its configuration (:func:`config_of`)."""
    return config_of(path) is not None


def kaist_path(directory: str | Path, config_deg: float) -> Path:
    """The file of configuration ``config_deg`` [deg] in ``directory`` (either layout, :func:`kaist_files`);
    ``<directory>/sine_config_<N>.txt`` when there is none."""
    folder, found = kaist_files(directory)
    for n, p in found:
        if n == config_deg:
            return p
    return Path(directory) / f"sine_config_{_fmt(config_deg)}.txt"
