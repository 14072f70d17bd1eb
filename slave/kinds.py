"""The slave's registry of instrument kinds (:func:`teleop.config.kinds.instrument_kind` names the kind): per kind
the slave's axis (its estimator, pair control and calibration routine, :class:`slave.axis.SlaveAxis`), the
simulated rig and the networked rig (``rig.type: zenoh``).

================  ===================================  ==========================================  ===================
kind              axis                                 simulated rig                               networked rig
================  ===================================  ==========================================  ===================
``tendon``        :class:`slave.tendon_axis.TendonAxis`  :class:`slave.simulated.SimulatedRig`      ``ZenohRig``
``pair``          :class:`slave.pair_axis.PairAxis`      :class:`slave.pair_rig.SimulatedInstrument` ``ZenohInstrument``
``spindle``       :class:`slave.spindle_axis.SpindleAxis` :class:`slave.spindle_rig.SpindleInstrument` none
================  ===================================  ==========================================  ===================

A rig that brings its own axis (a recording, :mod:`slave.recording`) names it as ``rig.axis_kind``. Another
kind is one :class:`SlaveKind` entry here, with its entries in :mod:`master.kinds` and :mod:`live.kinds`.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from teleop.config.kinds import instrument_kind, unknown_kind
from teleop.config.schema import Config
from teleop.errors import ConfigError

if TYPE_CHECKING:
    from slave.axis import SlaveAxis

__all__ = ["SlaveKind", "SLAVE_KINDS", "slave_kind", "axis_kind"]


@dataclass(frozen=True)
class SlaveKind:
    """What the slave builds for one kind of instrument; each a factory that imports its module when called.

    Attributes
    ----------
    axis : () -> type[SlaveAxis]
        The axis class (estimator, control and calibration routine of every joint of the kind).
    simulated : (cfg) -> Rig
        The in-process simulator of ``rig.type: simulated``.
    networked : (session, cfg) -> Rig
        The rig of ``rig.type: zenoh``; raises ConfigError when the kind has none.
    """
    axis: Callable[[], type[SlaveAxis]]
    simulated: Callable[[Config], Any]
    networked: Callable[[Any, Config], Any]


def _tendon_axis() -> type[SlaveAxis]:
    from slave.tendon_axis import TendonAxis
    return TendonAxis


def _pair_axis() -> type[SlaveAxis]:
    from slave.pair_axis import PairAxis
    return PairAxis


def _spindle_axis() -> type[SlaveAxis]:
    from slave.spindle_axis import SpindleAxis
    return SpindleAxis


def _tendon_sim(cfg: Config) -> Any:
    from slave.simulated import SimulatedRig
    return SimulatedRig.from_config(cfg)


def _pair_sim(cfg: Config) -> Any:
    from slave.pair_rig import SimulatedInstrument
    return SimulatedInstrument.from_config(cfg)


def _spindle_sim(cfg: Config) -> Any:
    from slave.spindle_rig import SpindleInstrument
    return SpindleInstrument.from_config(cfg)


def _tendon_zenoh(session: Any, cfg: Config) -> Any:
    from slave.zenoh_rig import ZenohRig
    return ZenohRig(session, cfg)


def _pair_zenoh(session: Any, cfg: Config) -> Any:
    from slave.zenoh_rig import ZenohInstrument
    return ZenohInstrument(session, cfg)


def _spindle_zenoh(session: Any, cfg: Config) -> Any:
    raise ConfigError("rig.type zenoh drives a motor per tendon; a spindle-driven instrument "
                      "(instrument.joints[].spindle_radius > 0) runs on rig.type simulated")


#: kind -> what the slave builds for it
SLAVE_KINDS: dict[str, SlaveKind] = {
    "tendon": SlaveKind(_tendon_axis, _tendon_sim, _tendon_zenoh),
    "pair": SlaveKind(_pair_axis, _pair_sim, _pair_zenoh),
    "spindle": SlaveKind(_spindle_axis, _spindle_sim, _spindle_zenoh),
}


def slave_kind(kind: str) -> SlaveKind:
    """The slave's entry of ``kind``. Raises LookupError (one line naming the kind and the kinds) when unknown."""
    try:
        return SLAVE_KINDS[kind]
    except KeyError:
        raise unknown_kind(kind, "slave.kinds") from None


def axis_kind(cfg: Config) -> type[SlaveAxis]:
    """The axis class of the configured instrument (errors of :func:`teleop.config.kinds.instrument_kind`)."""
    return slave_kind(instrument_kind(cfg)).axis()
