"""The instrument side: the slave node and its watchdog, one axis class per instrument kind (a single tendon, an
antagonistic pair, a spindle-driven pair), their power-up calibrations and calibration files, the rig interface and
its registry (simulated rigs, a rig over Zenoh).

Floor 2: it imports :mod:`estimator` and :mod:`teleop`, never :mod:`master`, :mod:`study` or :mod:`live`.
"""
