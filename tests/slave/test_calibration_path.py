"""Where calibration files go: the per-user data directory unless the config names a path, never the
current directory by default."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from slave.calibration_file import calibration_path, user_calibration_dir
from teleop.config.load import config_from_dict

ROOT = Path(__file__).resolve().parents[2]


def test_the_default_is_the_xdg_data_home(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    cfg = config_from_dict({"instrument": {"id": "cal0"}})
    assert cfg.calibration.dir is None
    assert calibration_path(cfg) == tmp_path / "data" / "tsm-teleop" / "calibration" / "cal0.yaml"


def test_without_xdg_data_home_it_is_under_the_home_directory(tmp_path, monkeypatch):
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    for value in (None, "", "relative/data"):      # unset, empty or relative: ignored (XDG base directory spec)
        if value is None:
            monkeypatch.delenv("XDG_DATA_HOME", raising=False)
        else:
            monkeypatch.setenv("XDG_DATA_HOME", value)
        assert user_calibration_dir() == tmp_path / "home" / ".local" / "share" / "tsm-teleop" / "calibration"


def test_a_path_named_in_the_config_is_kept(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    cfg = config_from_dict({"instrument": {"id": "cal0"}, "calibration": {"dir": str(tmp_path / "mine")}})
    assert calibration_path(cfg) == tmp_path / "mine" / "cal0.yaml"


def test_teleop_calibrate_with_the_defaults_writes_nothing_into_the_current_directory(tmp_path):
    cwd, data = tmp_path / "cwd", tmp_path / "data"
    cwd.mkdir()
    (cwd / "cfg.yaml").write_text("instrument:\n  id: calx\ncalibration:\n  speed: 0.01\n", encoding="utf-8")
    env = {"PATH": "/usr/bin:/bin", "HOME": str(tmp_path / "home"), "XDG_DATA_HOME": str(data)}
    r = subprocess.run([sys.executable, "-m", "live.cli", "calibrate", "--config", "cfg.yaml"], cwd=cwd, env=env,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    written = data / "tsm-teleop" / "calibration" / "calx.yaml"
    assert written.is_file() and f"wrote {written}" in r.stdout
    assert sorted(p.name for p in cwd.rglob("*")) == ["cfg.yaml"]
