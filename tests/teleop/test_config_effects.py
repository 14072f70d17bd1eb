"""One source for each effect: the catalogue entry drives the config schema, its documentation, the
simulated rig's switch list and the scenarios; and the rig config's layout (old keys name their new place)."""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from estimator.offline.effects import catalogue
from estimator.offline.effects.catalogue import Effect
from estimator.offline.effects.switches import RigSwitch, ScenarioKnob, Setting
from estimator.offline.effects.types import Parameter
from slave.simulated import SimulatedRig
from slave.simulated_effects import IMPLEMENTED
from study import scenarios
from teleop.config.effects import EffectsConfig, EffectSwitch, effect_ranges, effects_block
from teleop.config.load import config_from_dict, config_to_dict, load_config
from teleop.config.schema import Config
from teleop.errors import ConfigError

CONFIGS = Path(__file__).resolve().parents[2] / "configs"


class Toy(Effect):
    """A made-up effect: only its catalogue entry exists (no kernel anywhere)."""

    id = "toy_creep"
    cause = "test only"
    parameters = (Parameter("c_t", "1/s", 0.0, 1.0, 0.0, (0.1,), "creep rate"),)
    switch = RigSwitch("toy_creep", "a made-up creep", (Setting("creep", 0.5, "1/s", "0..2", "creep rate"),
                                                         Setting("onset", 1.0, "s", "> 0", "when it starts")))
    knob = ScenarioKnob((("creep", 0.2, 0.6),), ("creep",))


@pytest.fixture
def toy():
    entry = catalogue.register(Toy())
    try:
        yield entry
    finally:
        catalogue.unregister(entry.id)


def test_a_toy_entry_is_validated_by_the_loader(toy, tmp_path):
    cfg = load_config(None, {"rig.simulated.effects.toy_creep.enabled": True})
    sw = cfg.rig.simulated.effects.toy_creep
    assert sw.enabled and sw.creep == 0.5 and sw.onset == 1.0                 # the entry's defaults
    assert effect_ranges()["rig.simulated.effects.toy_creep.creep"] == ("0..2", "1/s")
    p = tmp_path / "toy.yaml"
    p.write_text("rig:\n  simulated:\n    effects:\n      toy_creep:\n        creep: 3.0\n")
    with pytest.raises(ConfigError, match=r":5: rig.simulated.effects.toy_creep.creep: 3.0 is out of range: "
                                          r"expected 0..2 \[1/s\]"):
        load_config(p)
    with pytest.raises(ConfigError, match=r"unknown key 'rig.simulated.effects.toy_creep.creeep' "
                                          r"\(expected one of: enabled, creep, onset\)"):
        load_config(None, {"rig.simulated.effects.toy_creep.creeep": 1.0})
    assert config_from_dict(config_to_dict(cfg)) == cfg
    assert "      toy_creep:" in effects_block(6) and "creep: 0.5" in effects_block(6)
    # the simulator has no kernel for it: refused when on, the rest of the rig unaffected
    with pytest.raises(ConfigError, match=r"rig.simulated.effects.toy_creep: the simulated rig has no kernel"):
        SimulatedRig.from_config(cfg)
    assert SimulatedRig.from_config(Config()).effects == ()


def test_a_toy_entry_is_offered_by_the_scenarios(toy):
    assert "toy_creep" in scenarios.scenario_effects()
    assert scenarios.realistic_range("toy_creep") == {"creep": (0.2, 0.6)}
    fx, truth = scenarios.effects_config("toy_creep", 0.5, 0.8, 60.0, np.random.default_rng(1))
    assert fx.enabled() == ("toy_creep",)
    assert abs(fx.toy_creep.creep) == pytest.approx(0.4) and fx.toy_creep.onset == 1.0
    assert truth == {"creep": fx.toy_creep.creep}


def test_the_toy_is_gone_after_unregister():
    assert "toy_creep" not in scenarios.scenario_effects()
    with pytest.raises(ConfigError, match="unknown key 'rig.simulated.effects.toy_creep'"):
        load_config(None, {"rig.simulated.effects.toy_creep.enabled": True})
    with pytest.raises(ValueError, match="in the catalogue already"):
        catalogue.register(catalogue.CATALOGUE["stiction"])


def test_default_yaml_documents_the_effects_as_the_catalogue_says():
    text = (CONFIGS / "default.yaml").read_text()
    assert effects_block(6) in text, ("regenerate the rig.simulated.effects block: "
                                      "teleop.config.effects.effects_block(6)")


def test_every_catalogue_switch_has_a_kernel_in_the_simulated_rig():
    assert set(catalogue.rig_switches()) == IMPLEMENTED
    sim = Config().rig.simulated
    for key in IMPLEMENTED:                                     # and the rig builds with each one on
        rig = SimulatedRig(Config().sheath, dataclasses.replace(sim, n_elements=20,
                                                                effects=EffectsConfig(**{key: EffectSwitch(True)})))
        assert rig.effects == (key,)


@pytest.mark.parametrize("old, new, text", [
    ("rig.n_elements", "rig.simulated.n_elements", "rig:\n  n_elements: 50\n"),
    ("rig.motor", "rig.simulated.motor", "rig:\n  motor:\n    max_speed: 0.02\n"),
    ("rig.load", "rig.simulated.load", "rig:\n  load: {tissue: false}\n"),
    ("rig.sensors", "rig.simulated.sensors", "rig:\n  sensors: {seed: 3}\n"),
    ("rig.effects", "rig.simulated.effects", "rig:\n  effects:\n    stiction: {enabled: true}\n"),
    ("sheath.mu", "rig.simulated.mu", "sheath:\n  mu: 0.2\n"),
])
def test_an_old_layout_key_names_where_it_moved(tmp_path, old, new, text):
    p = tmp_path / "old.yaml"
    p.write_text(text)
    with pytest.raises(ConfigError, match=rf"^{p}:2: '{old}' has moved to '{new}'"):
        load_config(p)
    with pytest.raises(ConfigError, match=rf"^overrides: '{old}' has moved to '{new}'"):
        load_config(None, {old + ".x": 1})


def test_the_simulated_rig_reads_only_its_block():
    cfg = load_config(None, {"rig.simulated.mu": 0.05, "rig.simulated.n_elements": 40, "rig.type": "zenoh"})
    rig = SimulatedRig.from_config(cfg)
    assert rig.n_elements == 40 and rig.K == pytest.approx(0.05 * cfg.sheath.geometry().total_angle)
