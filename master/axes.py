"""The instrument as the master sees it: a list of axes, each a single tendon or an antagonistic pair.

One :class:`master.node.MasterNode` serves every instrument; what differs between a single tendon
and a joint instrument is only what an axis reads from the slave's estimate and how its commands
are packed. An axis k has

* a *slave position* ``q_k`` - the proximal displacement ``x_in`` [m] of a tendon, or the estimated
  joint angle ``angle_hat`` [rad] of a pair - onto which the device handle is mapped,
  ``q_cmd = q_anchor + s_k (p - p_anchor)`` with ``s_k = motion_scale`` [m/m] for a tendon and
  ``motion_scale / r`` [rad/m] for a joint of pulley radius r (a device displacement moves a tendon
  by ``motion_scale`` times it either way);
* a *rendered tension* ``T_k`` [N]: the estimated distal tension ``T_out_hat`` of a tendon, or the
  net distal tension difference ``torque_hat / r`` of a pair; the device renders
  ``-force_scale T_k`` (:class:`master.mapping.ForceMap`);
* an alignment tolerance ``align_tolerance / r_k`` in its own unit (``r_k`` = 1 for a tendon), so
  that every axis is aligned to the same tendon displacement;
* a device axis (``pair_control.axes`` for a joint instrument, default axis k; axis 0 for a tendon).

:func:`master.kinds.instrument_axes` picks them by the instrument's kind (:mod:`master.kinds`). A
spindle-driven jaw (``spindle_radius`` > 0) is a joint here: the slave sends its jaw torque and angle
and takes jaw-angle commands, r being its jaw pulley's radius.
"""
from __future__ import annotations

from typing import Any

from teleop.config.schema import Config
from teleop.wire.messages import Command, Estimate

__all__ = ["InstrumentAxes", "TendonAxes", "JointAxes", "TENDON_CSV_COLUMNS", "TENDON_CSV_UNITS"]

#: The single tendon's master recording, one row per cycle (measured-data format: x_in is the command
#: sent, T_in the slave's latest accepted proximal tension, 0 before any).
TENDON_CSV_COLUMNS = ("time", "x_in", "T_in", "position", "T_out_hat", "force_cmd", "force", "energy", "state",
                      "console", "t_est_recv", "echo_age", "cmd_seq")
TENDON_CSV_UNITS = {"position": "m", "T_out_hat": "N", "force_cmd": "N", "force": "N", "energy": "J",
                    "state": "SideState", "console": "ConsoleStatus", "t_est_recv": "s", "echo_age": "s",
                    "cmd_seq": "-"}
_COMMON = ("state", "console", "t_est_recv", "echo_age", "cmd_seq", "marker")
_AXIS_COLS = ("cmd", "slave", "position", "tension", "force_cmd", "force", "energy")


class InstrumentAxes:
    """What differs between instruments, for the master (module docstring).

    Attributes
    ----------
    names : tuple of str, one per axis.
    radius : tuple of float, tendon displacement per unit of the axis [m/unit] (1 for a tendon, r for
        a joint [m/rad]).
    device_axes : tuple of int, the device axis of each instrument axis.
    unit : str, the unit of the slave position (``m`` or ``rad``).
    """

    names: tuple[str, ...] = ()
    radius: tuple[float, ...] = ()
    device_axes: tuple[int, ...] = ()
    unit = "m"

    @property
    def n(self) -> int:
        return len(self.names)

    def fits(self, est: Any) -> bool:
        """Whether ``est`` is an estimate of this instrument (kind and number of axes)."""
        raise NotImplementedError

    def tensions(self, est: Any) -> tuple[float, ...]:
        """Every measured or estimated tension of ``est`` [N] (checked against ``master.max_tension``)."""
        raise NotImplementedError

    def slave_positions(self, est: Any) -> list[float]:
        """q_k per axis (module docstring) [m or rad]."""
        raise NotImplementedError

    def rendered(self, est: Any) -> list[float]:
        """T_k per axis [N], the tension the device renders (module docstring)."""
        raise NotImplementedError

    def view(self, est: Any) -> Any:
        """What a simulated operator watches: per axis the proximal tension of each tendon (a tuple),
        None before any estimate."""
        raise NotImplementedError

    def command(self, seq: int, now: float, q: list[float], engaged: bool, marker: int):
        """The wire command carrying ``q`` (one value per axis)."""
        raise NotImplementedError

    def csv_columns(self) -> tuple[str, ...]:
        """Columns of the master's recording."""
        raise NotImplementedError

    def csv_units(self) -> dict[str, str]:
        """Units of the recording's columns."""
        raise NotImplementedError

    def csv_row(self, now: float, est: Any, common: tuple, axes: list[tuple]) -> tuple:
        """One recording row: ``common`` = (state, console, t_est_recv, echo_age, cmd_seq, marker),
        ``axes`` = per axis (cmd, slave position, device position, rendered tension, force_cmd, force,
        energy)."""
        raise NotImplementedError


