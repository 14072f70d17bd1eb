"""Where the two public datasets are, and what a user is told when they are not there.

``TSM_TELEOP_DATA`` names the data folder. It holds the KAIST and the MRD data, each either as the project's
folder (``kaist-tsm/``, ``mrd-davinci/``) or as a plain clone of its public repository
(``hysteresis_compensation_ROS/``, ``mis-tool-characterization/``). Unset or empty, the data folder is
``../shared/data`` beside the checkout. docs/how-to/get-the-data.md gives the ``git clone`` commands and the
licences. Each dataset's own layout (which files, named how) is resolved by :mod:`recorded.kaist_files` and
:mod:`recorded.mrd_files`.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

__all__ = ["DATA_ENV", "GUIDE", "Dataset", "KAIST", "MRD", "data_root", "dataset_dir", "not_found", "skip_reason"]

#: The environment variable naming the data folder.
DATA_ENV = "TSM_TELEOP_DATA"
#: The page that says how to get the data.
GUIDE = "docs/how-to/get-the-data.md"


@dataclass(frozen=True)
class Dataset:
    """One public dataset: its label, the project's folder name, the clone's folder name, the repository and
    what its resolver looks for (a phrase for the messages)."""

    label: str
    folder: str
    clone: str
    url: str
    expected: str


KAIST = Dataset("KAIST", "kaist-tsm", "hysteresis_compensation_ROS",
                "https://github.com/nhoyh/hysteresis_compensation_ROS",
                "optimization/selected/<N>.txt (a clone of github.com/nhoyh/hysteresis_compensation_ROS) or "
                "sine_config_<N>.txt files")
MRD = Dataset("MRD", "mrd-davinci", "mis-tool-characterization", "https://github.com/MRDLab/mis-tool-characterization",
              "data/Tool_<...>/<NN>.TXT runs (a clone of github.com/MRDLab/mis-tool-characterization), one Tool_ "
              "folder, or a folder of <NN>.TXT runs")


def data_root() -> Path:
    """The data folder: ``$TSM_TELEOP_DATA`` (``~`` expanded), else ``../shared/data`` beside the checkout."""
    value = os.environ.get(DATA_ENV, "").strip()
    if value:
        return Path(value).expanduser()
    return Path(__file__).resolve().parents[2] / "shared" / "data"


def dataset_dir(ds: Dataset) -> Path:
    """The dataset's folder in the data folder: the project's folder (``kaist-tsm``, ``mrd-davinci``) when it
    exists, else the clone (``hysteresis_compensation_ROS``, ``mis-tool-characterization``) when it exists, else
    the project's folder (absent: the readers then say what to do)."""
    root = data_root()
    for name in (ds.folder, ds.clone):
        if (root / name).is_dir():
            return root / name
    return root / ds.folder


def not_found(ds: Dataset, where: Path | str) -> str:
    """The one line for a folder holding none of the dataset's recordings: the folder, what is expected there,
    and the guide."""
    p = Path(where)
    missing = "" if p.is_dir() else " (no such folder)"
    return f"no {ds.label} recordings found under {p}{missing}: expected {ds.expected}; see {GUIDE}"


def skip_reason(ds: Dataset, where: Path | str) -> str:
    """Why a test that needs the dataset skips, in words that tell a user what to do."""
    return (f"{ds.label} data not found at {where}: clone {ds.url} into the data folder {data_root()} (or set "
            f"{DATA_ENV} to the folder that holds {ds.folder}/ or {ds.clone}/); see {GUIDE}")
