"""The phase of a tendon-sheath transmission (Phee et al. 2009, Sec. III): which law links the distal to the proximal
tension right now. Its readable classifier over a live estimate is :mod:`estimator.readable_phase`.
"""
from __future__ import annotations

from enum import IntEnum

__all__ = ["Phase"]


class Phase(IntEnum):
    """Which law links the distal to the proximal tension right now.

    HOLD            : proximal tension steady, distal end stuck.
    PULL            : slipping toward the actuator, T_out = T_in e^-K (eq. (1)).
    RELEASE         : slipping toward the tip, T_out = T_in e^+K (eq. (22)).
    PULL_TO_RELEASE : proximal tension falling, distal end stuck (T_out held, eqs. (14)-(21)).
    RELEASE_TO_PULL : proximal tension rising, distal end stuck (T_out held, eqs. (24)-(25)).
    """

    HOLD = 0
    PULL = 1
    RELEASE = 2
    PULL_TO_RELEASE = 3
    RELEASE_TO_PULL = 4

    @property
    def label(self) -> str:
        return {0: "hold", 1: "pull", 2: "release", 3: "pull->release", 4: "release->pull"}[int(self)]
