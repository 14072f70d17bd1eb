"""The configuration: the schema (one frozen dataclass per section), its range table and hard safety bounds,
the strict YAML reader with its limits, the checks across keys, and the tool files and path kinds a config names.

It imports only :mod:`teleop.errors` and the standard library (and pyyaml); every process reads its config through
:func:`teleop.config.load.load_config`.
"""
