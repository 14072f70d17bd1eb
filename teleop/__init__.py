"""What every process of a session shares, one family per sub-package: :mod:`teleop.config`, :mod:`teleop.wire`,
:mod:`teleop.session` (Zenoh), :mod:`teleop.timing`, :mod:`teleop.recording`, :mod:`teleop.rerun`, :mod:`teleop.ros2`;
and at the top the nodes every side builds on (:mod:`teleop.node`, :mod:`teleop.node_group`, :mod:`teleop.arms`) and
the error hierarchy (:mod:`teleop.errors`).

Floor 1 of the layout (tests/test_layering.py): it imports :mod:`estimator` only, never a side, the study or the live
application.
"""
