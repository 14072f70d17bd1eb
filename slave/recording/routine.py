"""What the recorded axes share: their power-up "routine" is the offline fit of the calibration recording, made
at once, and the fitted model lives beside the calibration file.

A recorded axis (:class:`slave.recording.spindle.RecordedSpindleAxis`, :class:`slave.recording.pair.RecordedPairAxis`,
:class:`slave.recording.tendon.RecordedTendonAxis`) puts :class:`RecordedRoutine` first among its bases and names
its routine class (``routine_class``: built from the config, it fits in its constructor and holds ``model``,
``done`` True from the start) and the calibration of a model (``model_calibration(cfg, model)``). The rig cannot
run a calibration motion: the routine's step returns the rig's state unchanged.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, ClassVar

from slave.calibration_file import calibration_path
from slave.rig import Rig, RigState
from teleop.config.schema import Config

__all__ = ["RecordedRoutine", "recorded_model_path"]


def recorded_model_path(cfg: Config) -> Path:
    """``<calibration.dir>/<instrument.id>.recording.json``, beside the calibration file."""
    return calibration_path(cfg).with_suffix(".recording.json")


class RecordedRoutine:
    """The calibration class methods of a recorded axis (module docstring)."""

    routine_class: ClassVar[Any]          # (cfg) -> the fitted routine: ``model``, ``done``
    model_calibration: ClassVar[Any]      # staticmethod (cfg, model) -> the slave's calibration data

    @classmethod
    def routine(cls, cfg: Config, rig: Rig) -> Any:
        """The fit of the calibration recording (``routine_class(cfg)``), done at once."""
        return cls.routine_class(cfg)

    @classmethod
    def routine_step(cls, routine: Any, rig: Rig, state: RigState, dt: float) -> RigState:
        """No motion: the recording plays on whatever the slave commands."""
        return rig.state

    @classmethod
    def calibration_of(cls, cfg: Config, routine: Any) -> Any:
        """The slave's calibration data of the routine's fitted model."""
        return cls.model_calibration(cfg, routine.model)
