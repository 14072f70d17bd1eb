"""The diagnosis's answers on a fixed set of recordings stay what they are.

``diagnosis_pinned.json`` beside this file holds, for short recordings of both simulators (the project's rig,
:mod:`study.scenarios`, and the independent lumped-mass simulator, :mod:`study.lumped.scenarios`), clean ones and
one or more per effect family, how each is made and what :func:`estimator.offline.diagnosis.selection.diagnose` answers:
``cause`` and ``causes`` (compared exactly) and ``gain`` (to :data:`GAIN_TOL`, derived from the fits' own
tolerance: the same answers on any CPU, whatever its vector width or its order of floating-point sums). The set covers
the procedure's rules: the finer route, the rest reading, the stick-slip reading, the held distal end, an effect judged
on one fold, structure no extension explains. A change of the code that is not meant to change an answer must leave them
all; one that is meant to rewrites the file (``python tests/estimator/test_diagnosis_pinned.py --write``) in the same
commit.

The pair diagnosis (:func:`estimator.offline.pair.diagnosis.diagnose_pair`) is pinned the same way on one KAIST
recording when the data set is present.
"""
from __future__ import annotations

import json
import sys
from dataclasses import replace
from pathlib import Path

import pytest

from estimator.offline.diagnosis import thresholds as th
from estimator.offline.diagnosis.selection import diagnose
from estimator.offline.pair.diagnosis_fit import FIT_TOL as PAIR_FIT_TOL
from recorded import kaist_files
from recorded.folders import KAIST, skip_reason
from study import scenarios
from study.lumped import scenarios as lumped_scenarios

PINNED = Path(__file__).with_name("diagnosis_pinned.json")
KAIST_DIR = kaist_files.default_kaist_dir()

#: Tolerance of a pinned held-out gain [-]. Every fit behind a gain stops on a relative change of its training
#: cost below ftol (diagnosis_thresholds.FIT_TOL of the single tendon, pair_diagnosis.FIT_TOL of the pair: 1e-6).
#: Near a minimum the cost is quadratic in the parameters, so a fit stopped there has them within sqrt(ftol) = 1e-3
#: (relative) of the minimum along its flattest direction; the held-out error is not at its own minimum, so it
#: moves to first order with them, and two CPUs that round their sums differently (AVX-512 against AVX2, FMA or
#: not) agree on a gain to ~1e-3.
GAIN_TOL = max(th.FIT_TOL, PAIR_FIT_TOL) ** 0.5

#: name -> how the recording is made: simulator, hidden effect (None: clean), seed, level, duration [s], rate [Hz]
#: (None: the simulator's own), candidate effects (None: the whole catalogue), a distal channel left out
CASES: dict[str, dict] = {
    "rig, clean": dict(sim="rig", effect=None, seed=21, level=None, duration=20.0, rate=200.0),
    "rig, velocity friction": dict(sim="rig", effect="velocity_friction", seed=11, level=None, duration=20.0,
                                   rate=200.0),
    "rig, proximal load-cell offset": dict(sim="rig", effect="sensor_offset:T_in", seed=11, level=None,
                                           duration=20.0, rate=200.0),
    "rig, distal encoder lag": dict(sim="rig", effect="sensor_lag:x_out", seed=11, level=None, duration=20.0,
                                    rate=200.0),
    "rig, an effect outside the catalogue": dict(sim="rig", effect="load_cell_wander", seed=901, level=None,
                                                 duration=15.0, rate=200.0),
    "lumped, clean": dict(sim="lumped", effect=None, seed=501, level=None, duration=20.0, rate=200.0),
    "lumped, an effect outside the catalogue": dict(sim="lumped", effect="load_cell_wander", seed=901, level=None,
                                                    duration=15.0, rate=200.0),
    "lumped, pretension": dict(sim="lumped", effect="pretension", seed=107, level=0.7, duration=20.0, rate=200.0),
    "lumped, distal backlash bending the route": dict(
        sim="lumped", effect="distal_backlash", seed=707110, level=0.8, duration=60.0, rate=None,
        effects=["distal_backlash", "pretension", "sensor_offset:x_in"]),
    "lumped, encoder off its zero at the initial rest": dict(
        sim="lumped", effect="sensor_offset:x_in", seed=4716102, level=0.2, duration=60.0, rate=None,
        effects=["sensor_offset:x_in", "tendon_stiffening", "friction_offset"]),
    "lumped, clean single arc on the finer route": dict(
        sim="lumped", effect=None, seed=900500, level=None, duration=60.0, rate=None,
        effects=["tendon_stiffening", "friction_offset", "sensor_offset:x_in"]),
    "lumped, clean distal end held on its stop": dict(
        sim="lumped", effect=None, seed=1019112, level=None, duration=60.0, rate=None,
        effects=["distal_backlash", "friction_offset", "sensor_offset:T_in"]),
    "lumped, distal load-cell drift from zero": dict(
        sim="lumped", effect="sensor_drift:T_out", seed=3415102, level=0.2, duration=60.0, rate=None,
        effects=["sensor_drift:T_out", "sensor_offset:T_out", "curvature_drift"]),
    "lumped, curvature drift with a rough proximal tension": dict(
        sim="lumped", effect="curvature_drift", seed=4402103, level=0.2, duration=20.0, rate=200.0),
    "lumped, distal load-cell gain on a constant force": dict(
        sim="lumped", effect="sensor_gain:T_out", seed=2011110, level=0.8, duration=60.0, rate=None,
        effects=["sensor_gain:T_out", "sensor_offset:T_out", "sensor_offset:T_in"]),
}


