"""The scaling benchmark's parts (benchmarks/bench_scaling.py), small: the generated instrument, the fit, and
its master + slave loop of one joint for a few cycles."""
from __future__ import annotations

import importlib.util
import os

import numpy as np
import pytest

_DIR = os.path.join(os.path.dirname(__file__), "..", "..", "benchmarks")


@pytest.fixture(scope="module")
def bench():
    # run as a script, the benchmark imports its sibling scripts from its own folder
    with pytest.MonkeyPatch.context() as mp:
        mp.syspath_prepend(_DIR)
        spec = importlib.util.spec_from_file_location("bench_scaling", os.path.join(_DIR, "bench_scaling.py"))
        assert spec is not None and spec.loader is not None
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        yield mod


def test_the_generated_instrument_repeats_the_3dof_joints_under_distinct_names(bench):
    cfg = bench.instrument(8, rerun="off")
    names = [j.name for j in cfg.instrument.joints]
    assert len(set(names)) == 8 and names[3] == "bend_ud3" and names[7] == "bend_lr7"
    assert [s.name for s in cfg.rig.simulated.joints] == names and cfg.pair_control.axes == tuple(range(8))
    assert cfg.instrument.joints[5].tendons == cfg.instrument.joints[2].tendons


def test_the_cost_per_tendon_is_the_slope_of_a_line_fit(bench):
    assert bench.slope([2, 6, 16, 32], [0.1 + 0.01 * n for n in (2, 6, 16, 32)]) == pytest.approx(0.01)


def test_the_loop_of_one_joint_times_both_steps_and_the_rig(bench, tmp_path):
    cfg = bench.instrument(1, rerun="off")
    loop = bench.Loop(cfg, bench.simulator_calibration(cfg), False, tmp_path)
    try:
        x = loop.run(50)
    finally:
        loop.close()
    assert x.shape == (5, 50) and np.isfinite(x).all() and (x[0] > 0).all() and (x[2] > 0).all()
    assert (x[4] <= x[1] + 1e-3).all()            # the rig's CPU time lies inside the slave step's
    assert loop.slave.cycles == 50 and loop.master.seq == 50
