"""Where the MRD runs are: the one place that knows both layouts of the data and names each run by its file.

* The project's folder (``mrd-davinci/``, SOURCE.md there): ``Tool_4_Maryland_L_2/<NN>.TXT`` and three more
  folders under ``more/``.
* The source repository (a plain clone of https://github.com/MRDLab/mis-tool-characterization):
  ``data/Tool_<...>/<NN>.TXT`` (fifteen folders; ``<ZXY>.TXT`` in the roll and pitch folders).

A run is a ``*.TXT`` file of its folder (the folder's ``SerialLog.txt`` and ``ReadME.txt`` are not runs) and is
named by its file stem (``"00"``). :func:`find_mrd_folder` takes a folder of runs, one ``Tool_`` folder, the
project's folder, a clone's root or its ``data/`` and returns the folder of runs it means; the default is the
data folder's (:func:`recorded.folders.dataset_dir`, ``TSM_TELEOP_DATA``).
"""
from __future__ import annotations

from pathlib import Path

from estimator.errors import DataError
from recorded.folders import MRD, dataset_dir, not_found

__all__ = ["DEFAULT_FOLDER", "default_mrd_dir", "run_files", "run_folders", "find_mrd_folder", "mrd_folder"]

#: The folder of runs read when a root holds several: the one of the results pages (docs/results/mrd.md).
DEFAULT_FOLDER = "Tool_4_Maryland_L_2"
#: Sub-folders holding folders of runs, from a root: a clone's ``data/``; and the project's ``more/``, where
#: :func:`mrd_folder` also looks.
_NESTS = ("", "data")
_NAMED = _NESTS + ("more",)
_NOT_RUNS = {"seriallog.txt", "readme.txt"}


def default_mrd_dir() -> Path:
    """The MRD folder of the data folder: ``mrd-davinci`` or a clone ``mis-tool-characterization``
    (:func:`recorded.folders.dataset_dir`)."""
    return dataset_dir(MRD)


def run_files(folder: str | Path) -> list[Path]:
    """The runs of one folder: its ``*.TXT`` files but ``SerialLog.txt`` and ``ReadME.txt``, sorted by name."""
    d = Path(folder)
    if not d.is_dir():
        return []
    return sorted(p for p in d.glob("*.TXT") if p.is_file() and p.name.lower() not in _NOT_RUNS)


def run_folders(root: str | Path) -> list[Path]:
    """The folders of runs one level under ``root`` and under its ``data/`` (a clone), sorted by path."""
    d = Path(root)
    subs = {s for nest in _NESTS if (d / nest).is_dir() for s in (d / nest).iterdir() if s.is_dir()}
    return sorted(s for s in subs if run_files(s))


def find_mrd_folder(root: str | Path | None = None) -> tuple[Path, list[Path], str]:
    """The folder of runs ``root`` (default :func:`default_mrd_dir`) means, its runs, and a note.

    ``root`` itself when it holds runs; else its one folder of runs (:func:`run_folders`); else, of several,
    :data:`DEFAULT_FOLDER`, with a note (one line) that names the choice.

    Raises
    ------
    DataError
        ``root`` is a file; no run under it (what is expected, and docs/how-to/get-the-data.md); several folders
        of runs and none of them :data:`DEFAULT_FOLDER` (the folders named).
    """
    d = Path(root) if root else default_mrd_dir()
    if d.is_file():
        raise DataError(f"{d}: a file, not an MRD folder: give the folder that holds the *.TXT runs "
                        f"(--runs {d.stem} picks this one)")
    files = run_files(d)
    if files:
        return d, files, ""
    subs = run_folders(d)
    if len(subs) == 1:
        return subs[0], run_files(subs[0]), ""
    pick = next((s for s in subs if s.name == DEFAULT_FOLDER), None)
    if pick is not None:
        return pick, run_files(pick), (f"{d}: {len(subs)} folders of runs; reading {pick} (the results pages' "
                                       "folder): give another folder to read it")
    if subs:
        names = ", ".join(str(s.relative_to(d)) for s in subs)
        raise DataError(f"{d}: {len(subs)} folders of runs ({names}): give one of them")
    raise DataError(not_found(MRD, d))


def mrd_folder(name: str, root: str | Path | None = None) -> Path:
    """The folder of runs called ``name`` (``"Tool_5_Maryland_L_2"``) under ``root`` (default
    :func:`default_mrd_dir`) in either layout: ``root/name``, ``root/data/name`` or ``root/more/name``;
    ``root/name`` when none exists."""
    d = Path(root) if root else default_mrd_dir()
    for nest in _NAMED:
        if (d / nest / name).is_dir():
            return d / nest / name
    return d / name
