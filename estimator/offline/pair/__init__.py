"""The antagonistic pair offline: the capstan-joint pair model fitted from motor commands, its diagnosis and
pair-level catalogue, and one parameter set shared across tube configurations (fit once, predict new shapes).

It imports the model core, :mod:`estimator.online` and :mod:`estimator.offline.fit`.
"""
