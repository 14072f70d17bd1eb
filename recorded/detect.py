"""A recording read for ``rig.type: recording``: its format (read from its content, never its name), the check of
its axis against the instrument's kind, and the reader of each format.

* ``mrd``: an MRD da Vinci run (``XY.TXT``, :mod:`recorded.mrd`), the recording of a spindle-driven jaw;
* ``kaist``: a KAIST recording (:mod:`recorded.kaist`), one antagonistic pair;
* ``csv``: the project's measured-data CSV (:func:`teleop.recording.measured_csv.read_measured_csv`), one tendon.

The rig that plays a recording is :mod:`slave.recording.rig`; the scripted operator that follows it
:mod:`master.recording_operator`. Both read the recording here.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from estimator.data import MeasuredData
from estimator.errors import DataError
from recorded.formats import detect_format
from recorded.kaist import read_kaist_recording
from recorded.mrd import MrdRun, read_mrd
from teleop.config.kinds import instrument_kind
from teleop.config.schema import Config
from teleop.errors import ConfigError
from teleop.recording.measured_csv import read_measured_csv

__all__ = ["FORMATS", "KIND_WORDS", "recording_format", "check_recording", "read_recording", "read_recording_run",
           "recorded_motion", "read_tendon_csv"]

#: The words of a recording's axis in the messages, by instrument kind.
KIND_WORDS = {"tendon": "single tendon", "pair": "pair", "spindle": "spindle"}


def read_tendon_csv(path: str | Path) -> MeasuredData:
    """The CSV with a distal channel (T_out or x_out). Raises DataError naming the file and the problem."""
    return read_measured_csv(path).require_distal()


#: The formats ``rig.recording.format`` names, and the axis each drives.
FORMATS = {"mrd": "spindle", "kaist": "pair", "csv": "tendon"}


def recording_format(path: Path, fmt: str = "auto") -> str:
    """The format of the recording ``path``: ``fmt`` unless ``auto``; else the one its first lines show
    (:func:`recorded.formats.detect_format`: the project's CSV header, 8 numbers a row: kaist, 10: mrd).

    Raises
    ------
    DataError
        The file does not exist, or its first lines are of no known format (the file and the formats tried).
    """
    if not path.is_file():
        raise DataError(f"rig.recording.path: {path}: no such file")
    if fmt != "auto":
        return fmt
    return detect_format(path)


def check_recording(cfg: Config) -> tuple[Path, str]:
    """The recording's path and format, checked against the instrument before anything starts.

    Raises
    ------
    ConfigError
        No ``rig.recording.path``; a recording whose axis is not the instrument's (an MRD run on a
        single tendon, ...); an MRD or KAIST recording on an instrument of more than one joint; ``at_end: loop``
        on a KAIST or CSV recording.
    DataError
        A missing or unreadable file (:func:`recording_format`).
    """
    rc = cfg.rig.recording
    if not rc.path:
        raise ConfigError("rig.recording.path: rig.type recording needs a recording (an MRD XY.TXT run, a KAIST "
                          "recording or a measured-data CSV; docs/how-to/get-the-data.md)")
    path = Path(rc.path).expanduser()
    fmt = recording_format(path, rc.format)
    want, have = KIND_WORDS[FORMATS[fmt]], KIND_WORDS[instrument_kind(cfg)]
    if want != have:
        raise ConfigError(f"rig.recording.path: {path} is a {fmt.upper()} recording of a {want} axis; the config's "
                          f"instrument is a {have} axis (instrument.joints): use an instrument of that axis type")
    if fmt != "mrd" and rc.at_end == "loop":
        raise ConfigError(f"rig.recording.at_end: loop replays MRD runs; a {fmt.upper()} recording plays once "
                          "(at_end: stop)")
    if fmt == "csv":
        return path, fmt
    if len(cfg.instrument.joints) != 1:
        raise ConfigError(f"rig.recording.path: {path} is one joint's recording; instrument.joints has "
                          f"{len(cfg.instrument.joints)} joints, need 1")
    return path, fmt


def read_recording_run(cfg: Config) -> MrdRun:
    """The checked recording of ``cfg`` read by :func:`recorded.mrd.read_mrd` (errors of :func:`check_recording`
    and :func:`recorded.mrd.read_mrd`: one line naming the file and the problem)."""
    path, _ = check_recording(cfg)
    return read_mrd(path)


def read_recording(cfg: Config) -> Any:
    """The checked recording of ``cfg`` read whole by its format's reader (an MrdRun or a KAIST recording):
    every problem of the file is one line naming it before anything starts (:func:`check_recording`,
    :func:`recorded.mrd.read_mrd`, :func:`recorded.kaist.read_kaist`)."""
    path, fmt = check_recording(cfg)
    if fmt == "kaist":
        return read_kaist_recording(path)
    if fmt == "csv":
        return read_tendon_csv(path)
    return read_mrd(path)


def recorded_motion(cfg: Config) -> tuple[np.ndarray, np.ndarray]:
    """(time [s] from 0, the recorded motion the operator retraces) of ``cfg``'s recording: the distal angle [rad]
    of an MRD or KAIST recording, the proximal displacement x_in [m] of a tendon's CSV."""
    path, fmt = check_recording(cfg)
    rec = read_recording(cfg)
    if fmt == "kaist":
        return rec.time - rec.time[0], rec.angle
    if fmt == "csv":
        return rec.time - rec.time[0], rec.x_in
    return rec.time, rec.theta_d
