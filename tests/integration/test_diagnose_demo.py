"""``teleop calibrate --diagnose`` on the simulated rig with a hidden effect (velocity friction, 30 s/m), then
``teleop demo`` with the model file it wrote, each as its own process: the diagnosis names the effect, and the
estimator with the model beats the base estimator on the distal tension of the same recording.

The comparison is paired: the base estimator is replayed over the model run's own recording (what ``teleop
replay`` computes, whose estimates equal the live loop's), so both face the same moves. Two demo runs would not: the
scripted operator feels the rendered force of its own run's estimate, so the two runs' moves, and with velocity
friction their errors, differ more between runs than between estimators."""
from __future__ import annotations

import hashlib
import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from estimator.data import MeasuredData
from live.replay.main import EXPERIMENTS, compare, load_model, load_run, reestimate, tension_noise
from teleop.config.load import load_config

pytestmark = pytest.mark.integration
#: The model's mean distal-tension error is below this share of the base's on the same recording (one run: 0.11 on
#: the paper experiment, 0.07 on the minor loops; on a loaded machine 0.12 and 0.46).
GAIN = 0.75
#: The model's error is below the base's at this quantile of each experiment's rows. Not the largest error: a late loop
#: cycle on a loaded machine makes the operator's command jump (0.15 mm in one cycle); when the pull stops, the model
#: relaxes its profile to the slow friction while the simulated tendon holds what the jerk left, and its error can
#: exceed the base's through the hold, for a few hundred milliseconds (on one loaded run 0.11 of full scale against
#: 0.04 over 5 % of the minor loops, the largest 0.220 against 0.215; docs/results/live-gain.md, "Where velocity
#: friction errs live").
QUANTILE = 90.0
SIM = Path(__file__).resolve().parents[2] / "configs" / "sim.yaml"
HIDDEN = """
rig:
  type: simulated
  simulated:
    effects:
      velocity_friction:
        enabled: true
        viscous: 30.0
"""


def _config(tmp_path: Path) -> Path:
    text = SIM.read_text()
    assert "  id: sim0" in text and "  rerun: save" in text and "\nrig:\n  type: simulated" in text
    text = text.replace("  id: sim0", "  id: itdiag").replace("  rerun: save", '  rerun: "off"')
    text = re.sub(r"\nrig:\n  type: simulated[^\n]*\n(  #[^\n]*\n)*", HIDDEN, text, count=1)
    cfg = tmp_path / "hidden.yaml"
    cfg.write_text(text + f"\ncalibration:\n  dir: {tmp_path / 'cal'}\n")
    return cfg


def _is_paper_bound(check: str) -> bool:
    """The demo's checks against the seed paper's accuracy bounds (a max error over one experiment)."""
    return "error max <=" in check


def _demo(cfg: Path, run_dir: Path, *extra: str) -> tuple[str, dict]:
    """Run the demo; it must complete without problems and pass every check of its own but the paper's accuracy
    bounds. Those bounds are for the paper's rig, without the hidden effect: with 30 s/m of velocity friction under
    the operator's fastest moves, the max errors over one experiment follow how jerky the moves were (the loop's late
    cycles on a loaded machine), for the base estimator as for the one with the model. The paired comparison below
    measures the model's gain; the paper's bounds are held on the rig without the effect
    (tests/integration/test_bridge.py)."""
    proc = subprocess.run([sys.executable, "-m", "live.cli", "demo", "--config", str(cfg), "--run-dir", str(run_dir),
                           "--timeout", "60", *extra], capture_output=True, text=True, timeout=150)
    summary = json.loads((run_dir / "summary.json").read_text())
    failed = [name for name, ok in summary["checks"].items() if not ok]
    assert summary["problems"] == [] and "Traceback" not in proc.stderr, (summary["problems"], proc.stderr[-3000:])
    held = [name for name in failed if not _is_paper_bound(name)]
    assert not held and proc.returncode == (1 if failed else 0), (failed, proc.stdout[-3000:])
    return proc.stdout, summary


def test_diagnose_names_the_effect_and_the_estimator_with_its_model_beats_the_base_on_the_same_run(tmp_path):
    cfg = _config(tmp_path)
    proc = subprocess.run([sys.executable, "-m", "live.cli", "calibrate", "--diagnose", "--config", str(cfg)],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0 and "Traceback" not in proc.stderr, proc.stderr[-3000:]
    assert "cause: velocity_friction" in proc.stdout, proc.stdout
    took = float(re.search(r"teleop calibrate --diagnose: ([0-9.]+) s", proc.stdout).group(1))
    assert took < 180.0                                    # the bound on the simulated rig
    model = tmp_path / "cal" / "itdiag.model.yaml"
    assert f"--model {model}" in proc.stdout

    out, ext = _demo(cfg, tmp_path / "model", "--model", str(model))
    sha = hashlib.sha256(model.read_bytes()).hexdigest()
    assert ext["model"]["sha256"] == sha and ext["model"]["id"] == "itdiag/tendon/profile_memory+velocity_friction"
    assert f"model {ext['model']['id']} (sha256 {sha[:12]}..." in out
    assert ext["slave"]["model"]["cycles"] > 0
    data, base_est = _base_estimate(tmp_path / "model")       # the base estimator, same inputs
    base = compare(data, base_est)
    assert data.T_out is not None
    for code, name in EXPERIMENTS.items():
        b, m = base[name]["vs_truth"], ext["experiments"][name]["profile_memory"]
        assert b["samples"] == ext["experiments"][name]["samples"]
        # the base misses c_v v T in every move; the model where the speed jumps (a late loop cycle) or where the
        # speed read's noise ends a slide mid-pull, until the pull slows (docs/results/live-gain.md, "Where velocity
        # friction errs live")
        assert m["force_error_mean_fs"] < GAIN * b["force_error_mean_fs"], (name, b, m)
        # the QUANTILE of the distal-tension error [N] against the simulator's truth: the live model's (recorded)
        # below the base's
        sel = data.extra["marker"].astype(int) == code
        assert sel.sum() > 1000, name
        q_model, q_base = (float(np.percentile(np.abs(est[sel] - data.T_out[sel]), QUANTILE))
                           for est in (data.extra["T_out_hat"], base_est["T_out"]))
        assert q_model < q_base, (name, QUANTILE, q_model, q_base)


def _base_estimate(run: Path) -> tuple[MeasuredData, dict[str, np.ndarray]]:
    """The run's recording and the base estimator replayed over it with the run's config and calibration, what
    ``teleop replay`` computes (:func:`live.replay.main.reestimate`)."""
    inp = load_run(run)
    cfg = load_config(run / "config.yaml")
    model, source = load_model(cfg, inp)
    return inp.data, reestimate(inp.data, model, cfg, "profile", tension_noise(cfg, source))
