"""``teleop --version`` prints the installed distribution's version and exits 0."""
from __future__ import annotations

import importlib.metadata

import pytest

from live import cli


def test_version_prints_the_installed_distributions_version(capsys):
    with pytest.raises(SystemExit) as exit_info:
        cli.main(["--version"])
    assert exit_info.value.code == 0
    assert capsys.readouterr().out.strip() == f"teleop {importlib.metadata.version('tsm-teleop')}"


def test_version_without_an_installed_distribution_says_unknown(monkeypatch):
    def missing(name: str) -> str:
        raise importlib.metadata.PackageNotFoundError(name)

    monkeypatch.setattr(importlib.metadata, "version", missing)
    assert cli.version() == "unknown"


def test_every_subcommand_is_still_offered():
    parser = cli.build_parser(["demo"])
    sub = next(a for a in parser._actions if a.dest == "command")
    assert {"demo", "master", "slave", "record", "router", "bridge", "calibrate", "replay", "analyze",
            "devices"} <= set(sub.choices)
