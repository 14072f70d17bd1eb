"""Offline identification and diagnosis: fitting the models to recorded arrays, and finding what they miss.

Identification: :mod:`~estimator.offline.calibration` (the seed paper's joint-limit initialisation, run
by the slave before the loop starts, never inside it), :mod:`~estimator.offline.fit`,
:mod:`~estimator.offline.pair.fit`, :mod:`~estimator.offline.spindle.fit`. Diagnosis and the effect
catalogue: :mod:`~estimator.offline.effects.catalogue`, :mod:`~estimator.offline.diagnosis.selection`,
:mod:`~estimator.offline.pair.diagnosis`, shared parameter sets across configurations or runs:
:mod:`~estimator.offline.pair.shared`, :mod:`~estimator.offline.pair.general`,
:mod:`~estimator.offline.spindle.shared`. They may import the online estimator and the model core.
"""
