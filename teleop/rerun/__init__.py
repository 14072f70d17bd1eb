"""The live view in Rerun: the layout (route coloured by tension, profile, estimate over truth, phase lane), the
logger of one explicit recording stream, and the thread or child process that keeps logging off the control loop.

It imports :mod:`teleop.config`, :mod:`teleop.wire` and :mod:`teleop.recording`; rerun-sdk is imported only here.
"""
