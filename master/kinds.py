"""The master's registry of instrument kinds (:func:`teleop.config.kinds.instrument_kind` names the kind): per kind
the master's axes (:mod:`master.axes`), the scripted operator's protocols (:mod:`master.protocols`), the number of
device axes it needs and the description of its CSV columns.

A joint (a degree of freedom of the instrument) is commanded as an angle whatever its transmission: the
``pair`` and ``spindle`` kinds share :class:`master.axes.JointAxes`; a single tendon is commanded as a
displacement (:class:`master.axes.TendonAxes`).
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from master.axes import InstrumentAxes, JointAxes, TendonAxes
from master.protocols import Segment, build_protocol, joint_protocols
from teleop.config.kinds import instrument_kind, unknown_kind
from teleop.config.schema import Config

__all__ = ["MasterKind", "MASTER_KINDS", "master_kind", "instrument_axes", "operator_protocols"]


@dataclass(frozen=True)
class MasterKind:
    """What the master builds for one kind of instrument.

    Attributes
    ----------
    axes : (cfg) -> InstrumentAxes
    protocols : (cfg, names) -> list of protocols, one per axis; raises ConfigError on a name that is not a
        protocol of the kind.
    device_axes : (cfg) -> int
        How many device axes the instrument needs.
    columns : str
        What the master's CSV columns hold (its metadata).
    """
    axes: Callable[[Config], InstrumentAxes]
    protocols: Callable[[Config, str], list[tuple[Segment, ...]]]
    device_axes: Callable[[Config], int]
    columns: str


def _joint_device_axes(cfg: Config) -> int:
    return max(cfg.pair_control.axes) + 1 if cfg.pair_control.axes else len(cfg.instrument.joints)


_TENDON = MasterKind(lambda cfg: TendonAxes(), lambda cfg, names: [build_protocol(names)], lambda cfg: 1,
                     "x_in = command sent, T_in = slave's latest proximal tension, force = rendered")
_JOINTS = MasterKind(JointAxes, joint_protocols, _joint_device_axes,
                     "per joint: cmd, slave angle [rad], device position [m], rendered tension torque_hat / r [N], "
                     "forces [N], passivity energy [J]")

#: kind -> what the master builds for it
MASTER_KINDS: dict[str, MasterKind] = {"tendon": _TENDON, "pair": _JOINTS, "spindle": _JOINTS}


def master_kind(kind: str) -> MasterKind:
    """The master's entry of ``kind``. Raises LookupError (one line naming the kind and the kinds) when unknown."""
    try:
        return MASTER_KINDS[kind]
    except KeyError:
        raise unknown_kind(kind, "master.kinds") from None


def instrument_axes(cfg: Config) -> InstrumentAxes:
    """The master's view of the configured instrument (its kind's :attr:`MasterKind.axes`)."""
    return master_kind(instrument_kind(cfg)).axes(cfg)


def operator_protocols(cfg: Config, names: str) -> list[tuple[Segment, ...]]:
    """The protocols of the configured instrument, one per axis (its kind's :attr:`MasterKind.protocols`).

    Raises
    ------
    ConfigError
        A name that is not a protocol of this kind of instrument.
    """
    return master_kind(instrument_kind(cfg)).protocols(cfg, names)
