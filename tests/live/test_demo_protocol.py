"""``teleop demo --protocol`` is checked against the instrument before any calibration, run directory or process:
one line naming the bad protocol and the valid ones, exit 2."""
from __future__ import annotations

from pathlib import Path

import pytest

from live.cli import main

CONFIGS = Path(__file__).resolve().parents[2] / "configs"


@pytest.mark.parametrize(("config", "protocol", "valid"), [
    (None, "shrt", "expected one of paper, minor, short"),
    (None, "paper,shrt", "expected one of paper, minor, short"),
    (CONFIGS / "instrument-3dof.yaml", "minor", "expected 'paper' or 'short'"),
])
def test_an_unknown_protocol_exits_2_before_anything_starts(tmp_path, capsys, config, protocol, valid) -> None:
    run_dir = tmp_path / "run"
    argv = ["demo", "--protocol", protocol, "--run-dir", str(run_dir)] + (["--config", str(config)] if config else [])
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    bad = protocol.split(",")[-1]
    assert len(err) == 1 and err[0].startswith(f"teleop: error: --protocol {protocol}: ") and repr(bad) in err[0]
    assert valid in err[0]
    assert not run_dir.exists()         # no run directory, so no calibration and no process


def test_a_valid_protocol_passes_the_check() -> None:
    from live.demo.run import check_protocol
    from teleop.config.load import load_config
    check_protocol(load_config(None), "paper,minor")
    check_protocol(load_config(CONFIGS / "instrument-3dof.yaml"), "short")
