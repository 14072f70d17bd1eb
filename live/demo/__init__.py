"""``teleop demo``: the whole system end to end on one machine (every instrument kind, the bimanual instrument and
a measured recording as the rig), and the accuracy summary and figure it ends with.

It imports :mod:`live` (the sides, discovery, the recorder), :mod:`slave`, :mod:`master` and :mod:`study`.
"""
