"""The readers of measured data sets: the KAIST flexible-endoscope recordings (:mod:`datasets.kaist`), the MRD da
Vinci runs (:mod:`datasets.mrd`), the layout of either clone (``*_files``) and the data folder
(:mod:`datasets.folders`), the column maps of other labs' CSV files, a recording's format read from its content
(:mod:`datasets.formats`, :mod:`datasets.recording`) and the calibration of a spindle-driven pair on recorded MRD
runs (:mod:`datasets.mrd_calibration`, :mod:`datasets.mrd_centre`).

It sits between ``teleop/`` and the sides: it imports ``estimator/`` and ``teleop/`` only, and ``slave/``
(the recording rig), ``master/`` (the operator that follows a recording) and ``study/`` read through it.
"""
