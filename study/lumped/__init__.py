"""The second simulator: a dynamic lumped-mass tendon-sheath model (its compiled step, the bench operator's motion
protocols) and its randomised recordings with hidden effects, the independent check of the diagnosis.

It imports :mod:`estimator` and :mod:`teleop` only.
"""
