"""The bimanual sides' helpers (live/bimanual_sides.py): ``--inject ...,arm=<name>`` and each arm's Rerun view."""
from __future__ import annotations

from pathlib import Path

import pytest

from live.bimanual_sides import ArmRerun, split_arm
from teleop.arms import load_arms
from teleop.errors import ConfigError

BIMANUAL = Path(__file__).resolve().parents[2] / "configs" / "notes-bimanual.yaml"


def test_inject_spec_names_one_arm_or_every_arm():
    bim = load_arms(BIMANUAL)
    assert split_arm("drop=1,stream=estimate,arm=left,on=usr1", bim) == ("left", "drop=1,stream=estimate,on=usr1")
    assert split_arm("delay=30ms", bim) == (None, "delay=30ms")
    assert split_arm(None, bim) == (None, None)
    with pytest.raises(ConfigError, match="arm=middle.*left, right"):
        split_arm("drop=1,arm=middle", bim)
    with pytest.raises(ConfigError):
        split_arm("drop=1,arm=left,arm=right", bim)


def test_arm_view_logs_under_the_arm_and_passes_the_rest():
    calls = []

    class Logger:
        def log_joint(self, t, joint, **kw):
            calls.append(("joint", joint, kw))

        def log_master(self, t, **kw):
            calls.append(("master", kw["axis"], kw["force"]))

        def flush(self):
            calls.append(("flush",))

    view = ArmRerun(Logger(), "right")
    view.log_joint(1.0, "grasp", torque_hat=0.01)
    view.log_master(1.0, axis="elbow", force=0.5)
    view.log_master(1.0, force=0.2)
    view.flush()
    assert calls == [("joint", "right/grasp", {"torque_hat": 0.01}), ("master", "right/elbow", 0.5),
                     ("master", "right", 0.2), ("flush",)]


@pytest.mark.parametrize("command", ["record", "calibrate", "bridge"])
def test_one_instrument_commands_refuse_a_bimanual_config_in_one_line(command, capsys):
    from live.cli import main
    assert main([command, "--config", str(BIMANUAL)]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "bimanual config" in err and "one arm's config" in err
