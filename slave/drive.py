"""The drive of every simulated rig: motor position loops, encoders and load cells, written once.

Each proximal tendon end has a motor, an encoder and a load cell; a rig holds them for an array of
tendons of any shape (``()`` for the single-tendon rig, ``(n_joints, 2)`` for a joint instrument):

* motor: a first-order position loop toward the command, time constant 1 / (2 pi bandwidth_hz),
  speed-limited, stepped exactly over ``h``:
      dx = clip( (1 - e^{-2 pi f_bw h}) (x_cmd - x),  -v_max h,  +v_max h )                  [m]
* encoder: the motor position quantised to q = 2 pi pulley_radius / encoder_lines_per_rev [m];
* load cell: the true proximal tension plus N(0, load_cell_noise^2) [N], from one numpy Generator
  seeded with ``rig.simulated.sensors.seed`` (drawn in blocks; the same stream whatever the shape).

The settings are checked by :func:`slave.simulated.validate_drive` when a rig is built.
"""
from __future__ import annotations

import math

import numpy as np

from teleop.config.schema import SimulatedRigConfig

__all__ = ["Drive", "NOISE_BLOCK"]

NOISE_BLOCK = 4096       # load-cell noise samples drawn at once (per tendon)


class Drive:
    """Motors, encoders and load cells of an array of tendons (module docstring).

    Parameters
    ----------
    rig : SimulatedRigConfig
        ``rig.simulated.motor`` (bandwidth_hz, max_speed, pulley_radius, encoder_lines_per_rev) and
        ``rig.simulated.sensors`` (load_cell_noise, seed), already validated.
    shape : tuple of int
        Shape of the tendon array; ``()`` gives Python floats in and out.

    Attributes
    ----------
    encoder_resolution : float, q [m].
    """

    def __init__(self, rig: SimulatedRigConfig, shape: tuple[int, ...] = ()):
        m = rig.motor
        self.shape = tuple(shape)
        self._omega = 2.0 * math.pi * m.bandwidth_hz
        self._vmax = float(m.max_speed)
        self.encoder_resolution = 2.0 * math.pi * m.pulley_radius / m.encoder_lines_per_rev
        self._sigma = float(rig.sensors.load_cell_noise)
        self._rng = np.random.default_rng(rig.sensors.seed)
        self._noise = self._rng.standard_normal((NOISE_BLOCK, *self.shape))
        self._k = 0

    def move(self, x, cmd, h: float):
        """Motor displacement over ``h`` [s] from ``x`` toward ``cmd`` [m] (module docstring); float or
        ndarray of :attr:`shape`."""
        gain, vmax_dt = self.motor_step(h)
        if not self.shape:
            dx = gain * (cmd - x)
            return vmax_dt if dx > vmax_dt else -vmax_dt if dx < -vmax_dt else dx
        return np.clip(gain * (cmd - x), -vmax_dt, vmax_dt)

    def motor_step(self, h: float) -> tuple[float, float]:
        """The motor loop's exact step over ``h`` [s]: (gain 1 - e^{-2 pi f_bw h}, speed limit v_max h [m]);
        :meth:`move` is ``clip(gain (cmd - x), -v_max h, v_max h)``."""
        return -math.expm1(-self._omega * h), self._vmax * h

    def encoder(self, x):
        """Encoder reading of motor position ``x`` [m]: ``q round(x / q)``."""
        q = self.encoder_resolution
        return q * round(x / q) if not self.shape else q * np.round(x / q)

    def load_cell_noise(self):
        """The next load-cell noise sample [N], float or ndarray of :attr:`shape`."""
        if self._k == NOISE_BLOCK:
            self._noise = self._rng.standard_normal((NOISE_BLOCK, *self.shape))
            self._k = 0
        n = self._noise[self._k]
        self._k += 1
        return self._sigma * float(n) if not self.shape else self._sigma * n
