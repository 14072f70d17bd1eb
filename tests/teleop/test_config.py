"""Strict config loading: defaults == default.yaml, merge, and each kind of error message."""
from __future__ import annotations

import dataclasses
import math
import re
import types
from pathlib import Path
from types import NoneType
from typing import Union, get_args, get_origin, get_type_hints

import pytest

from teleop.config.load import config_from_dict, config_to_dict, load_config, write_config
from teleop.config.ranges import RANGES
from teleop.config.schema import Config, RunConfig, TransportConfig
from teleop.errors import ConfigError

CONFIGS = Path(__file__).resolve().parents[2] / "configs"


def _write(tmp_path: Path, text: str, name: str = "x.yaml") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def test_default_yaml_is_exactly_the_dataclass_defaults():
    cfg = load_config(CONFIGS / "default.yaml")
    assert cfg == Config()
    assert cfg.rig.simulated.load.limit_stiffness == 2.0e6          # '2.0e6' is a float, not a string
    assert isinstance(cfg.rig.rate_hz, float) and cfg.rig.rate_hz == 1000.0
    assert cfg.sheath.runs[0] == RunConfig(0.30, math.inf)


def test_default_yaml_names_every_setting():
    """default.yaml spells out every key of the schema (so it documents all of them)."""
    import yaml
    data = yaml.safe_load((CONFIGS / "default.yaml").read_text())

    def missing(cls, d, prefix=""):
        out = []
        for name, tp in get_type_hints(cls).items():
            if name not in d:
                out.append(prefix + name)
            elif dataclasses.is_dataclass(tp):
                out += missing(tp, d[name], f"{prefix}{name}.")
        return out
    assert missing(Config, data) == []


def test_no_file_means_defaults_and_sim_yaml_loads():
    assert load_config() == Config()
    sim = load_config(CONFIGS / "sim.yaml")
    assert sim.rig.type == "simulated" and sim.master.device.type == "simulated"
    assert sim.transport.multicast_scouting is False
    assert sim.instrument.id == "sim0"
    assert dataclasses.replace(sim, instrument=Config().instrument) == Config()   # all else default


def test_file_overrides_only_what_it_names(tmp_path):
    p = _write(tmp_path, "rig:\n  simulated:\n    motor:\n      max_speed: 0.02\n"
                         "sheath:\n  runs:\n    - {length: 1.0, radius: 0.5}\n")
    cfg = load_config(p)
    assert cfg.rig.simulated.motor.max_speed == 0.02
    assert cfg.rig.simulated.motor.pulley_radius == Config().rig.simulated.motor.pulley_radius      # sibling kept
    assert cfg.rig.rate_hz == Config().rig.rate_hz
    assert cfg.sheath.runs == (RunConfig(1.0, 0.5),)                            # lists replaced whole
    assert cfg.sheath.EA == Config().sheath.EA and cfg.rig.simulated.mu == Config().rig.simulated.mu


def test_overrides_apply_last_nested_or_dotted(tmp_path):
    p = _write(tmp_path, "rig:\n  rate_hz: 500\n")
    cfg = load_config(p, {"rig": {"simulated": {"n_elements": 50}}, "master.mapping.force_scale": 0.5,
                          "transport.listen": ["tcp/127.0.0.1:9000"]})
    assert cfg.rig.rate_hz == 500.0 and cfg.rig.simulated.n_elements == 50
    assert cfg.master.mapping.force_scale == 0.5
    assert cfg.transport.listen == ("tcp/127.0.0.1:9000",)
    with pytest.raises(ConfigError, match=r"^overrides: unknown key 'rig.moter'"):
        load_config(p, {"rig.moter.max_speed": 1.0})


