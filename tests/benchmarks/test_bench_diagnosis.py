"""The diagnosis benchmark's report helpers (benchmarks/bench_diagnosis.py)."""
from __future__ import annotations

import importlib.util
import os

import pytest

_PATH = os.path.join(os.path.dirname(__file__), "..", "..", "benchmarks", "bench_diagnosis.py")


@pytest.fixture(scope="module")
def bench():
    # run as a script, the benchmark imports its report module from its own folder
    with pytest.MonkeyPatch.context() as mp:
        mp.syspath_prepend(os.path.dirname(_PATH))
        spec = importlib.util.spec_from_file_location("bench_diagnosis", _PATH)
        assert spec is not None and spec.loader is not None
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        yield mod


def test_accuracy_interval_is_clopper_pearson(bench):
    # k = 0: the exact upper bound is 1 - (alpha / 2)^(1 / n); k = n mirrors it
    lo, hi = bench.proportion_interval(0, 12)
    assert lo == 0.0 and hi == pytest.approx(1 - 0.025 ** (1 / 12), rel=1e-6)
    lo, hi = bench.proportion_interval(12, 12)
    assert hi == 1.0 and lo == pytest.approx(0.025 ** (1 / 12), rel=1e-6)
    # a set of 92 fixes an accuracy near 0.74 only to about +-0.09
    lo, hi = bench.proportion_interval(68, 92)
    assert lo < 68 / 92 < hi and 0.15 < hi - lo < 0.22
    assert bench.proportion_interval(0, 0) == (0.0, 1.0)


def test_seed_sets_do_not_overlap(bench):
    # every seed set spans less than 100000 seeds (effects 100 + 1000 k + 10 j + s, clean 500+, other 900+)
    bases = sorted(bench.SEED_BASE.values())
    assert len(set(bases)) == len(bases)
    assert all(b - a >= 100000 for a, b in zip(bases, bases[1:], strict=False))
    n_eff = len(bench.EFFECT_IDS)
    assert bench.effect_seed(0, n_eff - 1, 1, 1) < 100000
    held_out = [v for k, v in bench.SEED_BASE.items() if k.startswith("final")]
    assert held_out and min(held_out) > max(v for k, v in bench.SEED_BASE.items() if k.startswith("dev"))


def test_twins_are_diagnosed_and_their_false_alarms_reported(bench, capsys):
    # the clean twin of a hidden-effect recording (same seed: same rig, protocol and noise) is diagnosed with
    # --twins: one more clean rig per row (without it none: test_without_drops_the_distal_channel...); the report
    # counts its false alarms by distal load
    row = bench.one(("lumped", "sensor_offset:T_out", 0.8, 101, 20.0, None, True, False, ()))
    assert row["twin_cause"] in ("none", "unknown") or row["twin_cause"] in bench.EFFECT_IDS
    assert row["load"] in ("spring", "preloaded", "constant", "joint") and row["twin_structure"] > 0.0
    alarm = dict(row, twin_cause="friction_offset", twin_causes=["friction_offset"], load="constant")
    bench.table([row, alarm], "twins")
    out = capsys.readouterr().out
    n_fa = 1 + (row["twin_cause"] != "none")
    assert f"false alarms on the clean twins of the hidden-effect recordings: {n_fa}/2" in out
    assert "constant 1/" in out


def test_without_drops_the_distal_channel_and_the_effects_that_need_it(bench):
    # --without x_out: a rig with a distal load cell only; the row's footprint has no x_out, and effects that need
    # x_out (backlash, the x_out sensor effects) cannot show, while a T_out effect still can
    row = bench.one(("lumped", "sensor_offset:T_out", 0.8, 101, 20.0, None, False, False, ("x_out",)))
    assert set(row["footprint"]) == {"T_in", "T_out", "x_in"}
    assert "twin_cause" not in row                                  # no clean twin without --twins
    assert row["footprint"]["T_out"] > 3.0
    assert not bench.shows_without("distal_backlash", ("x_out",))
    assert not bench.shows_without("sensor_lag:x_out", ("x_out",))
    assert bench.shows_without("sensor_lag:x_out", ("T_out",))
    assert not bench.shows_without("sensor_gain:T_out", ("T_out",))
    assert bench.shows_without("stiction", ("x_out",)) and bench.shows_without("none", ("T_out",))


def test_known_route_is_the_rigs_own_wrap_shape(bench):
    # --route-known holds each rig's true route: the lumped simulator's arcs and straight runs (flat where the
    # route is straight, steep in its arcs) and the project rig's uniform bend (a straight line)
    import math

    import numpy as np
    lumped = bench.known_route({"route": ((0.5, math.inf), (0.2, 0.1), (0.5, math.inf), (0.3, 0.3))})
    s = np.linspace(0.0, 1.5, lumped.size)
    assert lumped[0] == 0.0 and lumped[-1] == 1.0 and np.all(np.diff(lumped) >= 0.0)
    assert np.allclose(lumped[s <= 0.5], 0.0)                       # straight first run: no wrap
    assert abs(np.interp(0.7, s, lumped) - 2.0 / 3.0) < 1e-2        # the first arc: 2 rad of the 3
    rig = bench.known_route({"route": ((1.2, 2.0),)})
    assert np.allclose(rig, np.linspace(0.0, 1.0, rig.size))


def test_floor_table_reads_the_clean_rows_at_the_floor_only(bench, tmp_path, capsys):
    import json
    rows = [
        {"effect": "none", "cause": "none", "structure": 1.2, "scores": {"stiction": 0.6, "sensor_lag:T_out": 0.9}},
        # a clean recording named something at the floor still counts (a false alarm lowers the bound)
        {"effect": "none", "cause": "stiction", "structure": 2.0,
         "scores": {"stiction": 0.4, "sensor_lag:T_out": 0.95}},
        # far from the floor: FLOOR_SCORE does not apply there, its scores do not count
        {"effect": "none", "cause": "unknown", "structure": 9.0, "scores": {"stiction": 0.1, "sensor_lag:T_out": 0.2}},
        {"effect": "stiction", "cause": "none", "structure": 1.0, "scores": {"stiction": 0.05},
         "twin_cause": "none", "twin_structure": 1.1, "twin_scores": {"stiction": 0.8, "sensor_lag:T_out": 0.75}},
    ]
    path = tmp_path / "dev.json"
    path.write_text(json.dumps(rows))
    table = bench.floor_table([str(path)])
    assert table == {"sensor_lag:T_out": pytest.approx(bench.FLOOR_FACTOR * 0.75),
                     "stiction": pytest.approx(bench.FLOOR_FACTOR * 0.4)}
    assert "3 clean recordings at the floor" in capsys.readouterr().out
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"rows": []}))
    with pytest.raises(ValueError, match="bad.json: not a list of benchmark rows"):
        bench.floor_table([str(bad)])
