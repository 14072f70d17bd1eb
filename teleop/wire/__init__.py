"""The wire: messages in SI units, their bytes (the only place the format lives), the Zenoh key expressions,
and the rig interface on the wire (motor set-points out, sensor samples back).

It imports :mod:`teleop.errors` and :mod:`teleop.config`; nothing here opens a session.
"""
