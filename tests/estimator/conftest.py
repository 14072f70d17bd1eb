"""The clean rig recording the diagnosis tests read, diagnosed once per session: the diagnosis is the expensive
part, and its result is only read."""
import pytest

from estimator.offline.diagnosis.selection import diagnose
from study.scenarios import record
from tests.estimator.diagnosis_support import DUR, RATE


@pytest.fixture(scope="session")
def clean_result():
    rec = record(None, seed=21, duration=DUR, rate_hz=RATE)
    return rec, diagnose(rec.data)
