"""Files a session writes and the offline readers read: the measured-data CSV of one tendon, the per-cycle CSV
written by a child process, the write-ahead journal of published messages, figures, and the checks every input
text file passes before it is parsed.

It imports :mod:`teleop.errors`, :mod:`teleop.config` and :mod:`teleop.wire`.
"""
