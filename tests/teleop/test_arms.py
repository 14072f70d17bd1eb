"""The bimanual config loader (teleop/arms.py): one ordinary Config per arm, strict errors with file:line."""
from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from teleop.arms import is_bimanual, load_arms
from teleop.config.load import load_config
from teleop.errors import ConfigError

ROOT = Path(__file__).resolve().parents[2]
BIMANUAL = ROOT / "configs" / "notes-bimanual.yaml"


def _write(tmp_path: Path, edit) -> Path:
    data = yaml.safe_load(BIMANUAL.read_text(encoding="utf-8"))
    edit(data)
    path = tmp_path / "bim.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return path


def test_shipped_bimanual_config_gives_two_arms_of_four_joints_sixteen_tendons():
    bim = load_arms(BIMANUAL)
    assert [a.hand for a in bim.arms] == ["left", "right"]
    assert {a.ident for a in bim.arms} == {"notes_left", "notes_right"}
    assert sum(2 * len(a.cfg.instrument.joints) for a in bim.arms) == 16
    left, right = bim.by_hand("left"), bim.by_hand("right")
    # each arm's own loads: the left grasps tissue, the right presses its elbow on the wall
    load = {a.name: {j.name: j.load for j in a.cfg.rig.simulated.joints} for a in (left, right)}
    assert load["left"]["grasp"].tissue and not load["left"]["elbow"].tissue
    assert load["right"]["elbow"].tissue and not load["right"]["grasp"].tissue
    assert load["right"]["elbow"].tissue_stiffness > load["left"]["grasp"].tissue_stiffness
    # the base is shared: one rate, one watchdog, one calibration setting for both
    assert left.cfg.rig.rate_hz == right.cfg.rig.rate_hz and left.cfg.slave == right.cfg.slave
    assert left.cfg.calibration == right.cfg.calibration


def test_single_arm_configs_are_not_bimanual_and_still_load():
    assert is_bimanual(BIMANUAL)
    for name in ("instrument-3dof.yaml", "sim.yaml", "instrument-spindle.yaml"):
        assert not is_bimanual(ROOT / "configs" / name)
        load_config(ROOT / "configs" / name)
    assert not is_bimanual(None) and not is_bimanual(ROOT / "configs" / "missing.yaml")


@pytest.mark.parametrize("edit, words", [
    (lambda d: d["arms"][1].update(name="left"), ["arms[1].name", "already the name"]),
    (lambda d: d["arms"][1].update(hand="left"), ["arms[1].hand", "right hand drives no arm"]),
    (lambda d: d["arms"][0].update(hand="middle"), ["arms[0].hand", "left, right"]),
    (lambda d: d["arms"][0].update(sheath={}), ["unknown key 'arms[0].sheath'"]),
    (lambda d: d["arms"][1]["instrument"].update(id="notes_left"), ["arms[1].instrument.id", "own id"]),
    (lambda d: d["arms"][0]["rig"].update(rate_hz=500), ["arms[0].rig.rate_hz", "one loop"]),
    (lambda d: d["arms"].pop(), ["arms: expected 2 arms"]),
    (lambda d: d["arms"][0]["instrument"].update(bogus=1), ["instrument.bogus"]),
])
def test_bad_bimanual_config_is_one_line_naming_file_and_line(tmp_path, edit, words):
    path = _write(tmp_path, edit)
    with pytest.raises(ConfigError) as e:
        load_arms(path)
    msg = str(e.value)
    assert msg.startswith(f"{path}:") and "\n" not in msg
    line = int(msg.split(":")[1])
    assert line >= 1
    for w in words:
        assert w in msg


def test_error_inside_an_arm_points_at_that_arms_line(tmp_path):
    def edit(d):
        d["arms"][1]["instrument"]["joints"][2]["limits"] = [0.5, 1.0]
    path = _write(tmp_path, edit)
    with pytest.raises(ConfigError) as e:
        load_arms(path)
    line = int(str(e.value).split(":")[1])
    text = path.read_text(encoding="utf-8").splitlines()
    arms_1 = next(i for i, t in enumerate(text) if "name: right" in t)
    assert line - 1 > arms_1 and "limits" in text[line - 1]
