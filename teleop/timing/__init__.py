"""Time: clocks and the loop pacer, real-time scheduling, where a paced loop's time goes, round-trip latencies
in constant memory, and the quietness and transparency of the haptic loop.

It imports :mod:`teleop.errors` and :mod:`teleop.config` only.
"""
