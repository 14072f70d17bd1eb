"""The readers of measured data sets: the KAIST flexible-endoscope recordings (:mod:`recorded.kaist`), the MRD da
Vinci runs (:mod:`recorded.mrd`), the layout of either clone (``*_files``) and the data folder
(:mod:`recorded.folders`), the column maps of other labs' CSV files, a recording's format read from its content
(:mod:`recorded.formats`, :mod:`recorded.detect`) and the calibration of a spindle-driven pair on recorded MRD
runs (:mod:`recorded.mrd_calibration`, :mod:`recorded.mrd_centre`).

It sits between ``teleop/`` and the sides: it imports ``estimator/`` and ``teleop/`` only, and ``slave/``
(the recording rig), ``master/`` (the operator that follows a recording) and ``study/`` read through it.
"""