class TendonAxes(InstrumentAxes):
    """A single tendon: one axis, commanded in ``x_in`` [m], rendering ``T_out_hat`` [N]."""

    names = ("tendon",)
    radius = (1.0,)
    device_axes = (0,)
    unit = "m"

    def fits(self, est: Any) -> bool:
        return isinstance(est, Estimate) and len(est.axes) == 1 and len(est.axes[0].tendons) == 1

    def tensions(self, est: Estimate) -> tuple[float, ...]:
        t = est.axes[0].tendons[0]
        return (t.T_in, t.T_out_hat)

    def slave_positions(self, est: Estimate) -> list[float]:
        return [est.axes[0].tendons[0].x_in]

    def rendered(self, est: Estimate) -> list[float]:
        return [est.axes[0].tendons[0].T_out_hat]

    def view(self, est: Estimate | None):
        return None if est is None else [(est.axes[0].tendons[0].T_in,)]

    def command(self, seq: int, now: float, q: list[float], engaged: bool, marker: int) -> Command:
        return Command(seq, now, (q[0],), engaged, marker)

    def csv_columns(self) -> tuple[str, ...]:
        return TENDON_CSV_COLUMNS

    def csv_units(self) -> dict[str, str]:
        return dict(TENDON_CSV_UNITS)

    def csv_row(self, now: float, est: Estimate | None, common: tuple, axes: list[tuple]) -> tuple:
        cmd, _, p, T, f_cmd, f, energy = axes[0]
        state, console, t_recv, echo_age, cmd_seq, _ = common
        T_in = 0.0 if est is None else est.axes[0].tendons[0].T_in
        return (now, cmd, T_in, p, T, f_cmd, f, energy, state, console, t_recv, echo_age, cmd_seq)


class JointAxes(InstrumentAxes):
    """A joint instrument: one axis per antagonistic pair, commanded in angle [rad], rendering the net
    distal tension ``torque_hat / r`` [N].

    Parameters
    ----------
    cfg : Config with ``instrument.joints`` (names, pulley radii) and ``pair_control.axes``.
    """

    unit = "rad"

    def __init__(self, cfg: Config):
        joints = cfg.instrument.joints
        self.names = tuple(j.name for j in joints)
        self.radius = tuple(float(j.pulley_radius) for j in joints)
        self.device_axes = tuple(cfg.pair_control.axes) or tuple(range(len(joints)))

    def fits(self, est: Any) -> bool:
        return (isinstance(est, Estimate) and len(est.axes) == self.n
                and all(len(a.tendons) == 2 for a in est.axes))

    def tensions(self, est: Estimate) -> tuple[float, ...]:
        return tuple(v for t in est.tendons for v in (t.T_in, t.T_out_hat))

    def slave_positions(self, est: Estimate) -> list[float]:
        return [a.position_hat for a in est.axes]

    def rendered(self, est: Estimate) -> list[float]:
        return [a.effort_hat / r for a, r in zip(est.axes, self.radius, strict=False)]

    def view(self, est: Estimate | None):
        return None if est is None else [(a.tendons[0].T_in, a.tendons[1].T_in) for a in est.axes]

    def command(self, seq: int, now: float, q: list[float], engaged: bool, marker: int) -> Command:
        return Command(seq, now, tuple(q), engaged, marker)

    def csv_columns(self) -> tuple[str, ...]:
        return ("time", *_COMMON) + tuple(f"{n}.{c}" for n in self.names for c in _AXIS_COLS)

    def csv_units(self) -> dict[str, str]:
        units = {"state": "SideState", "console": "ConsoleStatus", "t_est_recv": "s", "echo_age": "s",
                 "cmd_seq": "-", "marker": "-"}
        for n in self.names:
            units.update({f"{n}.cmd": "rad", f"{n}.slave": "rad", f"{n}.position": "m", f"{n}.tension": "N",
                          f"{n}.force_cmd": "N", f"{n}.force": "N", f"{n}.energy": "J"})
        return units

    def csv_row(self, now: float, est: Estimate | None, common: tuple, axes: list[tuple]) -> tuple:
        return (now, *common, *(v for a in axes for v in a))
