"""ROS 2 on Zenoh with no bridge: CRTK names, the CDR message types and their hashes, the key expressions and
attachments as rmw_zenoh spells them, and a side's CRTK publisher and ``servo_jp`` subscriber.

It imports :mod:`teleop.config`, :mod:`teleop.wire`, :mod:`teleop.session` and :mod:`teleop.timing`.
"""
