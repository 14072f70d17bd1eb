"""``teleop calibrate`` writes where the slave reloads from (``calibration.dir``, by default the per-user data
directory), never into the project's configs, whose calibration file is a read-only example."""
from __future__ import annotations

from pathlib import Path

import pytest

from live.calibrate import destination
from live.cli import main
from teleop.config.files import configs_dir
from teleop.config.load import config_from_dict, load_config
from teleop.errors import ConfigError

CONFIGS = Path(__file__).resolve().parents[2] / "configs"


@pytest.mark.parametrize("name", ["instrument-3dof.yaml", "instrument-spindle.yaml", "sim.yaml"])
def test_the_shipped_configs_calibrate_into_the_user_data_directory(tmp_path, monkeypatch, name):
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    cfg = load_config(CONFIGS / name)
    assert cfg.calibration.dir is None
    assert destination(cfg, None) == tmp_path / "data" / "tsm-teleop" / "calibration" / f"{cfg.instrument.id}.yaml"


def test_teleop_calibrate_of_the_joint_instrument_leaves_the_shipped_example_alone(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    example = CONFIGS / "calibration" / "flex3.yaml"
    before = example.read_bytes()
    assert main(["calibrate", "--config", str(CONFIGS / "instrument-3dof.yaml")]) == 0
    written = tmp_path / "data" / "tsm-teleop" / "calibration" / "flex3.yaml"
    assert written.is_file() and capsys.readouterr().out.splitlines()[-1] == f"wrote {written}"
    assert example.read_bytes() == before


def test_a_destination_inside_the_configs_is_refused_before_the_routine_runs(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    example = configs_dir() / "calibration" / "flex3.yaml"
    before = example.read_bytes()
    assert main(["calibrate", "--config", str(CONFIGS / "instrument-3dof.yaml"), "--out", str(example)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"teleop: error: --out {example}: ") and "read-only" in err[0]
    assert example.read_bytes() == before
    cfg = config_from_dict({"instrument": {"id": "calx"}, "calibration": {"dir": str(configs_dir() / "calibration")}})
    with pytest.raises(ConfigError, match=r"^calibration.dir .*: .* read-only examples; expected a path elsewhere"):
        destination(cfg, None)


def test_another_out_says_which_file_the_slave_reloads(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    out = tmp_path / "elsewhere.yaml"
    assert main(["calibrate", "--config", str(CONFIGS / "instrument-spindle.yaml"), "--out", str(out)]) == 0
    reload = tmp_path / "data" / "tsm-teleop" / "calibration" / "forceps1.yaml"
    assert capsys.readouterr().out.splitlines()[-1] == \
        f"wrote {out} (the slave of this config reloads {reload}, not this file)"
    assert out.is_file() and not reload.exists()
