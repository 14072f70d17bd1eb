"""Distal tension, elongation and joint torque of tendon-sheath transmissions from proximal sensors.

The public face of the library: every name a researcher uses, importable from here::

    from estimator import SheathModel, DistalEstimator, estimate_batch, calibrate, diagnose

The model core (Phee et al. 2009, the capstan law with tension-profile memory):

* :class:`SheathModel` (K [-], L/EA [m/N], route shape), :class:`SheathGeometry`, :class:`Run`;
* :class:`Phase`, :class:`PhaseFormulaEstimator` and :func:`phase_formula_batch` (the paper's phase formulas),
  :func:`K_from_M_e` (eq. (13));
* :class:`MeasuredData` (the arrays of one recording, SI units), :func:`noise_level`;
* :class:`EstimatorError`, :class:`CalibrationError`, :class:`DataError` (both ``ValueError``).

Online estimators (one proximal sample per call, or a whole recording in one compiled pass):

* one tendon: :class:`DistalEstimator` (``step``), :func:`estimate_batch`, :class:`DistalSample`,
  :class:`BatchEstimate`;
* an antagonistic joint: :class:`PairEstimator` (``step``), :func:`estimate_pair_batch`,
  :class:`PairSample`, :class:`PairBatch`;
* a cable pair on one input spindle: :class:`SpindleEstimator` (``step``), :class:`SpindleParams`,
  :func:`spindle_batch`, :func:`spindle_torque`, :func:`spindle_angle`.

Offline identification and diagnosis:

* :func:`calibrate` (the joint-limit initialisation of the seed paper, Sec. IV; the same function as
  :func:`calibrate_joint_limit`), :class:`CalibrationResult`, :func:`detect_knee`;
* :func:`fit_single` (K and L/EA of one recording, scored on held-out data), :class:`SingleTendonFit`;
* :func:`fit_pair`, :class:`PairParams`, :class:`PairFit` (an antagonistic pair from its motor command);
* :func:`diagnose` (what the base model misses on a recording and which physical effect explains it: a
  JSON-ready dict), :func:`diagnose_recording` (the same as a typed :class:`Diagnosis`).

Importing this package is cheap: each name loads its module (and the compiled kernels behind it) on
first use (PEP 562 module ``__getattr__``), so ``import estimator`` pulls in neither numba nor scipy.
The model core never imports this package's online or offline parts (tests/test_layering.py).
"""
from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

#: public name -> (module, attribute in that module)
_EXPORTS: dict[str, tuple[str, str]] = {
    # model core
    "Run": ("estimator.geometry", "Run"),
    "SheathGeometry": ("estimator.geometry", "SheathGeometry"),
    "SheathModel": ("estimator.sheath", "SheathModel"),
    "Phase": ("estimator.phase", "Phase"),
    "PhaseFormulaEstimator": ("estimator.capstan", "PhaseFormulaEstimator"),
    "phase_formula_batch": ("estimator.capstan", "phase_formula_batch"),
    "K_from_M_e": ("estimator.capstan", "K_from_M_e"),
    "MeasuredData": ("estimator.data", "MeasuredData"),
    "noise_level": ("estimator.data", "noise_level"),
    "EstimatorError": ("estimator.errors", "EstimatorError"),
    "CalibrationError": ("estimator.errors", "CalibrationError"),
    "DataError": ("estimator.errors", "DataError"),
    # online: one tendon, a joint, a spindle pair
    "DistalEstimator": ("estimator.online.distal", "DistalEstimator"),
    "DistalSample": ("estimator.online.distal", "DistalSample"),
    "BatchEstimate": ("estimator.online.distal", "BatchEstimate"),
    "estimate_batch": ("estimator.online.distal", "estimate_batch"),
    "PairEstimator": ("estimator.online.pair", "PairEstimator"),
    "PairSample": ("estimator.online.pair", "PairSample"),
    "PairBatch": ("estimator.online.pair", "PairBatch"),
    "estimate_pair_batch": ("estimator.online.pair_batch", "estimate_pair_batch"),
    "SpindleParams": ("estimator.online.spindle", "SpindleParams"),
    "SpindleEstimator": ("estimator.online.spindle_estimator", "SpindleEstimator"),
    "spindle_batch": ("estimator.online.spindle", "make_batch"),
    "spindle_torque": ("estimator.online.spindle", "predict_torque"),
    "spindle_angle": ("estimator.online.spindle", "predict_angle"),
    # offline: calibration, fitting, diagnosis
    "calibrate": ("estimator.offline.calibration", "calibrate_joint_limit"),
    "calibrate_joint_limit": ("estimator.offline.calibration", "calibrate_joint_limit"),
    "CalibrationResult": ("estimator.offline.calibration", "CalibrationResult"),
    "detect_knee": ("estimator.offline.calibration", "detect_knee"),
    "fit_single": ("estimator.offline.fit", "fit_single"),
    "SingleTendonFit": ("estimator.offline.fit", "SingleTendonFit"),
    "fit_pair": ("estimator.offline.pair.fit", "fit_pair"),
    "PairParams": ("estimator.offline.pair.fit", "PairParams"),
    "PairFit": ("estimator.offline.pair.fit", "PairFit"),
    "diagnose": ("estimator.offline.diagnosis.selection", "diagnose"),
    "diagnose_recording": ("estimator.offline.diagnosis.selection", "diagnose_recording"),
    "Diagnosis": ("estimator.offline.diagnosis.result", "Diagnosis"),
}

