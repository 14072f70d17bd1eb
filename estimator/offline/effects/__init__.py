"""The catalogue of model extensions: one small class per physical effect the base model misses (and the sensor
corrections), their plain-data switches, the compiled kernels of the extended profile-memory model and its batch
prediction.

It imports the model core (:mod:`estimator`'s top-level modules) and :mod:`estimator.online` only.
"""
