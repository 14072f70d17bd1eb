"""``rig.recording``: the settings of the ``recording`` rig (a measured recording played as the hardware).

The rig itself is :mod:`slave.recording.rig`; :mod:`teleop.config.schema` holds this section under ``rig.recording``.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

__all__ = ["RecordingRigConfig"]


@dataclass(frozen=True)
class RecordingRigConfig:
    """``rig.recording`` (configs/default.yaml spells every key out with its comment).

    path: the recording (a project CSV, a KAIST recording, an MRD ``XY.TXT`` run);
    format: how to read it (``auto``: from the file's first lines, never its name);
    rate: ``recording`` one recorded sample per slave cycle, ``slave`` the recording resampled at the rig's time;
    at_end: ``stop`` holds the last sample and reports the end, ``loop`` starts over;
    calibration_run: the recording the slave's calibration is fitted on: an MRD run (a path, or a run name of the
    recording's folder; null: the tool file's ``calibration.runs`` rule over the folder), a KAIST file (its command
    cycle 1) or a tendon's CSV (its first 60 %) (a path; null: the played recording itself).
    """

    path: str | None = None
    format: Literal["auto", "csv", "kaist", "mrd"] = "auto"
    rate: Literal["recording", "slave"] = "recording"
    at_end: Literal["stop", "loop"] = "stop"
    calibration_run: str | None = None