__all__ = [
    "Run", "SheathGeometry", "SheathModel", "Phase", "PhaseFormulaEstimator", "phase_formula_batch", "K_from_M_e",
    "MeasuredData", "noise_level", "EstimatorError", "CalibrationError", "DataError", "DistalEstimator",
    "DistalSample", "BatchEstimate", "estimate_batch", "PairEstimator", "PairSample", "PairBatch",
    "estimate_pair_batch", "SpindleEstimator", "SpindleParams", "spindle_batch", "spindle_torque", "spindle_angle",
    "calibrate", "calibrate_joint_limit", "CalibrationResult", "detect_knee", "fit_single", "SingleTendonFit",
    "fit_pair", "PairParams", "PairFit", "diagnose", "diagnose_recording", "Diagnosis",
]

if TYPE_CHECKING:       # the same names, for type checkers and editors (nothing is imported at run time)
    from estimator.capstan import K_from_M_e, PhaseFormulaEstimator, phase_formula_batch
    from estimator.data import MeasuredData, noise_level
    from estimator.errors import CalibrationError, DataError, EstimatorError
    from estimator.geometry import Run, SheathGeometry
    from estimator.offline.calibration import CalibrationResult, calibrate_joint_limit, detect_knee
    from estimator.offline.calibration import calibrate_joint_limit as calibrate
    from estimator.offline.diagnosis.result import Diagnosis
    from estimator.offline.diagnosis.selection import diagnose, diagnose_recording
    from estimator.offline.fit import SingleTendonFit, fit_single
    from estimator.offline.pair.fit import PairFit, PairParams, fit_pair
    from estimator.online.distal import BatchEstimate, DistalEstimator, DistalSample, estimate_batch
    from estimator.online.pair import PairBatch, PairEstimator, PairSample
    from estimator.online.pair_batch import estimate_pair_batch
    from estimator.online.spindle import SpindleParams
    from estimator.online.spindle import make_batch as spindle_batch
    from estimator.online.spindle import predict_angle as spindle_angle
    from estimator.online.spindle import predict_torque as spindle_torque
    from estimator.online.spindle_estimator import SpindleEstimator
    from estimator.phase import Phase
    from estimator.sheath import SheathModel


def __getattr__(name: str) -> Any:
    """Load a public name's module on first use (module docstring); AttributeError for any other name."""
    try:
        module, attr = _EXPORTS[name]
    except KeyError:
        raise AttributeError(f"module 'estimator' has no attribute {name!r}") from None
    value = getattr(importlib.import_module(module), attr)
    globals()[name] = value          # later look-ups skip this function
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))
