"""Master-side mapping: device motion -> tendon command, estimated distal tension -> device force.

Motion (:class:`MotionMap`), with ``s`` = ``motion_scale`` [-]::

    x_in_cmd = x_anchor + s (p - p_anchor)

The anchor pair (device position ``p_anchor`` [m], tendon displacement ``x_anchor`` [m]) is set on
engage from the slave's current ``x_in``, so engaging never makes the tendon jump. A clutch is the
same operation: while it is open the command holds; :meth:`MotionMap.anchor` re-anchors,
:meth:`MotionMap.resume` closes it again on the kept anchor. :mod:`master.console` decides which
(clutch button, deadman, alignment).

Force (:class:`ForceMap`), applied in this order every cycle::

    F_target = -force_scale * T_out_hat                      opposes the pull           [N]
    F_target *= min(1, (t - t_ramp) / ramp_time)             ramp-in after (re)engage
    F_target  = clip(F_target, -force_limit, +force_limit)   saturation
    F         = F_prev + clip(F_target - F_prev, -r dt, +r dt)   slew limit r = force_rate_limit [N/s]

and ``F = 0`` at once (no slew) when disengaged, when the estimate is stale or when any input is
NaN/inf; the ramp then starts again from zero on the next fresh estimate. Removing force is always
the safe direction, so a fault cuts it without slew; in normal operation every change is
slew-limited (smooth rendering). The returned force is finite and within
``[-force_limit, force_limit]`` for every input.
"""
from __future__ import annotations

import math

from teleop.config.schema import MappingConfig
from teleop.errors import ConfigError

__all__ = ["clamp_force", "MotionMap", "ForceMap"]


def clamp_force(force: float, limit: float) -> float:
    """``force`` [N] clipped to ``[-limit, limit]``; 0 when ``force`` is NaN or inf."""
    if not math.isfinite(force):
        return 0.0
    return max(-limit, min(limit, float(force)))


def _positive(name: str, value: float, allow_zero: bool = False) -> float:
    ok = math.isfinite(value) and (value >= 0 if allow_zero else value > 0)
    if isinstance(value, bool) or not ok:
        bound = ">= 0" if allow_zero else "> 0"
        raise ConfigError(f"master.mapping.{name} must be a finite number {bound}, got {value!r}")
    return float(value)


class MotionMap:
    """Device position [m] -> proximal tendon displacement command [m] by scaling about an anchor.

    Parameters
    ----------
    motion_scale : float
        Tendon displacement per device displacement [-], finite and > 0.

    Raises
    ------
    ConfigError
        ``motion_scale`` not finite or not > 0.
    """

    def __init__(self, motion_scale: float):
        self.scale = _positive("motion_scale", motion_scale)
        self.p_anchor = 0.0
        self.x_anchor = 0.0
        self.anchored = False
        self.last = 0.0            # last command [m]

    def anchor(self, position: float, x_in: float) -> None:
        """Close the clutch: from now on ``position`` [m] maps to ``x_in`` [m].

        Raises
        ------
        ValueError
            ``position`` or ``x_in`` not finite (the previous anchor is kept).
        """
        if not (math.isfinite(position) and math.isfinite(x_in)):
            raise ValueError(f"cannot anchor the motion map at position={position!r} m, x_in={x_in!r} m")
        self.p_anchor, self.x_anchor = float(position), float(x_in)
        self.last = self.x_anchor
        self.anchored = True

    def open_clutch(self) -> None:
        """Decouple: :meth:`command` holds the last command until :meth:`anchor` or :meth:`resume`."""
        self.anchored = False

    def resume(self) -> None:
        """Couple again on the kept anchor pair (the caller has checked the alignment)."""
        self.anchored = True

    def target(self, position: float) -> float:
        """Where ``position`` [m] maps with the present anchor [m], coupled or not (NaN in, NaN out)."""
        # x_in_cmd = x_anchor + s (p - p_anchor)
        return self.x_anchor + self.scale * (position - self.p_anchor)

    def command(self, position: float) -> float:
        """The displacement command [m] for device ``position`` [m].

        Holds the last command while the clutch is open or when ``position`` is NaN/inf.
        """
        if self.anchored and math.isfinite(position):
            # x_in_cmd = x_anchor + s (p - p_anchor)
            self.last = self.x_anchor + self.scale * (position - self.p_anchor)
        return self.last


