"""docs/reference/mcap.md: its Python snippet, run in a fresh interpreter beside a ``session.mcap`` of the demo's
instrument (``sim0``, configs/sim.yaml), finds the instrument in the file and prints its distal tension."""
from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np

from estimator.phase import Phase
from live.record.mcap_file import MCAP_NAME, McapRecording
from teleop.config.load import load_config
from teleop.wire.messages import tendon_estimate

ROOT = Path(__file__).resolve().parents[2]
PAGE = ROOT / "docs" / "reference" / "mcap.md"


def test_the_snippet_prints_the_demo_instruments_distal_tension(tmp_path):
    (code,) = re.findall(r"^```python\n(.*?)^```", PAGE.read_text(encoding="utf-8"), re.M | re.S)
    cfg = load_config(ROOT / "configs" / "sim.yaml")
    ident = cfg.instrument.id
    assert ident == "sim0"
    mc = McapRecording(tmp_path / MCAP_NAME, cfg, 1.7e9, every=1)
    T_out = 4.0 + np.arange(5)
    for k, T in enumerate(T_out):
        mc.write(10.0 + 1e-3 * k, f"teleop/{ident}/slave/estimate",
                 tendon_estimate(k, k, 10.0 + 1e-3 * k, T + 1.0, 1e-4, T, 1e-5, 9e-5, Phase.PULL, (T + 1.0, T)))
    mc.close()
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    assert lines[0] == f"instrument {ident}: /{ident}/measured_cf"
    rows = [ln.split() for ln in lines[1:]]
    assert [r[0] for r in rows] == [f"/{ident}/measured_cf"] * len(T_out)
    assert [float(r[2]) for r in rows] == list(T_out)