def test_lists_become_tuples_and_runs_become_run_configs(tmp_path):
    p = _write(tmp_path, "sheath:\n  runs:\n    - {length: 0.2}\n    - {length: 0.1, radius: .inf}\n"
                         "transport:\n  connect: [\"tcp/127.0.0.1:7448\"]\n")
    cfg = load_config(p)
    assert cfg.sheath.runs == (RunConfig(0.2), RunConfig(0.1))
    assert isinstance(cfg.sheath.runs, tuple) and isinstance(cfg.transport.connect, tuple)
    assert cfg.sheath.geometry().total_angle == 0.0                             # both runs straight
    assert cfg.sheath.geometry().length == pytest.approx(0.3)


def test_unknown_key_names_file_line_and_suggestion(tmp_path):
    p = _write(tmp_path, "rig:\n  rate_hz: 100\n  simulated:\n    moter:\n      max_speed: 1\n")
    with pytest.raises(ConfigError) as e:
        load_config(p)
    assert str(e.value) == f"{p}:4: unknown key 'rig.simulated.moter' (did you mean 'rig.simulated.motor'?)"


def test_unknown_key_in_list_item_and_misplaced_key(tmp_path):
    with pytest.raises(ConfigError, match=r"unknown key 'sheath.runs\[1\].lenght' "
                                          r"\(did you mean 'sheath.runs\[1\].length'"):
        load_config(_write(tmp_path, "sheath:\n  runs:\n    - {length: 1}\n    - {lenght: 1}\n"))
    with pytest.raises(ConfigError, match=r":1: unknown key 'watchdog_ms' \(did you mean '(master|slave).watchdog_ms'"):
        load_config(_write(tmp_path, "watchdog_ms: 20\n"))


def test_non_si_suffix_only_where_the_schema_names_it(tmp_path):
    assert load_config(_write(tmp_path, "slave:\n  watchdog_ms: 20\n")).slave.watchdog_ms == 20.0
    with pytest.raises(ConfigError, match=r":3: unknown key 'sheath.runs\[0\].length_mm': "
                                          r"non-SI '_mm' .* give 'length'"):
        load_config(_write(tmp_path, "sheath:\n  runs:\n    - {length_mm: 300}\n"))
    with pytest.raises(ConfigError, match="unknown key 'master.mapping.ramp_time_ms'"):
        load_config(_write(tmp_path, "master:\n  mapping:\n    ramp_time_ms: 500\n"))


@pytest.mark.parametrize("text, match", [
    ("rig:\n  rate_hz: fast\n", r":2: rig.rate_hz: expected a number, got 'fast' \(str\)"),
    ("rig:\n  simulated:\n    n_elements: 20.5\n",
     r":3: rig.simulated.n_elements: expected an integer, got 20.5 \(float\)"),
    ("rig:\n  simulated:\n    load:\n      tissue: 1\n",
     r":4: rig.simulated.load.tissue: expected true or false, got 1 \(int\)"),
    ("rig:\n  simulated:\n    load:\n      tissue: yes\n",
     r"rig.simulated.load.tissue: expected true or false, got 'yes'"),
    ("rig:\n  simulated:\n    effects:\n      stiction:\n        enabled: 1\n",
     r":5: rig.simulated.effects.stiction.enabled: expected true or false, got 1 \(int\)"),
    ("rig:\n  simulated:\n    effects:\n      stiction:\n        slip_time: fast\n",
     r":5: rig.simulated.effects.stiction.slip_time: expected a number, got 'fast' \(str\)"),
    ("rig:\n  rate_hz: true\n", r"rig.rate_hz: expected a number, got True \(bool\)"),
    ("rig:\n  type: real\n", r"rig.type: expected one of 'simulated', 'zenoh', 'recording', got 'real'"),
    ("recording:\n  rerun: of\n", r"recording.rerun: expected one of 'save', 'spawn', 'serve', 'off', got 'of'"),
    ("instrument:\n  id: 7\n", r"instrument.id: expected a non-empty string, got 7 \(int\)"),
    ("rig: 5\n", r":1: rig: expected a mapping of settings, got 5 \(int\)"),
    ("transport:\n  listen: tcp/127.0.0.1:1\n", r"transport.listen: expected a list, got 'tcp/"),
    ("sheath:\n  runs:\n    - {radius: 0.1}\n", r":3: sheath.runs\[0\]: missing key 'length'"),
    ("- 1\n- 2\n", r"top level: expected a mapping of settings, got a list"),
])
def test_wrong_types_name_key_expected_type_and_value(tmp_path, text, match):
    with pytest.raises(ConfigError, match=match):
        load_config(_write(tmp_path, text))