class ForceMap:
    """Estimated distal tension [N] -> safe device force [N] (see the module docstring).

    Parameters
    ----------
    force_scale : float
        Device force per distal tension [-], finite and >= 0.
    force_limit : float
        Saturation of the device force [N], finite and > 0.
    ramp_time : float
        Duration of the linear ramp-in after engage [s], finite and >= 0 (0 = no ramp).
    force_rate_limit : float
        Slew limit of the device force [N/s], finite and > 0.

    Raises
    ------
    ConfigError
        A parameter out of its range (the message names the config key).
    """

    def __init__(self, force_scale: float, force_limit: float, ramp_time: float, force_rate_limit: float):
        self.scale = _positive("force_scale", force_scale, allow_zero=True)
        self.limit = _positive("force_limit", force_limit)
        self.ramp_time = _positive("ramp_time", ramp_time, allow_zero=True)
        self.rate_limit = _positive("force_rate_limit", force_rate_limit)
        self.force = 0.0                  # last output [N]
        self.engaged = False
        self._t_ramp: float | None = None  # start of the current ramp [s]; None: starts on next fresh step
        self._t_last: float | None = None

    @classmethod
    def from_config(cls, cfg: MappingConfig) -> ForceMap:
        """Build from the ``master.mapping`` section."""
        return cls(cfg.force_scale, cfg.force_limit, cfg.ramp_time, cfg.force_rate_limit)

    def engage(self) -> None:
        """Start rendering: the ramp begins at the next fresh :meth:`step`."""
        self.engaged = True
        self._t_ramp = None

    def disengage(self) -> None:
        """Stop rendering: force 0 from now on, until :meth:`engage`."""
        self.engaged = False
        self._cut()

    def _cut(self) -> float:
        self.force = 0.0
        self._t_ramp = None
        return 0.0

    def ramp_gain(self, t: float) -> float:
        """The ramp factor in [0, 1] at time ``t`` [s] (0 before the ramp has started)."""
        if self._t_ramp is None or not math.isfinite(t):
            return 0.0
        if self.ramp_time == 0.0:
            return 1.0
        return min(1.0, max(0.0, (t - self._t_ramp) / self.ramp_time))

    def step(self, T_out_hat: float, t: float, fresh: bool = True) -> float:
        """The device force [N] for estimated distal tension ``T_out_hat`` [N] at time ``t`` [s].

        Parameters
        ----------
        T_out_hat : float
            Latest estimated distal tension [N]; NaN/inf gives 0 N and restarts the ramp.
        t : float
            Current time [s] (master clock); NaN/inf gives 0 N.
        fresh : bool
            False when the estimate is stale or the peer is gone: 0 N at once, ramp restarts.

        Returns
        -------
        float
            Finite force [N] in ``[-force_limit, force_limit]``.
        """
        t_last, self._t_last = self._t_last, t
        if not (self.engaged and fresh and math.isfinite(T_out_hat) and math.isfinite(t)):
            return self._cut()
        if self._t_ramp is None:
            self._t_ramp = t
        # F_target = -force_scale T_out_hat, ramped in, saturated
        target = clamp_force(-self.scale * T_out_hat * self.ramp_gain(t), self.limit)
        dt = 0.0 if t_last is None or not math.isfinite(t_last) else max(0.0, t - t_last)
        # slew limit: |dF| <= force_rate_limit dt
        dmax = self.rate_limit * dt
        force = self.force + max(-dmax, min(dmax, target - self.force))
        self.force = clamp_force(force, self.limit)
        return self.force
