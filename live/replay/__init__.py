"""``teleop replay RUN``: a recorded session played back through the estimator and the Rerun view (one tendon, or
an instrument's joints one by one).

It imports :mod:`teleop`, :mod:`estimator` and :mod:`slave` (calibration files).
"""
