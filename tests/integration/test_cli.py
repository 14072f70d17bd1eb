"""`teleop` on bad input: one line ``teleop: error: ...`` on stderr, exit code 2, no traceback."""
from __future__ import annotations

import subprocess
import sys

import pytest

from live.cli import build_parser, main
from live.sides import endpoints

TYPO = "rig:\n  rate_hzz: 1000\n"


def one_error_line(capsys) -> str:
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, err
    assert lines[0].startswith("teleop: error: ") and "Traceback" not in err
    return lines[0]


@pytest.mark.parametrize("side", ["slave", "master", "demo"])
def test_config_typo(side, tmp_path, capsys):
    cfg = tmp_path / "typo.yaml"
    cfg.write_text(TYPO)
    assert main([side, "--config", str(cfg), "--run-dir", str(tmp_path / "run")]) == 2
    line = one_error_line(capsys)
    assert "rate_hzz" in line and "typo.yaml" in line


@pytest.mark.parametrize("side", ["slave", "master", "demo"])
def test_missing_config_file(side, tmp_path, capsys):
    missing = tmp_path / "nope.yaml"
    assert main([side, "--config", str(missing)]) == 2
    assert "nope.yaml" in one_error_line(capsys)


def test_unknown_protocol(tmp_path, capsys):
    assert main(["master", "--protocol", "papr", "--run-dir", str(tmp_path)]) == 2
    assert "unknown protocol 'papr'" in one_error_line(capsys)


def test_bad_endpoint(tmp_path, capsys):
    assert main(["slave", "--listen", "tcp/nowhere", "--run-dir", str(tmp_path)]) == 2
    assert "tcp/nowhere" in one_error_line(capsys)


def test_analyze_missing_file(tmp_path, capsys):
    pytest.importorskip("study.analyze", reason="study.analyze is being written by another engineer")
    assert main(["analyze", str(tmp_path / "missing.csv")]) == 2
    assert "missing.csv" in one_error_line(capsys)


def test_console_script_exit_code_and_single_line(tmp_path):
    cfg = tmp_path / "typo.yaml"
    cfg.write_text(TYPO)
    proc = subprocess.run([sys.executable, "-m", "live.cli", "slave", "--config", str(cfg)],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1 and proc.stderr.startswith("teleop: error: ") and "Traceback" not in proc.stderr


def test_endpoint_flags_replace_both_lists():
    p = build_parser(["slave"])
    assert endpoints(p.parse_args(["slave"])) == (None, None)
    assert endpoints(p.parse_args(["slave", "--connect", "tcp/127.0.0.1:1"])) == ((), ("tcp/127.0.0.1:1",))
    args = p.parse_args(["slave", "--listen", "tcp/127.0.0.1:1", "--listen", "tcp/127.0.0.1:2"])
    assert endpoints(args) == (("tcp/127.0.0.1:1", "tcp/127.0.0.1:2"), ())
