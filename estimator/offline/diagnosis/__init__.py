"""The single-tendon diagnosis: what the base model gets wrong on a recording, which catalogue effect explains
it, and the held-out gain. Model-free readings, time-blocked folds and fits, the rules and their tuned thresholds,
and the typed result with its JSON form.

It imports :mod:`estimator.offline.effects`, :mod:`estimator.offline.fit` and the model core; never a side or
:mod:`teleop`.
"""
