"""``teleop keys``: the installation's credentials shown, made when missing, exported, renewed, and a role's Zenoh
entries printed for another Zenoh program."""
from __future__ import annotations

import json
import stat

import pytest

from live.cli import main


def test_keys_are_made_shown_exported_and_renewed(tmp_path, monkeypatch, capsys):
    folder = tmp_path / "keys"
    monkeypatch.setenv("TSM_TELEOP_KEYS", str(folder))
    assert main(["keys"]) == 0
    out = capsys.readouterr().out
    assert f"installation credentials: {folder}" in out and "observer" in out
    password = (folder / "master.password").read_text()
    assert main(["keys", "--export", str(tmp_path / "copy")]) == 0
    assert (tmp_path / "copy" / "master.password").read_text() == password
    assert stat.S_IMODE((tmp_path / "copy").stat().st_mode) == 0o700
    assert main(["keys", "--export", str(tmp_path / "copy")]) == 2          # never over an existing path
    assert "already exists" in capsys.readouterr().err
    assert main(["keys", "--renew"]) == 0
    assert (folder / "master.password").read_text() != password


def test_a_roles_zenoh_entries_are_printed_as_json(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("TSM_TELEOP_KEYS", str(tmp_path / "keys"))
    assert main(["keys", "--zenoh-config", "master"]) == 0
    cfg = json.loads(capsys.readouterr().out)
    usrpwd = cfg["transport"]["auth"]["usrpwd"]
    assert (usrpwd["user"] == "master"
            and usrpwd["password"] == (tmp_path / "keys" / "master.password").read_text().strip())
    assert cfg["access_control"]["enabled"] and usrpwd["dictionary_file"] == str(tmp_path / "keys" / "dictionary")
    with pytest.raises(SystemExit):
        main(["keys", "--zenoh-config", "surgeon"])
