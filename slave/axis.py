"""One axis of an instrument, as the slave node drives it: the interface every kind of axis implements.

An instrument is a list of axes (docs/concepts/architecture.md): a single tendon is a one-axis instrument
(:class:`slave.tendon_axis.TendonAxis`: a motor position command, the distal tension and the
elongation estimated with the tension-profile memory, :mod:`estimator.online.distal`); a joint
instrument has one axis per antagonistic pair (:class:`slave.pair_axis.PairAxis`: a joint-angle
command through the pair controller, the distal joint torque and angle estimated by
:mod:`estimator.online.pair`); a spindle instrument has one axis per spindle-driven jaw
(:class:`slave.spindle_axis.SpindleAxis`: a jaw-angle command turning the spindle, the jaw torque and
angle estimated from the spindle's angle and torque by the spindle pair model).
:class:`slave.node.SlaveNode` iterates over them; all axes of one instrument are of one kind, because
the rig's tendon shape (:mod:`slave.rig`) is ``()`` for a single tendon, ``(n_joints, 2)`` for pairs
and ``(n_joints,)`` (one spindle each) for spindles.

Per axis (instance methods): the checks of an incoming target (:meth:`SlaveAxis.out_of_range`,
:meth:`SlaveAxis.too_far`), the motor command of one cycle (:meth:`SlaveAxis.motor`), the estimator
step turning the rig's proximal samples into the axis's :class:`~teleop.wire.messages.AxisState`
(:meth:`SlaveAxis.observe`), its Rerun series (:meth:`SlaveAxis.log_rerun`).

Per kind (class methods, because the routine, the calibration file and the recording's layout are
the instrument's): the axes of a config (:meth:`SlaveAxis.build`), the power-up calibration routine
(:meth:`SlaveAxis.routine`, :meth:`SlaveAxis.routine_step`, :meth:`SlaveAxis.calibration_of`; also
``teleop calibrate``) and what its end or a reloaded calibration starts
(:meth:`SlaveAxis.finish_routine`, :meth:`SlaveAxis.start_loaded`), the rig command of the axes'
motor commands (:meth:`SlaveAxis.rig_command`), the recording (:meth:`SlaveAxis.recording`,
:meth:`SlaveAxis.csv_row`), the summary counters (:meth:`SlaveAxis.stats`) and the warm-up of the
compiled kernels (:meth:`SlaveAxis.warm_up`).
"""
from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from slave.rig import Rig, RigState
from teleop.config.schema import Config
from teleop.wire.messages import AxisState

__all__ = ["SlaveAxis"]


