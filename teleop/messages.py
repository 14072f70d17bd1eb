"""Messages on the wire: frozen dataclasses in SI units.

Encoding lives in :mod:`teleop.codec` only. Every field is finite after decoding (the codec rejects
NaN and inf), so consumers can trust them.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum

from estimator.phase import Phase

__all__ = ["Phase", "Side", "Command", "Estimate", "Heartbeat", "SideState", "JointCommand", "TendonState", "JointState",
           "JointEstimate"]


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
    """Master -> slave: proximal tendon displacement command.

    seq : int, increments by one per command (uint32 wrap).
    t_master : float [s], master monotonic clock at send (only the master compares it).
    x_in_cmd : float [m], proximal displacement command, + = tendon drawn toward the actuator.
    engaged : bool, the operator is in control (False: slave holds).
    marker : int, experiment/protocol segment tag for recordings (0 = none).
    """

    seq: int
    t_master: float
    x_in_cmd: float
    engaged: bool = True
    marker: int = 0


@dataclass(frozen=True)
class Estimate:
    """Slave -> master: measured proximal state and estimated distal state.

    seq : int, slave cycle counter.
    cmd_seq : int, seq of the last command the slave applied (echo, for round-trip latency).
    t_slave : float [s], slave monotonic clock.
    T_in : float [N], proximal tension (load cell).
    x_in : float [m], proximal displacement (encoder).
    T_out_hat : float [N], estimated distal tension.
    elongation_hat : float [m], estimated tendon elongation.
    x_out_hat : float [m], estimated distal displacement = x_in - elongation_hat.
    phase : Phase.
    profile : tuple of float [N], tension along the sheath, proximal to distal (may be empty).
    """

    seq: int
    cmd_seq: int
    t_slave: float
    T_in: float
    x_in: float
    T_out_hat: float
    elongation_hat: float
    x_out_hat: float
    phase: Phase
    profile: tuple[float, ...] = field(default=())


@dataclass(frozen=True)
class Heartbeat:
    """Either side -> the other, at a fixed rate: liveness and state."""

    side: Side
    seq: int
    t_sender: float
    state: SideState


# ---- joint instruments (1..4 antagonistic pairs, config instrument.joints) -------------------------

@dataclass(frozen=True)
class JointCommand:
    """Master -> slave: joint-angle commands of a joint instrument, every joint in config order.

    seq : int, increments by one per command (uint32 wrap).
    t_master : float [s], master monotonic clock at send.
    angles : tuple of float [rad], one per joint (1..4); + turns toward tendon a.
    engaged : bool, the operator is in control (False: the slave holds).
    marker : int, experiment/protocol segment tag for recordings (0 = none).
    """

    seq: int
    t_master: float
    angles: tuple[float, ...]
    engaged: bool = True
    marker: int = 0


@dataclass(frozen=True)
class TendonState:
    """One tendon in a JointEstimate: T_in [N] (load cell), x_in [m] (encoder), T_out_hat [N],
    elongation_hat [m], phase."""

    T_in: float
    x_in: float
    T_out_hat: float
    elongation_hat: float
    phase: Phase


@dataclass(frozen=True)
class JointState:
    """One joint in a JointEstimate: torque_hat [N m] = r (T_out,a - T_out,b), angle_hat [rad],
    tendons (a, b)."""

    torque_hat: float
    angle_hat: float
    tendons: tuple[TendonState, TendonState]


@dataclass(frozen=True)
class JointEstimate:
    """Slave -> master: measured and estimated state of every joint of a joint instrument.

    seq : int, slave cycle counter.
    cmd_seq : int, seq of the last JointCommand the slave applied (echo, for round-trip latency).
    t_slave : float [s], slave monotonic clock.
    joints : tuple of JointState, one per joint (1..4), config order.
    profiles : tuple of tuple of float [N], empty or one per tendon (joint 0 a, joint 0 b, joint 1 a,
        ...), all of one length: tension along each sheath, proximal to distal (decimated).
    """

    seq: int
    cmd_seq: int
    t_slave: float
    joints: tuple[JointState, ...]
    profiles: tuple[tuple[float, ...], ...] = field(default=())
