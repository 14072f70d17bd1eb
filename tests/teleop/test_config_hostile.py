"""Hostile and absurd config files end in one ConfigError line naming the file (and its line, column and key where
there is one) within a second: the reader's limits (teleop/config/reader.py), the kinds of the path keys
(teleop/config/paths.py) and the bounded rates and waits (teleop/config/ranges.py).

The processor time of each load (``time.process_time``: this process's own, whatever else runs on the machine) is
asserted below a second: the limits apply while the file is read, so that is a property of the limits (an alias bomb
without them takes hours), not a benchmark."""
from __future__ import annotations

import re
import time
from pathlib import Path

import pytest

from teleop.arms import is_bimanual, load_arms
from teleop.config.load import load_config
from teleop.config.paths import DIR_KEYS, FILE_KEYS
from teleop.config.reader import MAX_ALIASES, MAX_BYTES, MAX_DEPTH, MAX_INT_DIGITS, MAX_NODES
from teleop.errors import ConfigError

#: a 9-level "billion laughs": 324 bytes that expand to 9^9 (387 million) strings
BOMB = 'a: &a ["x","x","x","x","x","x","x","x","x"]\n' + "".join(
    f"{c}: &{c} [" + ",".join([f"*{p}"] * 9) + "]\n" for p, c in zip("abcdefgh", "bcdefghi", strict=False))


def _refused(path: Path, loader=load_config) -> str:
    """The one-line message of the ConfigError that loading ``path`` raises, checked to take under a second of this
    process's processor time."""
    t0 = time.process_time()
    with pytest.raises(ConfigError) as e:
        loader(path)
    elapsed = time.process_time() - t0
    msg = str(e.value)
    assert elapsed < 1.0, f"{elapsed:.2f} s to refuse {path.name}: {msg[:200]}"
    assert "\n" not in msg and msg.startswith(str(path)), msg
    return msg


def _write(tmp_path: Path, text: str, name: str = "x.yaml") -> Path:
    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    return p


def test_alias_bomb_ends_at_the_node_budget(tmp_path):
    p = _write(tmp_path, BOMB)
    assert len(BOMB) < 400
    msg = _refused(p)
    assert re.match(re.escape(str(p)) + r":\d+:\d+: \w", msg) and f"more than {MAX_NODES} values" in msg


def test_alias_bomb_is_refused_by_the_bimanual_check_too(tmp_path):
    p = _write(tmp_path, BOMB)
    t0 = time.process_time()
    assert is_bimanual(p) is False             # the ordinary loader then says what is wrong
    assert time.process_time() - t0 < 1.0
    _refused(p, load_arms)


def test_too_many_aliases(tmp_path):
    p = _write(tmp_path, "x: &x 1\nl: [" + ", ".join(["*x"] * (MAX_ALIASES + 1)) + "]\n")
    msg = _refused(p)
    assert msg.startswith(f"{p}:2:") and f"l[{MAX_ALIASES}]: more than {MAX_ALIASES} aliases" in msg


def test_recursive_alias(tmp_path):
    p = _write(tmp_path, "rig:\n  simulated: &s {motor: *s}\n")
    assert _refused(p).startswith(f"{p}:2:25: rig.simulated.motor: alias *s inside its own anchor &s")


def test_aliases_within_the_budget_still_load(tmp_path):
    p = _write(tmp_path, "sheath:\n  runs:\n    - &r {length: 0.3}\n    - *r\n"
                         "instrument:\n  joints:\n    - &j {name: a, limits: [-1, 1]}\n    - {<<: *j, name: b}\n")
    cfg = load_config(p)
    assert [r.length for r in cfg.sheath.runs] == [0.3, 0.3] and [j.name for j in cfg.instrument.joints] == ["a", "b"]


@pytest.mark.parametrize("opener, closer", [("[", "]"), ("{a: ", "}")])
def test_20000_deep_nesting_ends_at_the_depth_limit(tmp_path, opener, closer):
    p = _write(tmp_path, opener * 20_000 + closer * 20_000 + "\n")
    msg = _refused(p)
    assert re.match(re.escape(str(p)) + r":1:\d+: ", msg) and f"nested deeper than {MAX_DEPTH} levels" in msg


def test_nesting_at_the_depth_limit_reads(tmp_path):
    p = _write(tmp_path, "a: " + "[" * (MAX_DEPTH - 1) + "1" + "]" * (MAX_DEPTH - 1) + "\n")
    assert "unknown key 'a'" in _refused(p)          # read whole; the schema refuses the key


@pytest.mark.parametrize("text, where, kind", [
    ("? [a, b]\n: 1\n", ":1:3: ", "a list"),
    ("{[1]: 2}\n", ":1:2: ", "a list"),
    ("rig:\n  {a: 1}: 2\n", ":2:3: rig: ", "a mapping"),
    ("x: &k [1]\nrig: {*k : 1}\n", ":2:7: rig: ", "a list"),
])
def test_unhashable_key(tmp_path, text, where, kind):
    p = _write(tmp_path, text)
    assert _refused(p).startswith(f"{p}{where}{kind} as a key; a key is a name")


def test_unhashable_key_before_the_bimanual_check(tmp_path):
    p = _write(tmp_path, "? [a, b]\n: 1\n")
    assert is_bimanual(p) is False
    assert _refused(p, load_arms).startswith(f"{p}:1:3: a list as a key")


