"""``rig.type: recording``: a measured recording played as the instrument's hardware.

Each cycle the rig returns the recorded *proximal* signals at the recording's time (what a drive's encoder
and torque sensor read) and keeps the recorded *distal* signals as the ground truth of the summary (as the
simulators' truth: the estimators never read it). The commands the slave sends are recorded in the state
and otherwise ignored: the recording's motion is the one that happened.

The format of a recording (``rig.recording.format: auto``) is read from its first lines, never from its
name (:mod:`live.recording_formats`). An MRD da Vinci run (``XY.TXT``, :mod:`study.mrd`) drives the spindle
axis of an instrument of one spindle-driven jaw: x_in = the spindle angle [rad], T_in = the spindle torque
[N m], the truth's ``torque`` and ``theta`` the measured jaw torque [N m] and angle [rad]. The calibration the
slave needs is fitted on one named run of the recording's folder (:mod:`live.recording_axis`), because a
recording cannot execute a calibration motion.

A KAIST recording (``sine_config_N.txt``, or ``optimization/selected/N.txt`` of a clone; :mod:`study.kaist`)
drives the pair axis of an instrument of one antagonistic pair (:mod:`live.recording_pair`): x_in = the motor
command [rad] on both tendons, T_in = the two proximal tensions [N], the truth's ``theta`` the measured distal
angle. The project's measured-data CSV (:func:`teleop.recording.measured_csv.read_measured_csv`) drives the single-tendon
axis (:mod:`live.recording_tendon`): x_in, T_in proximal, T_out and x_out the truth.

Layering: the readers live in :mod:`study` (floor 3) and the rig reads through them, so the rig lives
here on floor 4 and registers itself in :data:`slave.rigs.RIG_TYPES` when this module is imported
(:mod:`live.sides` imports it before the slave builds its rig); :mod:`slave` stays free of the study.

``rig.recording.rate``: ``recording`` gives one recorded sample per step at the recording's own time;
``slave`` resamples the recording linearly at the rig's time (the sum of the steps' ``dt``).
``rig.recording.at_end``: ``stop`` holds the last sample and sets :attr:`RecordedSpindle.finished`;
``loop`` starts an MRD run over, the time running on (a KAIST or CSV recording plays once).
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from estimator.errors import DataError
from live.recording_formats import detect_format
from slave.rig import InstrumentTruth, RigInputError, RigState
from slave.rigs import register_rig
from study.mrd import MrdRun, read_mrd
from teleop.config.schema import Config
from teleop.errors import ConfigError

__all__ = ["FORMATS", "recording_format", "check_recording", "read_recording", "read_recording_run", "recorded_motion",
           "RecordedSpindle"]

#: The formats ``rig.recording.format`` names, and the axis each drives.
FORMATS = {"mrd": "spindle", "kaist": "pair", "csv": "single tendon"}


def recording_format(path: Path, fmt: str = "auto") -> str:
    """The format of the recording ``path``: ``fmt`` unless ``auto``; else the one its first lines show
    (:func:`live.recording_formats.detect_format`: the project's CSV header, 8 numbers a row: kaist, 10: mrd).

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


def _instrument_axis(cfg: Config) -> str:
    """The config's axis type, in the words of :data:`FORMATS`."""
    joints = cfg.instrument.joints
    if not joints:
        return "single tendon"
    return "spindle" if joints[0].spindle_radius > 0 else "pair"


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
    want, have = FORMATS[fmt], _instrument_axis(cfg)
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
    """The checked recording of ``cfg`` read by :func:`study.mrd.read_mrd` (errors of :func:`check_recording`
    and :func:`study.mrd.read_mrd`: one line naming the file and the problem)."""
    path, _ = check_recording(cfg)
    return read_mrd(path)


def read_recording(cfg: Config) -> Any:
    """The checked recording of ``cfg`` read whole by its format's reader (an MrdRun or a KAIST recording):
    every problem of the file is one line naming it before anything starts (:func:`check_recording`,
    :func:`study.mrd.read_mrd`, :func:`study.kaist.read_kaist`)."""
    path, fmt = check_recording(cfg)
    if fmt == "kaist":
        from study.kaist import read_kaist_recording
        return read_kaist_recording(path)
    if fmt == "csv":
        from live.recording_tendon import read_tendon_csv
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


class RecordedSpindle:
    """An MRD run played as one spindle-driven jaw (module docstring), a :class:`slave.rig.Rig`.

    Parameters
    ----------
    run : MrdRun
    joint_name : str
        The instrument's jaw.
    rate : ``"recording"`` or ``"slave"``
    at_end : ``"stop"`` or ``"loop"``

    Attributes
    ----------
    finished : bool
        ``at_end: stop`` and the last sample reached.
    """

    def __init__(self, run: MrdRun, joint_name: str = "jaw", rate: str = "recording", at_end: str = "stop"):
        if rate not in ("recording", "slave") or at_end not in ("stop", "loop"):
            raise ConfigError(f"rig.recording: rate {rate!r} must be recording or slave, at_end {at_end!r} stop or loop")
        self.run, self.rate, self.at_end = run, rate, at_end
        self.joint_names = (joint_name,)
        self.n_joints = 1
        self.duration = float(run.time[-1])
        self.period = self.duration + run.dt          # one pass of the recording, when it loops [s]
        self.finished = False
        self._i = 0
        self._t = 0.0
        self._state = self._read(0.0, 0, np.zeros(1))

    @classmethod
    def from_config(cls, cfg: Config) -> RecordedSpindle:
        """The recording of ``rig.recording`` for the config's one jaw (errors of :func:`read_recording_run`)."""
        rc = cfg.rig.recording
        return cls(read_recording_run(cfg), cfg.instrument.joints[0].name, rc.rate, rc.at_end)

    @property
    def axis_kind(self) -> Any:
        """The slave's axis kind on this rig: :class:`live.recording_axis.RecordedSpindleAxis`."""
        from live.recording_axis import RecordedSpindleAxis
        return RecordedSpindleAxis

    @property
    def state(self) -> RigState:
        return self._state

    def step(self, x_in_cmd: Any, dt: float) -> RigState:
        """Advance ``dt`` [s] > 0 (one sample at ``rate: recording``); the recorded proximal signals then.

        Raises
        ------
        RigInputError (ValueError)
            ``dt`` not a finite number > 0, or a command that is not one finite spindle angle [rad].
        """
        if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt > 0):
            raise RigInputError(f"dt must be a finite time step > 0 s, got {dt!r}")
        cmd = np.asarray(x_in_cmd, dtype=float).reshape(-1)
        if cmd.shape != (1,) or not np.isfinite(cmd).all():
            raise RigInputError(f"x_in_cmd must be 1 finite spindle angle in rad, got {cmd.tolist()}")
        n = len(self.run)
        if self.rate == "recording":
            i = self._i + 1
            lap, k = divmod(i, n)
            if lap and self.at_end == "stop":
                self.finished, i, lap, k = True, n - 1, 0, n - 1
            self._i = i
            t = lap * self.period + float(self.run.time[k])
        else:
            t = self._t + dt
            lap = int(t // self.period) if self.at_end == "loop" else 0
            if self.at_end == "stop" and t >= self.duration:
                self.finished, t = True, max(t, self.duration)
            k = -1
        self._t = t
        self._state = self._read(t, k, cmd, lap)
        return self._state

    def _read(self, t: float, k: int, cmd: np.ndarray, lap: int = 0) -> RigState:
        """The state at rig time ``t`` [s]: sample ``k`` (>= 0), else interpolated at t - lap period."""
        r = self.run
        if k >= 0:
            th, tq, ad, td = r.theta_p[k], r.tau_p[k], r.theta_d[k], r.tau_d[k]
        else:
            tr = min(t - lap * self.period, self.duration)
            th, tq, ad, td = (float(np.interp(tr, r.time, v)) for v in (r.theta_p, r.tau_p, r.theta_d, r.tau_d))
        none = np.zeros((1, 2))         # the cables' tensions and stretch are not measured on the recorded tool
        truth = InstrumentTruth(theta=np.array([ad]), torque=np.array([td]), T_in=none, T_out=none, x_in=none,
                                x_out=none, elongation=none)
        return RigState(t=float(t), x_in=np.array([th], dtype=float), T_in=np.array([tq], dtype=float),
                        x_in_cmd=np.array(cmd, dtype=float), truth=truth)

    def set_load(self, *, tissue: bool | None = None, force: float | None = None) -> None:
        """The recorded load is the one that acted: nothing to switch."""

    def close(self) -> None:
        """Nothing to release; idempotent."""


@register_rig("recording")
def _recording(cfg: Config, session: Any) -> Any:
    path, fmt = check_recording(cfg)
    if fmt == "kaist":
        from live.recording_pair import RecordedPair
        return RecordedPair.from_config(cfg, path)
    if fmt == "csv":
        from live.recording_tendon import RecordedTendon
        return RecordedTendon.from_config(cfg, path)
    return RecordedSpindle.from_config(cfg)