def answer(case: dict) -> dict:
    """Make the recording of ``case`` and diagnose it: {cause, causes, gain}."""
    sim = scenarios if case["sim"] == "rig" else lumped_scenarios
    kw = {"seed": case["seed"], "level": case["level"], "duration": case["duration"]}
    if case["rate"] is not None:
        kw["rate_hz"] = case["rate"]
    data = sim.record(case["effect"], **kw).data
    if case.get("without"):
        data = replace(data, **{case["without"]: None})
    effects = case.get("effects")
    res = diagnose(data, effects=None if effects is None else tuple(effects))
    return {"cause": res["cause"], "causes": list(res["causes"]), "gain": float(res["gain"])}


def pair_answer() -> dict:
    """The pair diagnosis of the KAIST recording at 0 deg: {cause, causes, gain}."""
    from estimator.offline.pair.diagnosis import diagnose_pair
    from recorded import kaist
    rec = next(r for r in kaist.load_all(KAIST_DIR) if r.config_deg == 0)
    train, test, _ = kaist.split(rec)
    s, _ = diagnose_pair(rec, train, test)
    return {"cause": s["cause"], "causes": list(s["causes"]), "gain": float(s["gain"])}


def _pinned() -> dict:
    return json.loads(PINNED.read_text())


def test_the_pinned_set_covers_both_simulators_clean_and_hidden_effects():
    pinned = _pinned()["single"]
    assert set(pinned) == set(CASES)
    sims = {c["sim"] for c in CASES.values()}
    assert sims == {"rig", "lumped"} and len(CASES) >= 12
    assert any(c["effect"] is None for c in CASES.values() if c["sim"] == "rig")
    assert any(c["effect"] is None for c in CASES.values() if c["sim"] == "lumped")


@pytest.mark.parametrize("name", sorted(CASES))
def test_the_diagnosis_answers_as_pinned(name):
    want = _pinned()["single"][name]
    got = answer(CASES[name])
    assert got["cause"] == want["cause"] and got["causes"] == want["causes"], (got, want)
    assert got["gain"] == pytest.approx(want["gain"], abs=GAIN_TOL), (got, want)


def test_the_pair_diagnosis_answers_as_pinned():
    if not kaist_files.find_configs(KAIST_DIR):
        pytest.skip(skip_reason(KAIST, KAIST_DIR))
    want = _pinned()["pair"]["KAIST 0 deg"]
    got = pair_answer()
    assert got["cause"] == want["cause"] and got["causes"] == want["causes"], (got, want)
    assert got["gain"] == pytest.approx(want["gain"], abs=GAIN_TOL), (got, want)


if __name__ == "__main__":       # rewrite the pinned answers (only when an answer is meant to change)
    if sys.argv[1:] != ["--write"]:
        sys.exit("usage: python tests/estimator/test_diagnosis_pinned.py --write")
    out = {"single": {name: answer(case) for name, case in CASES.items()},
           "pair": {"KAIST 0 deg": pair_answer()} if kaist_files.find_configs(KAIST_DIR) else {}}
    PINNED.write_text(json.dumps(out, indent=1, sort_keys=True) + "\n")
