"""The instrument's kind is read from the config in one place (teleop.config.kinds) and mapped to what each floor
builds by that floor's registry (slave.kinds, master.kinds, live.kinds): no other module branches on the config's
``instrument.joints`` or on a joint's ``spindle_radius``."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from live.kinds import LIVE_KINDS, live_kind
from master.kinds import MASTER_KINDS, master_kind
from slave.kinds import SLAVE_KINDS, axis_kind, slave_kind
from teleop.config.kinds import KINDS, instrument_kind
from teleop.config.load import load_config

ROOT = Path(__file__).resolve().parents[1]
CONFIGS = ROOT / "configs"
REGISTRIES = {"teleop/config", "slave/kinds.py", "master/kinds.py", "live/kinds.py"}
#: A test of the kind: the joints list's truth (``if cfg.instrument.joints``, ``... if not cfg.instrument.joints
#: else ...``) or a spindle radius compared to 0 outside a setting's check.
BRANCH = re.compile(r"\b(if|elif|not|and|else|while)\s+(not\s+)?[\w.]*instrument\.joints\b(?!\s*\[|\s*\))"
                    r"|[\w.]*instrument\.joints\s+(else|and|if)\b|spindle_radius\s*>\s*0(?![.\d]*\s*,\s*f?\")")


def branches(text: str) -> list[str]:
    """The lines of ``text`` that choose behaviour by the instrument's kind read from the config (comments and
    docstring lines with no code are skipped)."""
    out = []
    for line in text.splitlines():
        code = line.split("#", 1)[0]
        if BRANCH.search(code) and "``" not in code:
            out.append(line.strip())
    return out


def test_the_pattern_finds_a_branch():
    assert branches("    if cfg.instrument.joints:\n        x = 1")
    assert branches("    a = b if not cfg.instrument.joints else c")
    assert branches("    if joints[0].spindle_radius > 0:")
    assert not branches("    for j in cfg.instrument.joints:")
    assert not branches("    if len(cfg.instrument.joints) != 1:")


def test_no_module_outside_the_registries_branches_on_the_kind():
    found = []
    for pkg in ("estimator", "teleop", "recorded", "slave", "master", "study", "live"):
        for p in sorted((ROOT / pkg).rglob("*.py")):
            rel = p.relative_to(ROOT).as_posix()
            if any(rel == r or rel.startswith(r + "/") for r in REGISTRIES):
                continue
            found += [f"{rel}: {line}" for line in branches(p.read_text(encoding="utf-8"))]
    assert not found, "the instrument's kind is chosen outside the registries:\n" + "\n".join(found)


@pytest.mark.parametrize(("name", "kind"), [("sim.yaml", "tendon"), ("instrument-3dof.yaml", "pair"),
                                            ("instrument-spindle.yaml", "spindle")])
def test_each_config_has_its_kind_and_every_floor_an_entry(name, kind):
    cfg = load_config(CONFIGS / name)
    assert instrument_kind(cfg) == kind
    assert slave_kind(kind) is SLAVE_KINDS[kind] and master_kind(kind) is MASTER_KINDS[kind]
    assert live_kind(kind) is LIVE_KINDS[kind]
    assert axis_kind(cfg).__module__.startswith("slave.")


def test_every_registry_holds_every_kind():
    assert set(SLAVE_KINDS) == set(MASTER_KINDS) == set(LIVE_KINDS) == set(KINDS)


@pytest.mark.parametrize("lookup", [slave_kind, master_kind, live_kind])
def test_an_unknown_kind_is_one_clear_error(lookup):
    with pytest.raises(LookupError, match=r"no instrument kind 'tripod' \(kinds: tendon, pair, spindle\)$"):
        lookup("tripod")
