"""docs/reference/estimator.md: its Python snippets run, in order, in one fresh interpreter outside the checkout."""
from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

PAGE = Path(__file__).resolve().parents[2] / "docs" / "reference" / "estimator.md"


def snippets() -> list[str]:
    return re.findall(r"^```python\n(.*?)^```", PAGE.read_text(encoding="utf-8"), re.M | re.S)


def test_the_page_has_a_snippet_per_section():
    assert len(snippets()) >= 7


def test_every_snippet_runs_and_prints_what_it_claims(tmp_path):
    script = "\n".join(f"print('--- snippet {k}')\n{code}" for k, code in enumerate(snippets()))
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=600, cwd=tmp_path)
    assert proc.returncode == 0, f"{proc.stdout}\n{proc.stderr}"
    out = proc.stdout
    m = re.search(r"K = ([\d.]+) \(true 0\.630\)", out)
    assert m is not None and abs(float(m.group(1)) - 0.63) < 0.02
    m = re.search(r"distal tension rms error ([\d.]+) N of a ([\d.]+) N range", out)
    assert m is not None and float(m.group(1)) < 0.03 * float(m.group(2))
    m = re.search(r"T_out ([\d.-]+) N \(batch ([\d.-]+) N\)", out)
    assert m is not None and m.group(1) == m.group(2)          # the online steps and the batch pass agree
    m = re.search(r"true peak ([\d.]+) mN m, rms error ([\d.]+) mN m", out)
    assert m is not None and float(m.group(2)) < 0.05 * float(m.group(1))
    m = re.search(r"jaw torque ([\d.-]+) \.\. ([\d.-]+) N m \(spindle ([\d.-]+) \.\. ([\d.-]+) N m", out)
    assert m is not None
    jaw_lo, jaw_hi, spindle_lo, spindle_hi = map(float, m.groups())
    assert spindle_lo < jaw_lo < 0 < jaw_hi < spindle_hi      # friction takes part of the torque both ways
    m = re.search(r"cause: (\w+) \(hidden: (\w+)\)", out)
    assert m is not None and m.group(1) == m.group(2) == "velocity_friction"
    assert "typed: cause velocity_friction" in out                # the typed result says the same
