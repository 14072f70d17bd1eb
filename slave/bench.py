"""The calibration bench's distal sensors: what the diagnosis of a single tendon needs and an instrument lacks.

An instrument reads its tendon at the proximal end only (motor encoder ``x_in``, load cell ``T_in``). The diagnosis
(:func:`estimator.offline.diagnosis.selection.diagnose_recording`) compares the model's distal prediction with a
distal reading (``T_out`` and/or ``x_out``, docs/reference/formats.md), so ``teleop calibrate --diagnose`` runs on a
calibration bench: the instrument's tip held in a fixture with a distal load cell and a distal position sensor.

* :class:`SimulatedBench`: on the simulated rig, the bench's sensors at the simulated tip: a load cell with white
  noise (:data:`LOAD_CELL_NOISE`) and a position sensor with white noise quantised to :data:`POSITION_RESOLUTION`
  (the sensors of :mod:`study.scenarios`). Only these two readings reach the diagnosis: no noise-free signal, no
  elongation, no tension profile.
* :class:`SampleBench`: on a rig over Zenoh (``rig.type zenoh``), the distal readings the rig's samples carry in their
  distal fields (:mod:`teleop.wire.rig`: ``T_out``, ``x_out`` of each tendon), filled by the bench's controller beside
  the motor's; ``teleop bridge`` fills them from its simulator.

:func:`distal_bench` picks the bench of a rig, or None when the rig gives no distal reading.
"""
from __future__ import annotations

import numpy as np

from slave.rig import RigState, RigTruth
from slave.simulated import SimulatedRig

__all__ = ["LOAD_CELL_NOISE", "POSITION_NOISE", "POSITION_RESOLUTION", "SimulatedBench", "SampleBench",
           "distal_bench"]

#: noise of the simulated bench's distal load cell, standard deviation [N]
LOAD_CELL_NOISE = 0.03
#: noise of the simulated bench's distal position sensor, standard deviation [m]
POSITION_NOISE = 1e-6
#: resolution of the simulated bench's distal position sensor [m]
POSITION_RESOLUTION = 1e-6


class SimulatedBench:
    """The bench's distal load cell and position sensor at the simulated rig's tip (module docstring).

    Parameters
    ----------
    seed : int
        Seeds the sensors' noise.
    """

    name = "simulated bench (distal load cell and position sensor at the simulated tip)"

    def __init__(self, seed: int = 0):
        self._rng = np.random.default_rng([seed, 11])

    def read(self, state: RigState) -> tuple[float, float]:
        """(T_out [N], x_out [m]) the bench's sensors read on ``state``."""
        tip = state.truth
        if not isinstance(tip, RigTruth):
            raise RuntimeError("the simulated rig gave no single-tendon tip to read")
        n_T, n_x = self._rng.standard_normal(2)
        x = tip.x_out + POSITION_NOISE * float(n_x)
        return float(tip.T_out + LOAD_CELL_NOISE * float(n_T)), POSITION_RESOLUTION * round(x / POSITION_RESOLUTION)


class SampleBench:
    """The distal readings a networked rig's samples carry (module docstring)."""

    name = "the rig samples' distal fields (T_out, x_out)"

    def read(self, state: RigState) -> tuple[float, float]:
        """(T_out [N], x_out [m]) of ``state``'s sample; NaN when a sample comes without them."""
        tip = state.truth
        if not isinstance(tip, RigTruth):
            return float("nan"), float("nan")
        return float(tip.T_out), float(tip.x_out)


def distal_bench(rig, seed: int = 0) -> SimulatedBench | SampleBench | None:
    """The bench of ``rig``: :class:`SimulatedBench` on the simulated rig, :class:`SampleBench` on a rig whose samples
    carry distal readings, None on a rig that gives none."""
    if isinstance(rig, SimulatedRig):
        return SimulatedBench(seed)
    if isinstance(rig.state.truth, RigTruth):
        return SampleBench()
    return None
