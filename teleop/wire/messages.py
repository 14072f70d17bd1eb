"""Messages on the wire: frozen dataclasses in SI units, one set for every instrument.

An instrument is a list of axes (config order); an axis is a single tendon or an antagonistic pair
(tendon a, then b). A single-tendon instrument is a one-axis instrument: its Command carries one
target, its Estimate one axis of one tendon. Encoding lives in :mod:`teleop.wire.codec` only. Every field
is finite after decoding (the codec rejects NaN and inf), so consumers can trust them.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum

from estimator.phase import Phase

__all__ = [
    "Side", "Command", "Estimate", "Heartbeat", "SideState", "TendonState", "AxisState", "tendon_estimate",
]


class Side(IntEnum):
    MASTER = 1
    SLAVE = 2


class SideState(IntEnum):
    """What a process is doing, carried in its heartbeat."""

    STARTING = 0
    CALIBRATING = 1
    READY = 2        # slave: calibrated and accepting commands; master: device present
    ENGAGED = 3      # teleoperation active
    SAFE = 4         # watchdog or fault: holding safe
    STOPPING = 5


@dataclass(frozen=True)
class Command:
    """Master -> slave: one target per axis of the instrument, config order.

    seq : int, increments by one per command (uint32 wrap).
    t_master : float [s], master monotonic clock at send (only the master compares it).
    targets : tuple of float, one per axis (1..16): the proximal displacement command ``x_in_cmd`` [m]
        of a single-tendon axis (+ = tendon drawn toward the actuator), the joint angle [rad] of a
        pair (+ turns toward tendon a).
    engaged : bool, the operator is in control (False: slave holds).
    marker : int, experiment/protocol segment tag for recordings (0 = none).
    """

    seq: int
    t_master: float
    targets: tuple[float, ...]
    engaged: bool = True
    marker: int = 0


@dataclass(frozen=True)
class TendonState:
    """One tendon in an Estimate: T_in [N] (load cell), x_in [m] (encoder), T_out_hat [N] (estimated
    distal tension), elongation_hat [m] (estimated tendon elongation), phase."""

    T_in: float
    x_in: float
    T_out_hat: float
    elongation_hat: float
    phase: Phase


@dataclass(frozen=True)
class AxisState:
    """One axis in an Estimate.

    effort_hat : float, the estimated distal load the master renders: ``T_out_hat`` [N] of a single
        tendon, the joint torque ``r (T_out,a - T_out,b)`` [N m] of a pair.
    position_hat : float, the estimated distal position: ``x_out_hat = x_in - elongation_hat`` [m] of a
        single tendon, the joint angle [rad] of a pair.
    tendons : tuple of TendonState, one (a single tendon) or two (a pair: a, then b).
    """

    effort_hat: float
    position_hat: float
    tendons: tuple[TendonState, ...]


@dataclass(frozen=True)
class Estimate:
    """Slave -> master: measured and estimated state of every axis of the instrument.

    seq : int, slave cycle counter.
    cmd_seq : int, seq of the last Command the slave applied (echo, for round-trip latency).
    t_slave : float [s], slave monotonic clock.
    axes : tuple of AxisState, one per axis (1..16), config order.
    profiles : tuple of tuple of float [N], empty or one per tendon (axis 0 first tendon, ...), all of
        one length: tension along each sheath, proximal to distal (decimated).
    """

    seq: int
    cmd_seq: int
    t_slave: float
    axes: tuple[AxisState, ...]
    profiles: tuple[tuple[float, ...], ...] = field(default=())

    @property
    def tendons(self) -> tuple[TendonState, ...]:
        """Every tendon of every axis, in order (axis 0 first tendon, axis 0 second tendon, ...)."""
        return tuple(t for a in self.axes for t in a.tendons)


def tendon_estimate(seq: int, cmd_seq: int, t_slave: float, T_in: float, x_in: float, T_out_hat: float,
                    elongation_hat: float, x_out_hat: float, phase: Phase, profile: tuple[float, ...] = ()) -> Estimate:
    """The Estimate of a single-tendon (one-axis) instrument: one axis of one tendon, ``effort_hat =
    T_out_hat`` [N], ``position_hat = x_out_hat`` [m], the profile (may be empty) as its one profile."""
    tendon = TendonState(T_in, x_in, T_out_hat, elongation_hat, phase)
    return Estimate(seq, cmd_seq, t_slave, (AxisState(T_out_hat, x_out_hat, (tendon,)),),
                    (tuple(profile),) if len(profile) else ())


@dataclass(frozen=True)
class Heartbeat:
    """Either side -> the other, at a fixed rate: liveness and state."""

    side: Side
    seq: int
    t_sender: float
    state: SideState