class SlaveAxis:
    """One axis of the instrument on the slave (module docstring). Subclasses implement every method.

    Attributes
    ----------
    cfg : Config
        The run's config.
    name : str
        The axis's name (``tendon``, or the joint's name).
    index : int
        Its place in the instrument (the row of the rig's ``(n_joints, 2)`` arrays of a pair).
    tendon_per_unit : float
        Tendon travel per unit of the axis's target [m per m, or m/rad: the distal pulley's radius]: the
        scale of ``slave.engage_tolerance``, ``slave.max_step`` and ``slave.max_speed`` on this axis.
    """

    name = "axis"
    index = 0
    tendon_per_unit = 1.0
    #: What the kind's power-up routine does to the instrument, for the messages that announce it.
    routine_text = "the power-up calibration routine"
    cfg: Config

    # ---- per kind ----------------------------------------------------------------------------------
    @classmethod
    def build(cls, cfg: Config, rig: Rig) -> list[SlaveAxis]:
        """The axes of the configured instrument, before any calibration."""
        raise NotImplementedError

    @classmethod
    def routine(cls, cfg: Config, rig: Rig) -> Any:
        """The power-up calibration routine (``done`` once fitted), run by :meth:`routine_step`."""
        raise NotImplementedError

    @classmethod
    def routine_step(cls, routine: Any, rig: Rig, state: RigState, dt: float) -> RigState:
        """One cycle of the routine: its command to the rig for ``dt`` [s], the rig's new state (which
        the routine sees when it keeps its own samples)."""
        raise NotImplementedError

    @classmethod
    def calibration_of(cls, cfg: Config, routine: Any) -> Any:
        """The finished routine's fit as calibration data (:class:`~slave.calibration_file.InstrumentCalibration`)."""
        raise NotImplementedError

    @classmethod
    def finish_routine(cls, axes: Sequence[SlaveAxis], routine: Any, state: RigState) -> tuple[Any, dict]:
        """Start the axes on the routine's fit (their estimators replay its proximal samples).

        Returns (:class:`~slave.calibration_file.InstrumentCalibration`, calibration.json contents)."""
        raise NotImplementedError

    @classmethod
    def start_loaded(cls, axes: Sequence[SlaveAxis], calibration: Any, state: RigState) -> dict:
        """Start the axes on a reloaded calibration (estimators at rest); the calibration.json contents."""
        raise NotImplementedError

    @classmethod
    def rig_command(cls, motors: list) -> Any:
        """The rig's command (its tendon shape) from one motor command per axis."""
        raise NotImplementedError

    @classmethod
    def recording(cls, cfg: Config, rig: Rig) -> tuple[str, tuple[str, ...], dict[str, str]]:
        """The slave's recording: file name, columns, metadata."""
        raise NotImplementedError

    @classmethod
    def csv_row(cls, state: RigState, common: tuple, axes: Sequence[SlaveAxis]) -> list:
        """One recording row: ``common`` = (marker, cmd_seq, state, t_node, t_cmd_recv)."""
        raise NotImplementedError

    @classmethod
    def stats(cls, axes: Sequence[SlaveAxis]) -> dict[str, Any]:
        """The kind's own counters for the run summary."""
        raise NotImplementedError

    @classmethod
    def warm_up(cls, cfg: Config) -> None:
        """Compile the rig's and the estimators' numba kernels with throwaway objects."""
        raise NotImplementedError

    @classmethod
    def motor_all(cls, axes: Sequence[SlaveAxis], relax: bool, targets: Sequence[float | None], state: RigState,
                  dt: float) -> Any:
        """:meth:`motor` of every axis with its target, as :meth:`rig_command` takes them (a kind may step its
        controllers together, the same numbers)."""
        return [ax.motor(relax, t, state, dt) for ax, t in zip(axes, targets, strict=False)]

    @classmethod
    def observe_all(cls, axes: Sequence[SlaveAxis], state: RigState) -> list[tuple[AxisState, tuple[float, ...]]]:
        """:meth:`observe` of every axis, in order (a kind may step its estimators together, the same numbers)."""
        return [ax.observe(state) for ax in axes]

    # ---- per axis ----------------------------------------------------------------------------------
    def out_of_range(self, target: float) -> str | None:
        """Why ``target`` (m or rad) is outside the axis's command range, or None."""
        raise NotImplementedError

    def too_far(self, target: float, state: RigState) -> str | None:
        """Why engaging on ``target`` would move the axis too far at once, or None."""
        raise NotImplementedError

    def motor(self, relax: bool, target: float | None, state: RigState, dt: float) -> Any:
        """This cycle's motor command(s) [m]: ``relax`` (SAFE: the axis's safe behaviour), else
        follow ``target`` when given (ENGAGED), else hold the last one."""
        raise NotImplementedError

    def observe(self, state: RigState) -> tuple[AxisState, tuple[float, ...]]:
        """One estimator step on the rig's proximal samples (never the truth): the axis's state on
        the wire and its tension profile (empty when it sends none)."""
        raise NotImplementedError

    def log_calibration(self, rerun: Any, cycles: int, log_every: int, state: RigState) -> None:
        """Rerun series while the power-up routine runs (none by default)."""

    def log_rerun(self, rerun: Any, cycles: int, state: RigState, everything: bool = False) -> None:
        """The axis's Rerun series of this cycle (``everything``: all of them now, at set-up)."""
        raise NotImplementedError
