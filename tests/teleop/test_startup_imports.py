"""A process that reads a configuration and speaks the wire protocol (the master, the recorder, the router, the
``teleop`` command line itself) loads no compiled code: the sheath's route (:mod:`estimator.geometry`) and the
phase codes (:mod:`estimator.phase`) are plain Python, and numba, which costs about a third of a second of every
start, stays out of such a process until something runs a kernel. The live sides load no fitting library
(scipy.optimize, about half a second) until a calibration solves for K."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

LIGHT = ("live.cli", "teleop.config.schema", "teleop.config.load", "teleop.wire.codec", "master.node_base",
         "live.record.recorder", "live.router",
         "live.discovery", "live.faults", "teleop.recording.journal", "estimator.geometry", "estimator.phase")


def _loaded(code: str, package: str) -> list[str]:
    """The modules of ``package`` (itself and its submodules) that a fresh interpreter has loaded after running
    ``code``, sorted (the first three)."""
    probe = (f"import json, sys; {code}; print(json.dumps(sorted(m for m in sys.modules "
             f"if m == {package!r} or m.startswith({package + '.'!r}))[:3]))")
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True).stdout
    return json.loads(out)


@pytest.mark.parametrize("module", LIGHT)
def test_a_configuration_and_wire_process_does_not_load_numba(module):
    assert _loaded(f"import {module}", "numba") == [], module


def test_the_estimator_still_loads_its_kernels():
    # the counter-check: the modules with compiled code do load numba (the test above can fail)
    assert _loaded("import estimator.sheath", "numba")


def test_a_live_side_starts_without_the_fitting_library():
    # scipy.optimize costs about half a second of a start (its docstrings are parsed on import); the live sides
    # solve nothing with it unless a calibration asks for K, so its imports wait for that call
    assert _loaded("import live.cli, slave.node, master.node, slave.calibration_file, estimator.capstan; "
                   "[live.cli.build_parser([c]) for c in ('slave', 'master', 'demo')]", "scipy.optimize") == []
    assert _loaded("import estimator.offline.diagnosis.fit", "scipy.optimize")     # the counter-check


@pytest.mark.parametrize("command", ["master", "record", "router", "view"])
def test_the_command_line_of_a_process_without_kernels_loads_none(command):
    # the replay's and the analysis's arguments load with their modules only when the command names them
    assert _loaded(f"import live.cli; live.cli.build_parser([{command!r}])", "numba") == [], command
