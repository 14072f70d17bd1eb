"""The Rerun view's blueprint (teleop/rerun/layout.py): one column per arm for a bimanual joint list, the single-arm
layout for joints without an arm."""
from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from teleop.config.load import load_config
from teleop.rerun.layout import arm_groups, blueprint, joint_views


def _views(item) -> list:
    """Every view under a blueprint or container, depth first in layout order."""
    root = getattr(item, "root_container", None)
    if root is not None:
        return _views(root)
    contents = getattr(item, "contents", None)
    if hasattr(item, "kind") and contents is not None:
        return [v for c in contents for v in _views(c)]
    return [item]


@pytest.fixture(scope="module")
def joints():
    cfg = load_config(Path(__file__).resolve().parents[2] / "configs" / "instrument-3dof.yaml")
    return joint_views(cfg)


def _bimanual(joints):
    return tuple(dataclasses.replace(v, name=f"{arm}/{v.name}") for arm in ("left", "right") for v in joints)


def test_arm_groups_need_an_arm_on_every_joint(joints):
    both = _bimanual(joints)
    assert arm_groups(both) == {"left": ("bend_ud", "bend_lr", "grasp"), "right": ("bend_ud", "bend_lr", "grasp")}
    assert arm_groups(joints) == {} and arm_groups(()) == {}
    assert arm_groups((*both, joints[0])) == {}                      # one joint without an arm: one instrument


def test_bimanual_blueprint_has_one_force_panel_per_hand_beside_its_joints(joints):
    """Each hand's rendered-force panel holds that hand's force series only; its arm's torque plots follow it
    in the same column; the 3D view shows all pairs; no panel mixes both hands' master series."""
    root = blueprint(_bimanual(joints)).root_container
    views = _views(root)
    by_name = {str(v.name): v for v in views}
    for arm in ("left", "right"):
        hand = by_name[f"{arm} hand: rendered force [N]"]
        assert str(hand.origin) == f"master/{arm}"
        forces = [str(c) for c in hand.contents]
        assert all(c.startswith(f"/master/{arm}/") and c.endswith("/force") for c in forces)
        assert {f"/master/{arm}/{j.name}/force" for j in joints} <= set(forces)
    columns = root.contents[1:]
    assert [str(c.name) for c in columns] == ["left arm", "right arm"]
    for arm, column in zip(("left", "right"), columns, strict=False):
        origins = [str(v.origin) for v in _views(column)]
        assert origins[0] == f"master/{arm}"
        torques = [o for o in origins if o.endswith("/torque")]
        assert torques == [f"joints/{arm}/{j.name}/torque" for j in joints]
    assert [str(v.origin) for v in views if "Spatial3D" in type(v).__name__] == ["instrument"]
    assert "master" not in {str(v.origin) for v in views}


def test_single_arm_blueprint_keeps_one_column_of_joints_and_one_master_panel(joints):
    views = _views(blueprint(joints))
    origins = [str(v.origin) for v in views]
    rows = [o for j in joints for o in (f"joints/{j.name}/torque", f"joints/{j.name}/angle")]
    assert origins == ["instrument", "/", *rows, "master", "signals"]
    assert not any("hand" in str(v.name) for v in views)
    assert [str(v.origin) for v in _views(blueprint())][:2] == ["sheath", "profile"]     # a single tendon
