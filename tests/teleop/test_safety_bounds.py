"""Hard bounds of the safety-relevant settings: one line naming key, bound and reason; the waiver."""
from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

from teleop.config.bounds import BOUNDS, Bound, bounded_keys, waiver_lines, waivers
from teleop.config.load import load_config
from teleop.errors import ConfigError

ROOT = Path(__file__).resolve().parents[2]


def _past(b: Bound) -> object:
    """A value on the wrong side of ``b``."""
    if b.op == "==":
        return "0.0.0.0" if isinstance(b.limit, str) else not b.limit
    return float(b.limit) * 10.0 + 1.0 if b.op == "<=" else float(b.limit) * 0.5


def _nested(key: str, value: object) -> dict:
    """``a.b[].c`` -> {"a": {"b": [{"name": "j0", "c": value}]}} (a list entry needs a joint name)."""
    head, _, rest = key.partition(".")
    if head.endswith("[]"):
        return {head[:-2]: [{"name": "j0", **_nested(rest, value)}]}
    return {head: _nested(rest, value) if rest else value}


def _yaml(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "cfg.yaml"
    path.write_text(text, encoding="utf-8")
    return path


def test_the_defaults_are_within_every_bound():
    cfg = load_config(ROOT / "configs" / "default.yaml")
    assert cfg.safety.override == () and waivers(cfg) == []
    for name in ("sim.yaml", "instrument-3dof.yaml"):
        load_config(ROOT / "configs" / name)


def test_a_watchdog_past_its_bound_is_one_line_naming_key_bound_and_reason(tmp_path):
    path = _yaml(tmp_path, "master:\n  watchdog_ms: 600000\n")
    with pytest.raises(ConfigError) as e:
        load_config(path)
    msg = str(e.value)
    assert "\n" not in msg
    assert msg.startswith(f"{path}:2: master.watchdog_ms = 600000: above the hard bound 100 ms: ")
    assert "fault suite" in msg and "safety.override" in msg


@pytest.mark.parametrize("bound", BOUNDS, ids=lambda b: b.key)
def test_every_bound_refuses_a_value_past_it_and_its_waiver_admits_it(bound):
    data = _nested(bound.key, _past(bound))
    if bound.key.startswith("instrument.joints"):
        data["pair_control"] = {"axes": []}
    path = bound.key.replace("[]", "[0]")
    from teleop.config.load import config_from_dict
    with pytest.raises(ConfigError, match="^<dict>: " + re.escape(f"{path} = ")):
        config_from_dict(data)
    cfg = config_from_dict({**data, "safety": {"override": [bound.key]}})
    (w,) = waivers(cfg)
    assert w["key"] == bound.key and w["past_bound"] and w["values"][path] == _past(bound)
    assert "PAST its hard bound" in waiver_lines(cfg)[0]


def test_a_value_within_its_bound_passes_and_a_waiver_of_it_says_so():
    from teleop.config.load import config_from_dict
    cfg = config_from_dict({"safety": {"override": ["slave.watchdog_ms"]}})
    (w,) = waivers(cfg)
    assert not w["past_bound"] and "within its hard bound" in waiver_lines(cfg)[0]


def test_an_unknown_key_in_the_override_is_refused(tmp_path):
    path = _yaml(tmp_path, "safety:\n  override: [master.mapping.forcelimit]\n")
    with pytest.raises(ConfigError, match=r"safety.override\[0\]: 'master.mapping.forcelimit' has no hard bound "
                                          r"to waive \(did you mean 'master.mapping.force_limit'\?\)$"):
        load_config(path)


def test_overrides_cannot_pass_a_bound_without_the_waiver_and_can_with_it(tmp_path):
    path = _yaml(tmp_path, "master:\n  mapping:\n    force_limit: 1.0e6\n")
    with pytest.raises(ConfigError, match="master.mapping.force_limit = 1e\\+06: above the hard bound 10 N"):
        load_config(None, {"master.mapping.force_limit": 1.0e6})
    cfg = load_config(path, {"safety.override": ["master.mapping.force_limit"]})
    assert cfg.master.mapping.force_limit == 1.0e6


def test_every_bound_names_a_schema_key_once_with_a_reason():
    from teleop.config.load import config_from_dict
    cfg = config_from_dict({"instrument": {"joints": [{"name": "j0"}]}, "safety": {"override": bounded_keys()}})
    assert len(set(bounded_keys())) == len(BOUNDS) == len(waivers(cfg))
    for b, w in zip(BOUNDS, waivers(cfg), strict=False):
        assert len(w["values"]) == 1 and not w["past_bound"] and len(b.reason) > 40


def test_the_cli_refuses_an_unsafe_config_with_exit_status_2(tmp_path):
    path = _yaml(tmp_path, "master:\n  mapping:\n    force_limit: 1.0e6\n")
    for side in ("slave", "master"):
        r = subprocess.run([sys.executable, "-m", "live.cli", side, "--config", str(path), "--run-dir",
                            str(tmp_path / side)], capture_output=True, text=True, timeout=120, cwd=ROOT)
        assert r.returncode == 2, r.stderr
        lines = r.stderr.strip().splitlines()
        assert len(lines) == 1 and "master.mapping.force_limit = 1e+06: above the hard bound 10 N: " in lines[0]
        assert not (tmp_path / side).exists()


def test_a_waived_run_announces_and_records_the_waiver(tmp_path):
    from teleop.session.transport import free_tcp_port, loopback_endpoint
    path = _yaml(tmp_path, "master:\n  mapping:\n    force_limit: 1.0e6\nsafety:\n  override: "
                           "[master.mapping.force_limit]\nrecording:\n  rerun: 'off'\n")
    run = tmp_path / "run"
    r = subprocess.run([sys.executable, "-m", "live.cli", "master", "--config", str(path), "--listen",
                        loopback_endpoint(free_tcp_port()), "--run-dir", str(run), "--max-duration", "0.5"],
                       capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert "SAFETY WAIVER (safety.override): master.mapping.force_limit = 1e+06 N, PAST" in r.stderr + r.stdout
    stats = json.loads((run / "master_stats.json").read_text(encoding="utf-8"))
    (w,) = stats["safety_waivers"]
    assert w["key"] == "master.mapping.force_limit" and w["past_bound"] and w["values"] == {
        "master.mapping.force_limit": 1.0e6}


def test_the_reference_page_lists_every_bound_with_its_reason():
    page = (ROOT / "docs" / "reference" / "safety-bounds.md").read_text(encoding="utf-8")
    rows = {line.split("|")[1].strip(" `"): line for line in page.splitlines() if line.startswith("| `")}
    assert set(rows) == set(bounded_keys())
    for b in BOUNDS:
        limit = str(b.limit).lower() if isinstance(b.limit, (bool, str)) else f"{b.limit:g}"
        assert b.reason in rows[b.key] and limit in rows[b.key].split("|")[3]
