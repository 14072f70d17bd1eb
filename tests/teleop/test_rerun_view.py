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
    """Each hand's force panel holds that hand's force series only; its arm's torque plots are in the same
    column; the 3D view shows all pairs; no panel mixes both hands' master series."""
    root = blueprint(_bimanual(joints)).root_container
    views = _views(root)
    by_name = {str(v.name): v for v in views}
    for arm in ("left", "right"):
        hand = by_name[f"{arm} hand: rendered and mapped force [N]"]
        forces = [str(c) for c in hand.contents]
        assert all(c.startswith(f"/master/{arm}/") and c.endswith(("/force", "/force_cmd")) for c in forces)
        assert {f"/master/{arm}/{j.name}/force" for j in joints} | {f"/master/{arm}/force"} <= set(forces)
    columns = root.contents[1:]
    assert [str(c.name) for c in columns] == ["left arm", "right arm"]
    for arm, column in zip(("left", "right"), columns, strict=True):
        torques = [str(v.origin) for v in _views(column) if str(v.origin).endswith("/torque")]
        assert torques == [f"joints/{arm}/{j.name}/torque" for j in joints]
        other = "right" if arm == "left" else "left"
        assert not any(f"/{other}/" in str(c) for v in _views(column) for c in (v.contents or ()))
    assert [str(v.origin) for v in views if "Spatial3D" in type(v).__name__] == ["instrument"]


def test_single_arm_blueprint_puts_the_slave_beside_the_master(joints):
    """The slave's columns (pairs, then each joint's torque and angle) come first, the master's last: forces and
    commands of every joint axis, the round trip and the operator's lane."""
    root = blueprint(joints).root_container
    slave, master = _views(root.contents[0]) + _views(root.contents[1]), _views(root.contents[-1])
    rows = [o for j in joints for o in (f"joints/{j.name}/torque", f"joints/{j.name}/angle")]
    assert [str(v.origin) for v in slave] == ["instrument", "signals", *rows]
    contents = [str(c) for v in master for c in v.contents]
    assert {f"/master/{j.name}/force" for j in joints} <= set(contents)
    assert {f"/master/{j.name}/x_in_cmd" for j in joints} <= set(contents)
    assert "/master/rtt" in contents and "/master/console" in contents
    assert "Master: command [rad]" in {str(v.name) for v in master}          # a joint's command is its angle
    assert [str(v.origin) for v in _views(blueprint())][:2] == ["sheath", "profile"]     # a single tendon


@pytest.mark.parametrize("kind", ["tendon", "joints", "bimanual"])
def test_every_plot_names_one_unit_and_the_time_panel_shows_the_session(joints, kind):
    """Every time series and bar chart names its unit in brackets; the time panel shows the session timeline."""
    bp = blueprint({"tendon": (), "joints": joints, "bimanual": _bimanual(joints)}[kind])
    plots = [v for v in _views(bp.root_container) if "TimeSeries" in type(v).__name__ or "BarChart" in type(v).__name__]
    unitless = [str(v.name) for v in plots if "[" not in str(v.name) and "other signals" not in str(v.name)]
    assert plots and unitless == []
    assert bp.time_panel.timeline == "session"


def test_the_angle_axis_follows_the_data_and_the_torque_axis_the_joint(joints):
    """A recorded run's joint can leave the configured limits (the MRD jaw at -1.36 rad against -0.5..0.7): the
    angle plot has no fixed range; the torque plot keeps the joint's."""
    views = {str(v.name): v for v in _views(blueprint(joints))}
    for j in joints:
        assert views[f"{j.name}: angle [rad]"].properties.get("ScalarAxis") is None
        assert views[f"{j.name}: torque [N m]"].properties.get("ScalarAxis") is not None
