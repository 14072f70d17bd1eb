"""Tool files (configs/tools/, teleop.config.tools): the shipped tools load, the loader refuses bad files in one line
naming the file and key, a config names its tool, and ``--tool`` turns into the one-run calibration's load gain."""
from __future__ import annotations

from pathlib import Path

import pytest

from study.mrd.tools import tool_calibration, tool_entry
from teleop.config.files import tool_file
from teleop.config.load import load_config
from teleop.config.tools import TOOL_RANGES, Tool, load_tool, tool_names, tools_dir
from teleop.errors import ConfigError

LEFT = "davinci-maryland-left"


def _text(name: str = LEFT) -> str:
    return (tools_dir() / f"{name}.yaml").read_text()


def _write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "tool.yaml"
    p.write_text(text)
    return p


def test_every_shipped_tool_loads_and_names_its_file():
    names = tool_names()
    assert {LEFT, "davinci-maryland-right"} <= set(names)
    for n in names:
        t = load_tool(n)
        assert isinstance(t, Tool) and t.name == n
        assert t.load_gain.value > 0 and t.load_gain.uncertainty >= 0
        assert t.limits.spindle_angle[0] < t.limits.spindle_angle[1]
        assert "University of Minnesota" in t.source.attribution and "ODbL" in t.source.licence


def test_a_tool_is_found_by_name_or_by_path():
    by_name = load_tool(LEFT)
    assert load_tool(tools_dir() / f"{LEFT}.yaml") == by_name
    assert tool_file(LEFT) == tools_dir() / f"{LEFT}.yaml"
    with pytest.raises(ConfigError, match="no such tool file.*shipped tools: .*davinci-maryland-left"):
        load_tool("no-such-tool")


@pytest.mark.parametrize("old,new,words", [
    ("axis: left jaw", "axis: left jaw\nload_gian: 1.0", r"tool.yaml:\d+: unknown key 'load_gian'"),
    ("  value: 0.9427", "  value: high", r"tool.yaml:\d+: load_gain.value: expected a number, got 'high'"),
    ("  value: 0.9427", "  value: -0.9", r"load_gain.value: -0.9 is out of range: expected > 0"),
    ("  uncertainty: 0.0049", "  uncertainty: -1", r"load_gain.uncertainty: -1.0 is out of range: expected >= 0"),
    ("  spindle_angle: [0.041, 1.027]", "  spindle_angle: [1.1, 1.0]",
     r"limits.spindle_angle: expected \[lower, upper\]"),
    ("  runs: mid", "  runs: 'a run'", r"calibration.runs: 'a run' is not 'mid' or a run name"),
    ("name: davinci-maryland-left", "name: left jaw", r"name: 'left jaw' is not a tool name"),
    ("axis: left jaw\n", "", r"missing key 'axis'"),
])
def test_the_loader_refuses_a_bad_file_naming_the_key(tmp_path, old, new, words):
    text = _text()
    assert old in text
    with pytest.raises(ConfigError, match=words) as e:
        load_tool(_write(tmp_path, text.replace(old, new, 1)))
    assert str(tmp_path / "tool.yaml") in str(e.value) and "\n" not in str(e.value)


def test_every_range_names_a_key_of_the_schema():
    t = load_tool(LEFT)
    for key in TOOL_RANGES:
        obj: object = t
        for part in key.split("."):
            obj = getattr(obj, part)
        assert isinstance(obj, float)


def test_a_config_names_its_tool_and_a_missing_one_is_refused(tmp_path):
    cfg = tmp_path / "c.yaml"
    cfg.write_text(f"instrument:\n  tool: {LEFT}\n")
    assert load_config(cfg).instrument.tool == LEFT
    assert load_config().instrument.tool is None
    cfg.write_text("instrument:\n  tool: nowhere-forceps\n")
    with pytest.raises(ConfigError, match=r"c.yaml:2: instrument.tool: tool 'nowhere-forceps': no such tool file"):
        load_config(cfg)


def test_the_tool_gives_the_load_gain_of_the_one_run_calibration():
    t = load_tool(LEFT)
    g = repr(t.load_gain.value)
    assert tool_calibration(None, None) is None and tool_calibration("00", None) == "00"
    assert tool_calibration(None, t) == f"gain={g}:{t.calibration.runs}"
    assert tool_calibration("12", t) == f"gain={g}:12"
    assert tool_calibration("kinematic:mid", t) == f"gain={g}:kinematic:mid"
    with pytest.raises(ConfigError, match="the load gain comes from --tool"):
        tool_calibration("gain=0.9:00", t)
    with pytest.raises(ConfigError, match="not for segment"):
        tool_calibration("segment:3", t)
    entry = tool_entry(t)
    assert entry["load_gain"]["measured_on"] == t.load_gain.measured_on and entry["name"] == LEFT
