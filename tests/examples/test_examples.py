"""The example scripts run as a user runs them (``python examples/<name>.py``, the installed package) and
print figures that hold: the estimate's error, the calibration's, the cause named, the loop's round trip."""
from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from study.scenarios import record
from teleop.recording.measured import write_measured_csv

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def run_example(name: str, *args: str, cwd: Path | None = None) -> str:
    """stdout of ``python examples/<name>.py args`` (run from ``cwd``: not the checkout, so only the installed
    package can be imported); fails with its stderr on a non-zero exit."""
    proc = subprocess.run([sys.executable, str(EXAMPLES / f"{name}.py"), *args], capture_output=True, text=True,
                          timeout=300, cwd=cwd)
    assert proc.returncode == 0, f"{name}.py exited {proc.returncode}:\n{proc.stdout}\n{proc.stderr}"
    return proc.stdout


def number(pattern: str, text: str) -> float:
    m = re.search(pattern, text)
    assert m is not None, f"{pattern!r} not in:\n{text}"
    return float(m.group(1))


def test_estimate_csv_on_the_simulated_recording(tmp_path):
    out = run_example("estimate_csv", cwd=tmp_path)
    assert "the simulated rig's" in out
    # the profile-memory estimate with the rig's own K and L/EA: within 2 % of the distal tension's range
    assert number(r"distal tension: rms error [\d.]+ N \(([\d.]+) % of", out) < 2.0
    assert number(r"distal displacement: rms error [\d.]+ mm \(([\d.]+) % of", out) < 2.0


def test_estimate_csv_fits_the_model_of_a_given_file(tmp_path):
    path = tmp_path / "rec.csv"
    write_measured_csv(path, record(None, seed=11, duration=20.0).data)
    out = run_example("estimate_csv", str(path), cwd=tmp_path)
    assert "fitted on the first" in out
    # held out: the last 40 % of the recording, not seen by the fit
    assert number(r"distal tension: rms error .* over ([\d.]+) s", out) == pytest.approx(8.0, abs=1.0)
    assert number(r"distal tension: rms error [\d.]+ N \(([\d.]+) % of", out) < 3.0


def test_calibrate_recovers_the_rig_s_K_and_M_e(tmp_path):
    out = run_example("calibrate", cwd=tmp_path)
    assert abs(number(r"calibrated K += [\d.]+ +\(rig [\d.]+, error ([+-][\d.]+) %", out)) < 3.0
    assert abs(number(r"calibrated M_e = .*error ([+-][\d.]+) %", out)) < 1.0
    assert number(r"calibrated model: rms error ([\d.]+) N", out) < 0.1


@pytest.mark.parametrize("effect", ["velocity_friction", "stiction"])
def test_diagnose_names_the_hidden_effect(tmp_path, effect):
    out = run_example("diagnose", "--effect", effect, cwd=tmp_path)
    hidden = re.search(r"hidden effect: (\w+)", out)
    assert hidden is not None and hidden.group(1) == effect
    assert re.search(r"^cause: (\w+)", out, re.M).group(1) == effect   # type: ignore[union-attr]
    assert number(r"gain on the held-out block: (-?\d+) %", out) > 30


@pytest.mark.integration
def test_teleop_loop_runs_both_sides_over_zenoh(tmp_path):
    out = run_example("teleop_loop", cwd=tmp_path)
    assert "protocol finished" in out
    assert number(r"distal tension estimate: rms error ([\d.]+) N", out) < 0.2
    p50 = number(r"round trip .*p50 ([\d.]+) ms", out)
    assert 0 < p50 < 50
    assert number(r"(\d+) echoed", out) > 1000
