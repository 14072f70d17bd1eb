"""``teleop demo`` finds its configs and prints hints that work from an installed package as from a checkout."""
from __future__ import annotations

import sys
from pathlib import Path

from live.demo.main import DEFAULT_CONFIG, rerun_command
from teleop.config.files import configs_dir, resolve_config, shipped_config
from teleop.config.load import load_config

ROOT = Path(__file__).resolve().parents[2]
LIVE_SOURCES = sorted(p for d in ("live", "master", "slave", "teleop") for p in (ROOT / d).rglob("*.py"))


def test_the_default_config_is_the_project_s_sim_yaml():
    assert DEFAULT_CONFIG == shipped_config("sim.yaml") and DEFAULT_CONFIG.is_file()
    assert load_config(DEFAULT_CONFIG).instrument.id == "sim0"
    # every file of the checkout's configs/ is found where the package looks (its copy when installed)
    names = {p.relative_to(ROOT / "configs") for p in (ROOT / "configs").rglob("*.yaml")}
    assert names and all((configs_dir() / n).is_file() for n in names)


def test_a_documented_configs_path_resolves_from_any_directory(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    own = resolve_config("configs/instrument-3dof.yaml")
    assert own.is_absolute() and own.is_file() and own == shipped_config("instrument-3dof.yaml")
    # a file of the user's own, even under a configs/ folder, wins; an unknown name is left for the loader
    (tmp_path / "configs").mkdir()
    (tmp_path / "configs" / "sim.yaml").write_text("instrument:\n  id: mine\n", encoding="utf-8")
    assert resolve_config("configs/sim.yaml") == Path("configs/sim.yaml")
    assert resolve_config("configs/missing.yaml") == Path("configs/missing.yaml")
    assert resolve_config("elsewhere/instrument-3dof.yaml") == Path("elsewhere/instrument-3dof.yaml")


def test_hints_name_no_virtual_environment_folder():
    found = [f"{p.relative_to(ROOT)}:{i}" for p in LIVE_SOURCES
             for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1) if ".venv" in line]
    assert not found, f"messages must work from a pip install too: {found}"


def test_the_rerun_hint_names_a_viewer_that_exists_or_the_plain_command(monkeypatch):
    cmd = rerun_command()
    assert cmd == "rerun" or (Path(cmd).is_file() and Path(cmd).parent == Path(sys.executable).parent)
    monkeypatch.setenv("PATH", "")
    cmd = rerun_command()
    assert cmd == "rerun" or Path(cmd).parent == Path(sys.executable).parent


def test_the_demo_runs_its_sides_with_normal_scheduling_where_the_machine_cannot_hold_their_real_time_threads(
        monkeypatch):
    from live.demo.run import co_located
    cfg = load_config(DEFAULT_CONFIG)
    assert cfg.master.realtime_priority > 0 and cfg.slave.realtime_priority > 0
    monkeypatch.setattr("os.sched_getaffinity", lambda pid: {0, 1})      # the CPUs the demo's processes may use
    small, why = co_located(cfg)
    assert small.master.realtime_priority == 0 and small.slave.realtime_priority == 0
    assert why is not None and why.startswith("2 CPUs for master, slave and recorder")
    assert small.master.mapping == cfg.master.mapping and small.slave.watchdog_ms == cfg.slave.watchdog_ms
    monkeypatch.setattr("os.sched_getaffinity", lambda pid: set(range(8)))
    assert co_located(cfg) == (cfg, None)


def test_the_bimanual_demo_gives_both_sides_the_same_scheduling_rule(tmp_path, monkeypatch):
    from live.demo import bimanual
    from teleop.arms import load_arms
    src = shipped_config("notes-bimanual.yaml")
    loaded = load_arms(src)
    for d in ("small", "kept", "large"):
        (tmp_path / d).mkdir()           # the run's folder, made by the demo before
    monkeypatch.setattr("os.sched_getaffinity", lambda pid: {0, 1})
    bim, why = bimanual._resolved(src, tmp_path / "small", loaded)
    assert why is not None and why.startswith("2 CPUs for master, slave and recorder")
    for arm in bim.arms:         # the run's file and each arm's own config, which the sides and recorders read
        own = load_config(tmp_path / "small" / arm.ident / "config.yaml")
        assert arm.cfg.master.realtime_priority == own.master.realtime_priority == 0
        assert arm.cfg.slave.realtime_priority == own.slave.realtime_priority == 0
    kept, why = bimanual._resolved(src, tmp_path / "kept", loaded, keep_realtime=True)
    assert why is None and all(a.cfg.master.realtime_priority > 0 and a.cfg.slave.realtime_priority > 0
                               for a in kept.arms)
    monkeypatch.setattr("os.sched_getaffinity", lambda pid: set(range(8)))
    large, why = bimanual._resolved(src, tmp_path / "large", loaded)
    assert why is None
    assert [a.cfg.master.realtime_priority for a in large.arms] == [a.cfg.master.realtime_priority for a in kept.arms]
