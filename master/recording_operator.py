"""The scripted operator of a recorded run: the hand follows the recorded jaw (or joint) angle.

On ``rig.type: recording`` with the simulated device (``master.device.type: simulated``) the master's operator
is :class:`RecordedOperator` instead of the protocol script: a protocol moves the hand until the rendered
tension crosses its targets, which a recording (whose motion is the one that happened) never answers. The
recorded operator moves the handle so that the commanded jaw angle retraces the recorded jaw angle from the
instant control engages: p(t) = p0 + (r_d / s) (theta_d(t - t_engage) - theta_d(0)) [m], with s the master's
``mapping.motion_scale`` and r_d the jaw pulley radius (the master commands q = q_anchor + (s / r_d)
(p - p_anchor), :class:`master.mapping.MotionMap`). It feels the rendered jaw force like any device and is
finished when the recording's duration has passed since it engaged. The recording is read on the master's
machine with the slave's reader (the demo runs both on one machine).
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from master.device import MultiAxisState
from teleop.config.schema import Config

__all__ = ["RecordedOperator", "recorded_operator"]


class RecordedOperator:
    """A hand retracing the recorded jaw angle (module docstring).

    Parameters
    ----------
    time : ndarray, shape (n,)
        Recording time [s], from 0.
    jaw_angle : ndarray, shape (n,)
        Recorded jaw angle [rad].
    metres_per_rad : float
        Handle travel per jaw radian, r_d / motion_scale [m/rad] > 0.
    """

    def __init__(self, time: np.ndarray, jaw_angle: np.ndarray, metres_per_rad: float):
        self.time, self.angle = np.asarray(time, dtype=float), np.asarray(jaw_angle, dtype=float)
        self.k = float(metres_per_rad)
        self.duration = float(self.time[-1])
        self.force = 0.0
        self.marker = 0
        self.timeouts = 0
        self._engaged = False
        self._t0: float | None = None
        self._t = 0.0

    @property
    def finished(self) -> bool:
        """The recording's duration has passed since control engaged."""
        return self._t0 is not None and self._t - self._t0 >= self.duration

    def watch(self, T_in: Any, engaged: bool) -> None:
        """Control engaged (the proximal tensions are not used: the hand follows the recording)."""
        self._engaged = bool(engaged)

    def on_console(self, status) -> None:
        """The console's status; the recorded hand never clutches."""

    def read(self, t: float) -> MultiAxisState:
        """The handle position [m] at master time ``t`` [s]."""
        self._t = t
        if self._engaged and self._t0 is None:
            self._t0 = t
        tr = 0.0 if self._t0 is None else min(t - self._t0, self.duration)
        p = self.k * (float(np.interp(tr, self.time, self.angle)) - float(self.angle[0]))
        return MultiAxisState(t=t, positions=(p,))

    def set_force(self, force: float, t: float) -> None:
        """Feel ``force`` [N] (non-finite: 0)."""
        self.force = float(force) if math.isfinite(force) else 0.0

    def set_forces(self, forces, t: float) -> None:
        """Feel the one axis's force [N]."""
        self.set_force(float(list(forces)[0]), t)

    def close(self) -> None:
        self.force = 0.0


def recorded_operator(cfg: Config) -> RecordedOperator:
    """The recorded operator of ``cfg``'s recording (errors of :func:`recorded.detect.recorded_motion`); on a
    single tendon the handle retraces the recorded x_in (the master commands x_in = anchor + s (p - p_anchor))."""
    from recorded.detect import recorded_motion
    t, motion = recorded_motion(cfg)
    r = float(next((j.pulley_radius for j in cfg.instrument.joints), 1.0))   # a tendon: x_in itself
    return RecordedOperator(t, motion, r / float(cfg.master.mapping.motion_scale))