def test_5000_digit_integer_names_file_line_and_key(tmp_path):
    p = _write(tmp_path, "rig:\n  rate_hz: " + "9" * 5000 + "\n")
    assert _refused(p) == (f"{p}:2:12: rig.rate_hz: an integer of 5000 digits; expected a number of at most "
                           f"{MAX_INT_DIGITS} digits")


@pytest.mark.parametrize("text, match", [
    ("instrument:\n  id: 2001-13-01\n", r":2:7: instrument.id: month must be in 1..12"),
    ("rig:\n  rate_hz: !!int 0x1F\n", r":2:12: rig.rate_hz: invalid literal"),
    ("rig:\n  rate_hz: !!python/object:os.system 1\n", r":2:12: rig.rate_hz: could not determine a constructor"),
])
def test_values_no_constructor_accepts_name_file_line_and_key(tmp_path, text, match):
    p = _write(tmp_path, text)
    assert re.match(re.escape(str(p)) + match, _refused(p))


def test_a_directory_as_the_config_says_so(tmp_path):
    assert _refused(tmp_path) == f"{tmp_path}: is a directory; expected a config file (YAML)"


@pytest.mark.parametrize("size", [MAX_BYTES + 1, 5 * 1024 * 1024])
def test_a_file_above_the_size_cap_is_refused_before_parsing(tmp_path, size):
    p = tmp_path / "big.yaml"
    p.write_text("sheath:\n  runs:\n" + "    - {length: 0.1}\n" * (size // 20 + 1), encoding="utf-8")
    assert _refused(p) == f"{p}: {p.stat().st_size} bytes; a config file is at most {MAX_BYTES} bytes"


@pytest.mark.parametrize("text", [
    "[" + ", ".join(["1"] * (MAX_BYTES // 3)) + "]\n",                             # values past the node budget
    "sheath:\n  runs:\n" + "    - {length: 0.1}\n" * (MAX_BYTES // 21),
    "a: '" + "x " * (MAX_BYTES // 2 - 8) + "'\n",                                   # one long scalar
    "\n" * (MAX_BYTES - 16) + "a: 1\n",
])
def test_the_costliest_files_under_the_cap_end_within_a_second(tmp_path, text):
    assert len(text.encode()) <= MAX_BYTES
    _refused(_write(tmp_path, text))


def _nested(key: str, value: str) -> str:
    """``a.b.c`` = value as block YAML."""
    parts = key.split(".")
    parents = "".join(f"{'  ' * i}{k}:\n" for i, k in enumerate(parts[:-1]))
    return parents + f"{'  ' * (len(parts) - 1)}{parts[-1]}: {value}\n"


@pytest.mark.parametrize("key", DIR_KEYS)
def test_a_file_where_a_directory_is_written(tmp_path, key):
    f = tmp_path / "a-file"
    f.write_text("x")
    for value, problem in ((f, "is a file, not a directory"), (f / "sub", f"cannot be made: '{f}' is a file")):
        p = _write(tmp_path, _nested(key, str(value)))
        line = len(key.split("."))
        assert _refused(p).startswith(f"{p}:{line}: {key}: '{value}' {problem}; expected a directory")


@pytest.mark.parametrize("key", FILE_KEYS + ("instrument.tool",))
def test_a_directory_where_a_file_is_read(tmp_path, key):
    d = tmp_path / "a-dir"
    d.mkdir()
    p = _write(tmp_path, _nested(key, str(d)))
    msg = _refused(p)
    assert msg.startswith(f"{p}:{len(key.split('.'))}: {key}: ") and "is a directory; expected a" in msg


@pytest.mark.parametrize("key, value, expected", [
    ("rig.rate_hz", "1e-6", "10..10000"), ("rig.rate_hz", "1e300", "10..10000"),
    ("master.rate_hz", "1e-6", "10..10000"), ("master.rate_hz", "100000", "10..10000"),
    ("slave.heartbeat_hz", "1e-6", "1..1000"), ("ros2.rate_hz", "1e300", "1..1000"),
    ("rig.zenoh.wait_s", "1e300", "0.01..3600"), ("transport.run_id_timeout", "1e300", "0..60"),
    ("recording.flush_interval", "1e300", "0.001..10"),
])
def test_rates_and_waits_are_bounded(tmp_path, key, value, expected):
    p = _write(tmp_path, _nested(key, value))
    line = len(key.split("."))
    assert re.fullmatch(re.escape(f"{p}:{line}: {key}: ") + r"\S+ is out of range: expected "
                        + re.escape(expected) + r" \[\w+\]", _refused(p))


def test_a_config_saved_as_utf16_or_latin1_is_named_as_such(tmp_path):
    p = tmp_path / "u16.yaml"
    p.write_text("rig:\n  rate_hz: 500\n", encoding="utf-16")
    assert "not a UTF-8 text file (looks like UTF-16 text, byte-order mark at byte 0)" in _refused(p)
    p = tmp_path / "latin1.yaml"
    p.write_bytes("# 90\xb0 bend\nrig:\n  rate_hz: 500\n".encode("latin-1"))
    assert _refused(p).startswith(f"{p}:1: not a UTF-8 text file (byte 0xb0 at byte 4 is not UTF-8")
