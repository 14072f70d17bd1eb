"""The live session's registry of instrument kinds (:func:`teleop.config.kinds.instrument_kind` names the kind): per
kind the demo's evaluation, what ``teleop replay`` does with its runs, the Rerun view's 3D sheath and the names the
demo's summary uses.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from teleop.config.kinds import instrument_kind, unknown_kind
from teleop.config.schema import Config

__all__ = ["LiveKind", "LIVE_KINDS", "live_kind", "kind_of"]


@dataclass(frozen=True)
class LiveKind:
    """What the live session does for one kind of instrument.

    Attributes
    ----------
    demo : ``"tendon"`` or ``"joints"``
        The demo's evaluation of a run (:data:`live.demo.main.DEMOS`: :class:`live.demo.main.TendonDemo`,
        :class:`live.demo.joints.JointDemo`).
    replay : ``"tendon"`` or ``"joints"``
        Which replay re-estimates the kind's runs (:mod:`live.replay.main`, :mod:`live.replay.joints`).
    replay_refusal : str or None
        Why ``teleop replay`` cannot re-estimate the kind's runs (None: it can).
    sheath_view : bool
        The Rerun view shows the sheath's route in 3D (a single tendon's ``sheath.runs``).
    summary : str
        The kind's word in the demo's summary (``tendon`` or ``joints``).
    slave_file : str
        The slave's CSV of a run.
    """
    demo: str
    replay: str
    replay_refusal: str | None
    sheath_view: bool
    summary: str
    slave_file: str


_SPINDLE_REFUSAL = ("spindle-driven; teleop replay re-estimates from per-cable load cells, which a spindle instrument "
                    "does not have")

#: kind -> what the live session does for it
LIVE_KINDS: dict[str, LiveKind] = {
    "tendon": LiveKind("tendon", "tendon", None, True, "tendon", "slave.csv"),
    "pair": LiveKind("joints", "joints", None, False, "joints", "slave_joints.csv"),
    "spindle": LiveKind("joints", "joints", _SPINDLE_REFUSAL, False, "joints", "slave_joints.csv"),
}


def live_kind(kind: str) -> LiveKind:
    """The live session's entry of ``kind``. Raises LookupError (one line naming the kind and the kinds) when
    unknown."""
    try:
        return LIVE_KINDS[kind]
    except KeyError:
        raise unknown_kind(kind, "live.kinds") from None


def kind_of(cfg: Config) -> Any:
    """The live session's entry of the configured instrument's kind."""
    return live_kind(instrument_kind(cfg))
