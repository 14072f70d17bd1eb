"""The MRD da Vinci tool study (``teleop analyze --mrd``): the spindle pair model against measured jaw torque and
angle, folders of separate stroke windows, the tool file's constants, the printed table, report and figures, and the
model file it writes for the live loop.

It imports :mod:`estimator`, :mod:`teleop` and :mod:`recorded` (the MRD readers and the calibration on recorded runs).
"""