@pytest.mark.parametrize("text, match", [
    ("sheath:\n  EA: -3\n", r":2: sheath.EA: -3.0 is out of range: expected > 0 \[N\]"),
    ("rig:\n  simulated:\n    mu: -0.1\n", r"rig.simulated.mu: -0.1 is out of range: expected >= 0"),
    ("sheath:\n  runs:\n    - {length: 0}\n", r"sheath.runs\[0\].length: 0.0 is out of range: expected > 0 \[m\]"),
    ("sheath:\n  runs:\n    - {length: 1, radius: -2}\n", r"sheath.runs\[0\].radius: -2.0 is out of range"),
    ("sheath:\n  runs: []\n", r"sheath.runs: expected at least one run"),
    ("rig:\n  rate_hz: 0\n", r"rig.rate_hz: 0.0 is out of range: expected 10..10000 \[Hz\]"),
    ("rig:\n  simulated:\n    motor:\n      max_speed: -1\n",
     r"rig.simulated.motor.max_speed: -1.0 is out of range: expected > 0 \[m/s\]"),
    ("rig:\n  simulated:\n    load:\n      limit_stiffness: -2.0e6\n",
     r"rig.simulated.load.limit_stiffness: -2000000.0 is out of range"),
    ("rig:\n  simulated:\n    effects:\n      stiction:\n        slip_time: 0\n",
     r":5: rig.simulated.effects.stiction.slip_time: 0.0 is out of range: expected > 0 \[s\]"),
    ("rig:\n  simulated:\n    effects:\n      sensor_delay: {delay: .inf}\n",
     r"rig.simulated.effects.sensor_delay.delay: expected a finite number, got inf"),
    ("rig:\n  simulated:\n    effects:\n      sensor_gain: {gain: 0.8}\n",
     r"rig.simulated.effects.sensor_gain.gain: 0.8 is out of range: expected -0.5..0.5 \[-\]"),
    ("rig:\n  simulated:\n    effects:\n      sensor_drift: {rate: -0.5}\n",
     r"rig.simulated.effects.sensor_drift.rate: -0.5 is out of range: expected -0.1..0.1 \[N/s\]"),
    ("rig:\n  simulated:\n    effects:\n      encoder_offset: {offset: .nan}\n",
     r"rig.simulated.effects.encoder_offset.offset: expected a finite number, got nan"),
    ("rig:\n  simulated:\n    effects:\n      presliding: {distance: 0}\n",
     r"rig.simulated.effects.presliding.distance: 0.0 is out of range: expected > 0 \[m\]"),
    ("rig:\n  simulated:\n    effects:\n      distal_backlash: {width: -1.0e-4}\n",
     r"rig.simulated.effects.distal_backlash.width: -0.0001 is out of range: expected >= 0 \[m\]"),
    ("slave:\n  watchdog_ms: -5\n", r"slave.watchdog_ms: -5.0 is out of range: expected > 0 \[ms\]"),
    ("estimator:\n  profile_points: 70000\n", r"estimator.profile_points: 70000 is out of range: expected 0..65535"),
    ("sheath:\n  EA: .inf\n", r"sheath.EA: expected a finite number, got inf"),
    ("rig:\n  simulated:\n    mu: .nan\n", r"rig.simulated.mu: expected a finite number, got nan"),
    ("instrument:\n  id: a/b\n", r":2: instrument.id: 'a/b' is not a valid instrument id"),
    ("transport:\n  listen: [\"127.0.0.1:7447\"]\n",
     r"transport.listen\[0\]: '127.0.0.1:7447' is not a zenoh endpoint"),
])
def test_out_of_range_values_name_key_and_range(tmp_path, text, match):
    with pytest.raises(ConfigError, match=match):
        load_config(_write(tmp_path, text))


