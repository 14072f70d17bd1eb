"""The KAIST flexible-endoscope study (``teleop analyze --kaist``): the inputs it reads, the pair diagnosis's
summary, report and figures, and the model files it writes for the live loop.

It imports :mod:`estimator`, :mod:`teleop` and :mod:`recorded` (the KAIST readers).
"""
