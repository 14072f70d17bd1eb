"""instrument.joints: 1..16 joints, errors naming the file, line, joint and key; the 3-joint instrument loads."""
from __future__ import annotations

from pathlib import Path

import pytest

from teleop.config.load import config_from_dict, config_to_dict, load_config
from teleop.config.schema import Config
from teleop.errors import ConfigError

CONFIGS = Path(__file__).resolve().parents[2] / "configs"


def test_three_joint_instrument_loads_with_its_own_tendons():
    cfg = load_config(CONFIGS / "instrument-3dof.yaml")
    names = [j.name for j in cfg.instrument.joints]
    assert names == ["bend_ud", "bend_lr", "grasp"]
    routes = {(j.name, t): getattr(j.tendons, t).runs for j in cfg.instrument.joints for t in "ab"}
    assert len(set(routes.values())) == 6                    # every tendon has its own route
    assert cfg.instrument.joints[2].pulley_radius == 0.002 and cfg.pair_control.axes == (0, 1, 2)
    assert config_from_dict(config_to_dict(cfg)) == cfg
    # the single-tendon sections are untouched: sim.yaml and the defaults have no joints
    assert load_config(CONFIGS / "sim.yaml").instrument.joints == () and Config().instrument.joints == ()


def _write(tmp_path, text):
    p = tmp_path / "inst.yaml"
    p.write_text(text)
    return p


JOINT = "    - name: {name}\n      pulley_radius: 0.004\n"


@pytest.mark.parametrize("text, match", [
    ("instrument:\n  joints:\n" + "".join(JOINT.format(name=f"j{i}") for i in range(17)),
     r"inst.yaml:2: instrument.joints: 17 joints, an instrument has 1 to 16"),
    ("instrument:\n  joints:\n" + JOINT.format(name="a") + JOINT.format(name="a"),
     r"inst.yaml:5: instrument.joints\[1\].name: 'a' is already the name of instrument.joints\[0\]"),
    ("instrument:\n  joints:\n    - name: wrist\n      limits: [0.2, 1.0]\n",
     r"inst.yaml:4: instrument.joints\[0\].limits \(wrist\): expected \[lower, upper\] \[rad\] with lower < 0 < upper"),
    ("instrument:\n  joints:\n    - name: wrist\n      limits: [-1.0, 0.0, 1.0]\n",
     r"instrument.joints\[0\].limits \(wrist\)"),
    ("instrument:\n  joints:\n    - name: wrist\n      tendons:\n        b:\n          EA: 0\n",
     r"inst.yaml:6: instrument.joints\[0\].tendons.b.EA: 0.0 is out of range: expected > 0 \[N\]"),
    ("instrument:\n  joints:\n    - name: wrist\n      tendons:\n        c: {}\n",
     r"unknown key 'instrument.joints\[0\].tendons.c'"),
    ("instrument:\n  joints:\n    - pulley_radius: 0.004\n",
     r"instrument.joints\[0\]: missing key 'name'"),
    ("instrument:\n  joints:\n    - name: 'wr ist'\n", r"instrument.joints\[0\].name: 'wr ist' is not a joint name"),
    ("instrument:\n  joints:\n    - name: w\n"
     "rig:\n  simulated:\n    joints:\n      - {name: w, load: {tissue_contact: -0.1}}\n",
     r"rig.simulated.joints\[0\].load.tissue_contact: -0.1 is out of range: expected >= 0 \[rad\]"),
    ("instrument:\n  joints:\n    - name: w\n      load: {tissue_contact: 0.1}\n",
     r"inst.yaml:4: 'instrument.joints\[0\].load' has moved to 'rig.simulated.joints\[\].load \(the entry with"),
    ("instrument:\n  joints:\n    - name: w\n      tendons:\n        b: {mu: 0.2}\n",
     r"inst.yaml:5: 'instrument.joints\[0\].tendons.b.mu' has moved to 'rig.simulated.joints\[\].tendons.b.mu"),
    ("instrument:\n  joints:\n    - name: w\nrig:\n  simulated:\n    joints:\n      - {name: v}\n",
     r"inst.yaml:7: rig.simulated.joints\[0\].name: 'v' must name a joint of instrument.joints once \(joints: w\)"),
    ("instrument:\n  joints:\n    - name: w\n      pulley_radius_mm: 4\n",
     r"non-SI '_mm' keys are accepted only where the schema names them"),
    ("instrument:\n  joints:\n" + JOINT.format(name="a") + "pair_control:\n  axes: [0, 0]\n",
     r"pair_control.axes: expected one distinct device axis per joint \(1\), got \[0, 0\]"),
])
def test_bad_joint_settings_name_file_line_joint_and_key(tmp_path, text, match):
    with pytest.raises(ConfigError, match=match):
        load_config(_write(tmp_path, text))
