"""The single candidates screened at the base (estimator.offline.diagnosis.singles): a candidate whose linearised
share of the base's residual is below its price is fitted only when a step needs it. Screening changes no answer:
the same recordings diagnosed with every candidate fitted name the same causes with the same gain, and every
candidate the screen set aside, once fitted, either cannot pay for its parameters (S + PENALTY x parameters >= 1) or
ranks below the cause named (log S + log(RANK_FACTOR) x parameters). The linear share underestimates an effect that
acts through a play (pre-sliding, a backlash): such a look-alike can fit part of another cause's loop, so the screen
does not claim more."""
from __future__ import annotations

import math

import pytest

from estimator.offline.diagnosis import thresholds as th
from estimator.offline.diagnosis.selection import diagnose
from estimator.offline.diagnosis.singles import Singles
from study.scenarios import record
from tests.estimator.diagnosis_support import DUR, RATE

#: [-] the gain's tolerance between the two runs: the pinned answers' (tests/estimator/test_diagnosis_pinned.py)
GAIN_TOL = 1e-3

CASES = {
    "clean": (None, 12),
    "one cause": ("velocity_friction", 13),
    "two causes": (("sensor_offset:T_in", "tendon_stiffening"), 13),
}


def _fitting_every_candidate(monkeypatch) -> None:
    """Singles.screen followed by fitting every screened candidate: the diagnosis without the screen."""
    screen = Singles.screen.__func__

    def every(cls, ctx, base, cands, keep):
        singles = screen(cls, ctx, base, cands, keep)
        singles.complete()
        return singles

    monkeypatch.setattr(Singles, "screen", classmethod(every))


@pytest.mark.parametrize("name", list(CASES))
def test_screening_changes_no_answer_and_sets_aside_only_what_cannot_pay(name, monkeypatch):
    eid, seed = CASES[name]
    data = record(eid, seed=seed, duration=DUR, rate_hz=RATE).data
    screened = diagnose(data)
    _fitting_every_candidate(monkeypatch)
    every = diagnose(data)
    assert every["screened"] == {} and screened["causes"] == every["causes"]
    assert abs(screened["gain"] - every["gain"]) <= GAIN_TOL
    if name == "clean":
        assert screened["screened"], "the screen set nothing aside on a clean recording"
    cands = every["candidates"]
    first = cands[every["causes"][0]] if every["causes"] and every["causes"][0] in cands else None
    for cid in screened["screened"]:
        c = cands[cid]
        assert c["penalised_score"] >= 1.0 or (first is not None and _rank(c) > _rank(first)), (cid, c["score"])


def _rank(c: dict) -> float:
    """The forward selection's rank of a single candidate's entry: log S + log(RANK_FACTOR) x its parameters (its
    price over PENALTY)."""
    n = round((c["penalised_score"] - c["score"]) / th.PENALTY)
    return math.log(max(c["score"], 1e-12)) + math.log(th.RANK_FACTOR) * n
