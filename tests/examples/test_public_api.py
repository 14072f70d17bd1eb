"""``from estimator import ...``: every public name resolves, and importing the package loads no numerics."""
from __future__ import annotations

import inspect
import subprocess
import sys

import pytest

import estimator


@pytest.mark.parametrize("name", estimator.__all__)
def test_every_public_name_resolves_to_a_documented_object(name):
    obj = getattr(estimator, name)
    assert obj.__module__.startswith("estimator.")
    assert inspect.getdoc(obj), f"estimator.{name} has no docstring"


def test_the_short_names_are_the_library_s_functions():
    from estimator.offline.calibration import calibrate_joint_limit
    from estimator.online.spindle import make_batch, predict_angle, predict_torque
    assert estimator.calibrate is calibrate_joint_limit
    assert (estimator.spindle_batch, estimator.spindle_torque, estimator.spindle_angle) == \
        (make_batch, predict_torque, predict_angle)


def test_an_unknown_name_is_an_attribute_error():
    with pytest.raises(AttributeError, match="no attribute 'DistalEstimater'"):
        _ = estimator.DistalEstimater
    assert set(estimator.__all__) <= set(dir(estimator))


def test_import_estimator_loads_neither_numba_nor_scipy_nor_the_submodules():
    code = ("import sys, estimator; "
            "print(sorted(m for m in sys.modules if m.split('.')[0] in ('numba', 'scipy', 'numpy') "
            "or m.startswith('estimator.')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
