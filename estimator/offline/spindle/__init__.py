"""The spindle-driven cable pair offline: the calibration of the spindle pair model and of its centre map, and
one parameter set for many runs with extension selection and leave-one-run-out.

It imports the model core and :mod:`estimator.online` only.
"""
