"""The offline study: measured-data readers (the generic column map, KAIST, MRD), the per-dataset analyses
with their reports and figures, the scenario generators and the lumped simulator.

It sits above ``slave/`` (whose simulated rigs the scenario generators drive) and below the live
application, whose command line dispatches ``teleop analyze`` here; no side imports it.
"""
