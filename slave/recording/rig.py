"""``rig.type: recording``: a measured recording played as the instrument's hardware.

Each cycle the rig returns the recorded *proximal* signals at the recording's time (what a drive's encoder
and torque sensor read) and keeps the recorded *distal* signals as the ground truth of the summary (as the
simulators' truth: the estimators never read it). The commands the slave sends are recorded in the state
and otherwise ignored: the recording's motion is the one that happened.

The format of a recording (``rig.recording.format: auto``) is read from its first lines, never from its
name (:mod:`recorded.formats`). An MRD da Vinci run (``XY.TXT``, :mod:`recorded.mrd`) drives the spindle
axis of an instrument of one spindle-driven jaw: x_in = the spindle angle [rad], T_in = the spindle torque
[N m], the truth's ``torque`` and ``theta`` the measured jaw torque [N m] and angle [rad]. The calibration the
slave needs is fitted on one named run of the recording's folder (:mod:`slave.recording.spindle`), because a
recording cannot execute a calibration motion.

A KAIST recording (``sine_config_N.txt``, or ``optimization/selected/N.txt`` of a clone; :mod:`recorded.kaist`)
drives the pair axis of an instrument of one antagonistic pair (:mod:`slave.recording.pair`): x_in = the motor
command [rad] on both tendons, T_in = the two proximal tensions [N], the truth's ``theta`` the measured distal
angle. The project's measured-data CSV (:func:`teleop.recording.measured_csv.read_measured_csv`) drives the
single-tendon axis (:mod:`slave.recording.tendon`): x_in, T_in proximal, T_out and x_out the truth.

The recording is read and checked against the instrument by :mod:`recorded.detect`; the rig is registered
in :mod:`slave.rigs` as every rig (``rig.type: recording``, :func:`recording_rig`).

``rig.recording.rate``: ``recording`` gives one recorded sample per step at the recording's own time;
``slave`` resamples the recording linearly at the rig's time (the sum of the steps' ``dt``).
``rig.recording.at_end``: ``stop`` holds the last sample and sets :attr:`RecordedSpindle.finished`;
``loop`` starts an MRD run over, the time running on (a KAIST or CSV recording plays once).
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from recorded.detect import check_recording, read_recording_run
from recorded.mrd import MrdRun
from slave.rig import InstrumentTruth, RigInputError, RigState
from teleop.config.schema import Config
from teleop.errors import ConfigError

__all__ = ["RecordedSpindle", "recording_rig"]


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
            raise ConfigError(f"rig.recording: rate {rate!r} must be recording or slave, "
                              f"at_end {at_end!r} stop or loop")
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
        """The slave's axis kind on this rig: :class:`slave.recording.spindle.RecordedSpindleAxis`."""
        from slave.recording.spindle import RecordedSpindleAxis
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


def recording_rig(cfg: Config) -> Any:
    """The rig of ``rig.recording``: the recording's format chooses it (:func:`recorded.detect.check_recording`:
    one line naming the file and the problem on a recording that does not fit the instrument)."""
    path, fmt = check_recording(cfg)
    if fmt == "kaist":
        from slave.recording.pair import RecordedPair
        return RecordedPair.from_config(cfg, path)
    if fmt == "csv":
        from slave.recording.tendon import RecordedTendon
        return RecordedTendon.from_config(cfg, path)
    return RecordedSpindle.from_config(cfg)
