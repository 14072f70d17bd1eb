"""``teleop record``: the recorder process (every message of an instrument, losing none), its MCAP file and how
it is read back or rebuilt, its disk budget, its side of the write-ahead journals, and its end-of-session figure.

It imports :mod:`teleop`, :mod:`slave` and :mod:`master` as every command of :mod:`live` may.
"""
