"""The live application: the ``teleop`` command line and the commands of a live session (sides, bridge,
router, discovery, faults, record, replay, calibrate, demo). It wires ``master/`` and ``slave/`` together
and is the top floor of the import graph (tests/test_layering.py)."""
