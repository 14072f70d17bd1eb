"""A process that reads a configuration and speaks the wire protocol (the master, the recorder, the router, the
``teleop`` command line itself) loads no compiled code: the sheath's route (:mod:`estimator.geometry`) and the
phase codes (:mod:`estimator.phase`) are plain Python, and numba, which costs about a third of a second of every
start, stays out of such a process until something runs a kernel. The live sides load no fitting library
(scipy.optimize, about half a second) until a calibration solves for K."""
from __future__ import annotations

import subprocess
import sys

import pytest

LIGHT = ("live.cli", "teleop.config.schema", "teleop.config.load", "teleop.wire.codec", "master.node_base",
         "live.record.recorder", "live.router",
         "live.discovery", "live.faults", "teleop.recording.journal", "estimator.geometry", "estimator.phase")


@pytest.mark.parametrize("module", LIGHT)
def test_a_configuration_and_wire_process_does_not_load_numba(module):
    code = f"import sys, {module}; print(sorted(m for m in sys.modules if m.split('.')[0] == 'numba')[:3])"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]", (module, out)


def test_the_estimator_still_loads_its_kernels():
    # the counter-check: the modules with compiled code do load numba (the test above can fail)
    code = "import sys, estimator.sheath; print('numba' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "True"


def _fitting_library_loaded(code: str) -> bool:
    """Whether a fresh interpreter that runs ``code`` has loaded scipy.optimize."""
    out = subprocess.run([sys.executable, "-c", f"import sys; {code}; print('scipy.optimize' in sys.modules)"],
                         capture_output=True, text=True, check=True).stdout
    return out.strip() == "True"


def test_a_live_side_starts_without_the_fitting_library():
    # scipy.optimize costs about half a second of a start (its docstrings are parsed on import); the live sides
    # solve nothing with it unless a calibration asks for K, so its imports wait for that call
    assert not _fitting_library_loaded("import live.cli, slave.node, master.node, slave.calibration_file, "
                                       "estimator.capstan; [live.cli.build_parser([c]) for c in "
                                       "('slave', 'master', 'demo')]")
    assert _fitting_library_loaded("import estimator.offline.diagnosis.fit")     # the counter-check


@pytest.mark.parametrize("command", ["master", "record", "router", "view"])
def test_the_command_line_of_a_process_without_kernels_loads_none(command):
    # the replay's and the analysis's arguments load with their modules only when the command names them
    code = (f"import sys, live.cli; live.cli.build_parser([{command!r}]); "
            "print(sorted(m for m in sys.modules if m.split('.')[0] == 'numba')[:3])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]", (command, out)
