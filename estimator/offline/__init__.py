"""Offline identification and diagnosis: fitting the models to recorded arrays, and finding what they miss.

Identification: :mod:`~estimator.offline.calibration` (the seed paper's joint-limit initialisation, run
by the slave before the loop starts, never inside it), :mod:`~estimator.offline.fit`,
:mod:`~estimator.offline.pair`, :mod:`~estimator.offline.spindle_fit`. Diagnosis and the effect
catalogue: :mod:`~estimator.offline.effects`, :mod:`~estimator.offline.diagnosis`,
:mod:`~estimator.offline.pair_diagnosis`, shared parameter sets across configurations or runs:
:mod:`~estimator.offline.pair_shared`, :mod:`~estimator.offline.pair_general`,
:mod:`~estimator.offline.spindle_shared`. They may import the online estimator and the model core.
"""
