"""`teleop` on hostile and absurd input: one line ``teleop: error: <file>:<line>...`` on stderr, exit code 2, within a
second of processor time (``time.process_time``: this process's own, whatever else runs), before any process starts (the
config reader's limits, the kinds of the config's paths and of the path arguments, the bounded rates).

The modules the sides load before reading their config are imported here first, so that the second each case is
given is the reading's, not the imports'."""
from __future__ import annotations

import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

import live.demo.main  # noqa: F401  (the imports each side makes before it reads its config)
import slave.node  # noqa: F401
import slave.recording.rig  # noqa: F401
from live.cli import main
from teleop.config.reader import MAX_BYTES

BOMB = 'a: &a ["x","x","x","x","x","x","x","x","x"]\n' + "".join(
    f"{c}: &{c} [" + ",".join([f"*{p}"] * 9) + "]\n" for p, c in zip("abcdefgh", "bcdefghi", strict=False))


@pytest.fixture(autouse=True)
def no_process(monkeypatch):
    """Every case ends before a child process is started."""
    def refuse(*args, **kwargs):
        raise AssertionError(f"a process was started: {args[:1]}")
    monkeypatch.setattr(subprocess, "Popen", refuse)


def _error_line(capsys, argv: list[str]) -> str:
    """The one stderr line of ``teleop argv``, checked to end with exit code 2 within a second of processor time."""
    t0 = time.process_time()
    code = main(argv)
    elapsed = time.process_time() - t0
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert code == 2 and len(lines) == 1 and "Traceback" not in err, err
    assert lines[0].startswith("teleop: error: "), err
    assert elapsed < 1.0, f"{elapsed:.2f} s: {lines[0][:200]}"
    return lines[0][len("teleop: error: "):]


def _case(tmp_path: Path, name: str) -> tuple[Path, str]:
    """(config file, regex of where its error is: file, line and column or key) of case ``name``."""
    a_file, a_dir = tmp_path / "a-file", tmp_path / "a-dir"
    a_file.write_text("x")
    a_dir.mkdir(exist_ok=True)
    text, where = {
        "alias bomb": (BOMB, r":\d+:\d+: .*more than \d+ values"),
        "20000-deep nesting": ("[" * 20_000 + "]" * 20_000 + "\n", r":1:\d+: .*nested deeper than \d+ levels"),
        "list as a key": ("? [a, b]\n: 1\n", r":1:3: a list as a key"),
        "flow list as a key": ("{[1]: 2}\n", r":1:2: a list as a key"),
        "5000-digit integer": ("rig:\n  rate_hz: " + "9" * 5000 + "\n",
                               r":2:12: rig.rate_hz: an integer of 5000 digits"),
        "recording.dir a file": (f"recording:\n  dir: {a_file}\n", r":2: recording.dir: .* is a file"),
        "calibration.dir a file": (f"calibration:\n  dir: {a_file}\n", r":2: calibration.dir: .* is a file"),
        "device file a directory": (f"master:\n  device:\n    file: {a_dir}\n",
                                    r":3: master.device.file: .* is a directory"),
        "rate 1e-6": ("rig:\n  rate_hz: 1e-6\n", r":2: rig.rate_hz: 1e-06 is out of range: expected 10..10000"),
        "rate 1e300": ("rig:\n  rate_hz: 1e300\n", r":2: rig.rate_hz: 1e\+300 is out of range: expected 10..10000"),
        "5 MB file": ("sheath:\n  runs:\n" + "    - {length: 0.1}\n" * (5 * 2 ** 20 // 20),
                      rf": \d+ bytes; a config file is at most {MAX_BYTES} bytes"),
    }[name]
    p = tmp_path / "hostile.yaml"
    p.write_text(text, encoding="utf-8")
    return p, where


CASES = ["alias bomb", "20000-deep nesting", "list as a key", "flow list as a key", "5000-digit integer",
         "recording.dir a file", "calibration.dir a file", "device file a directory", "rate 1e-6", "rate 1e300",
         "5 MB file"]


@pytest.mark.parametrize("side", ["slave", "master", "demo"])
@pytest.mark.parametrize("case", CASES)
def test_hostile_config_ends_in_one_line_naming_file_and_line(tmp_path, capsys, side, case):
    path, where = _case(tmp_path, case)
    line = _error_line(capsys, [side, "--config", str(path), "--run-dir", str(tmp_path / "run")])
    assert re.match(re.escape(str(path)) + where, line), line
    assert not (tmp_path / "run").exists()              # refused before the run directory was made


@pytest.mark.parametrize("side", ["slave", "master", "demo", "record", "bridge", "calibrate"])
def test_a_directory_as_config_says_it_is_a_directory(tmp_path, capsys, side):
    assert _error_line(capsys, [side, "--config", str(tmp_path)]) == \
        f"--config {tmp_path}: is a directory; expected a file"


@pytest.mark.parametrize("argv, expected", [
    (["slave", "--run-dir", "{file}"], "--run-dir {file}: is a file, not a directory; expected a directory"),
    (["master", "--run-dir", "{file}/run"],
     "--run-dir {file}/run: cannot be made: '{file}' is a file; expected a directory"),
    (["demo", "--recording", "{dir}"], "--recording {dir}: is a directory; expected a file"),
    (["record", "--journals", "{file}"], "--journals {file}: is a file, not a directory; expected a directory"),
    (["analyze", "--kaist", "{dir}", "--model-out", "{file}"],
     "--model-out {file}: is a file, not a directory; expected a directory"),
    (["analyze", "{dir}", "--model-out", "{file}"], "FILE {dir}: is a directory; expected a file"),
    (["slave", "--max-duration", "nan"], "--max-duration nan: expected a number of seconds >= 0"),
    (["master", "--max-duration", "-1"], "--max-duration -1.0: expected a number of seconds >= 0"),
])
def test_path_and_duration_arguments_of_the_wrong_kind(tmp_path, capsys, argv, expected):
    a_file, a_dir = tmp_path / "a-file", tmp_path / "a-dir"
    a_file.write_text("x")
    a_dir.mkdir()
    fill = {"file": str(a_file), "dir": str(a_dir)}
    assert _error_line(capsys, [a.format(**fill) for a in argv]) == expected.format(**fill)


def test_the_console_script_ends_an_alias_bomb_in_one_line(tmp_path, monkeypatch):
    monkeypatch.undo()                                   # this test starts the program itself
    p = tmp_path / "bomb.yaml"
    p.write_text(BOMB)
    proc = subprocess.run([sys.executable, "-m", "live.cli", "slave", "--config", str(p)], capture_output=True,
                          text=True, timeout=60)
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr
    assert re.match(r"teleop: error: " + re.escape(str(p)) + r":\d+:\d+: ", proc.stderr)


def test_a_model_file_may_be_written_over(tmp_path):
    """FILE.csv --model-out OUT.yaml writes one file: an existing one is no directory to refuse."""
    import argparse

    from live.cli import path_args_problem
    out = tmp_path / "m.model.yaml"
    out.write_text("x")
    csv = tmp_path / "r.csv"
    csv.write_text("x")
    args = argparse.Namespace(command="analyze", file=str(csv), model_out=str(out))
    assert path_args_problem(args) is None                # the file's own check (study.tendon_model) takes it
    args.file = None
    assert "expected a directory" in (path_args_problem(args) or "")
