"""The online estimator: what runs in the slave's control loop, sample by sample, from proximal sensors.

:mod:`~estimator.online.distal` (one tendon: distal tension and elongation, profile memory),
:mod:`~estimator.online.pair` and :mod:`~estimator.online.pair_batch` (an antagonistic pair: joint
torque and angle), :mod:`~estimator.online.spindle` (a cable pair on one input spindle; per cycle
:mod:`~estimator.online.spindle_estimator`), :mod:`~estimator.online.spindle_centre` (the jaw torque from the
spindle's band centre; per cycle :mod:`~estimator.online.centre_estimator`). They import
only the model core at the top of :mod:`estimator` (sheath, capstan, phase, kernels), never
:mod:`estimator.offline`.
"""