def test_missing_file_names_the_path(tmp_path):
    with pytest.raises(ConfigError, match=re.escape(f"{tmp_path / 'nope.yaml'}: config file not found")):
        load_config(tmp_path / "nope.yaml")
    with pytest.raises(ConfigError, match=re.escape(f"{tmp_path}: is a directory; expected a config file")):
        load_config(tmp_path)


def test_yaml_syntax_error_names_file_and_line(tmp_path):
    p = _write(tmp_path, "rig:\n  rate_hz: 100\n  motor: [1, 2\nslave: {}\n")
    with pytest.raises(ConfigError, match=re.escape(str(p)) + r":4:\d+: YAML syntax error"):
        load_config(p)


def test_duplicate_key_is_an_error(tmp_path):
    with pytest.raises(ConfigError, match=r":3: duplicate key 'rig.rate_hz'"):
        load_config(_write(tmp_path, "rig:\n  rate_hz: 1\n  rate_hz: 2\n"))


def test_yaml12_scalars(tmp_path):
    cfg = load_config(_write(tmp_path, "recording:\n  rerun: off\nsheath:\n  EA: 1.5e4\n"
                                       "rig:\n  simulated:\n    mu: 1e-1\n    sensors:\n      seed: 010\n"))
    assert cfg.recording.rerun == "off"                     # not YAML 1.1 False
    assert cfg.sheath.EA == 15000.0 and cfg.rig.simulated.mu == 0.1
    assert cfg.rig.simulated.sensors.seed == 10             # not octal


def test_empty_file_and_empty_section_mean_defaults(tmp_path):
    assert load_config(_write(tmp_path, "# nothing\n")) == Config()
    assert load_config(_write(tmp_path, "rig:\n  # motor: ...\n")) == Config()


def test_config_to_dict_round_trips(tmp_path):
    cfg = load_config(CONFIGS / "default.yaml", {"sheath.runs": [{"length": 0.5}, {"length": 0.2, "radius": 0.1}],
                                                 "instrument.id": "x-1"})
    d = config_to_dict(cfg)
    assert d["sheath"]["runs"] == [{"length": 0.5}, {"length": 0.2, "radius": 0.1}]
    assert isinstance(d["transport"]["listen"], list)
    assert config_from_dict(d) == cfg
    assert load_config(write_config(cfg, tmp_path / "resolved.yaml")) == cfg


def test_range_table_covers_every_numeric_field_and_nothing_else():
    numeric = []

    def walk(cls, prefix):
        for name, tp in get_type_hints(cls).items():
            p = prefix + name
            if dataclasses.is_dataclass(tp):
                walk(tp, p + ".")
            elif get_origin(tp) is tuple and dataclasses.is_dataclass(get_args(tp)[0]):
                walk(get_args(tp)[0], p + "[].")      # sheath.runs, instrument.joints, ...
            elif get_origin(tp) is tuple and get_args(tp)[0] in (int, float):
                numeric.append(p + "[]")               # joint limits, device axes
            elif tp in (int, float) or (get_origin(tp) in (Union, types.UnionType)
                                        and set(get_args(tp)) in ({int, NoneType}, {float, NoneType})):
                numeric.append(p)                      # Optional numbers too (estimator.tension_noise)
    walk(Config, "")
    assert sorted(numeric) == sorted(RANGES)


def test_transport_defaults_are_loopback_without_multicast():
    t = TransportConfig()
    assert t.mode == "peer" and t.listen == ("tcp/127.0.0.1:7447",) and not t.multicast_scouting
