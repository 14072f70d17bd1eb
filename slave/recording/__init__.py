"""``rig.type: recording``: a measured recording played as the instrument's hardware (:mod:`slave.recording.rig`),
and the recorded axis of each kind, whose calibration is fitted on a recording (``spindle``, ``pair``, ``tendon``;
``routine`` what they share).

It imports ``estimator/``, ``teleop/``, ``recorded/`` (the readers) and the rest of ``slave/``.
"""
