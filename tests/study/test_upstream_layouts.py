"""Plain clones of the two public repositories, laid out as they are upstream, read by the documented commands.

The fixtures are a few short synthetic files made here, in each repository's own layout and names
(docs/how-to/get-the-data.md): ``hysteresis_compensation_ROS/optimization/selected/<N>.txt`` beside a longer
recording of another layout (``conf0_60.txt``), and ``mis-tool-characterization/data/Tool_<...>/<NN>.TXT`` with
``%`` header lines, a ``SerialLog.txt`` and a ``ReadME.txt``. No real data is copied. The layout resolvers find
the recordings and name them by configuration and run; ``teleop analyze --kaist`` and ``--mrd`` on a clone's
root get past discovery and stop on the tiny data with one clear line; ``teleop demo --recording`` and
``rig.recording.format: auto`` tell the formats apart by content, a file named like another format's included.
"""
from __future__ import annotations

import argparse
import math
import os
from pathlib import Path

import pytest

from estimator.errors import DataError
from live.cli import main
from live.demo.recording import with_recording
from recorded.detect import recording_format
from recorded.folders import DATA_ENV, GUIDE, KAIST, MRD, data_root, dataset_dir, skip_reason
from recorded.kaist_files import config_of, default_kaist_dir, find_kaist_dir, kaist_files
from recorded.mrd import MIN_ROWS, load_mrd_dir
from recorded.mrd_files import default_mrd_dir, find_mrd_folder, mrd_folder
from study import analyze
from study.kaist.inputs import parse_configs
from study.mrd.tools import add_tool_argument
from teleop.config.load import load_config
from teleop.errors import ConfigError

ROOT = Path(__file__).resolve().parents[2]
KAIST_CONFIGS = (0, 60, 120, 180, 240)


def kaist_rows(stamps: int, repeats: int = 3) -> str:
    """The KAIST robot's log: 8 numbers and a trailing comma a row, each 40 Hz stamp written ``repeats`` times."""
    rows = []
    for k in range(stamps):
        t, cmd = 0.025 * k, 60.0 * math.sin(0.025 * k)
        rows += [f"{t:.6f}, {cmd:.6f}, 1500.0, {0.5 * cmd:.6f}, {5 + cmd / 20:.6f}, {5 - cmd / 20:.6f}, "
                 "250.0, -250.0 \n"] * repeats
    return "".join(rows)


def mrd_rows(rows: int, load: float = 0.1) -> str:
    """An MRD Lab run: ``%`` header lines, then 10 comma-separated numbers a row at 1 kHz."""
    head = ["%This file contains synthetic data", "%Back-end Time [ms], Back-end CUI Encoder [counts], ..."]
    body = [f"{k / 1000:.3f},{400 * math.sin(k / 300):.2f},{1200 * math.cos(k / 300):.2f},0.01,"
            f"{-350 * math.sin(k / 300):.2f},{-300 - 10 * math.cos(k / 300):.2f},{load:.2f},0.00,1900.00,0.00"
            for k in range(rows)]
    return "\n".join(head + body) + "\n"


def kaist_clone(parent: Path, stamps: int = 10) -> Path:
    """A clone of nhoyh/hysteresis_compensation_ROS: the numbered configurations and what sits beside them."""
    root = parent / KAIST.clone
    sel = root / "optimization" / "selected"
    sel.mkdir(parents=True)
    for n in KAIST_CONFIGS:
        (sel / f"{n}.txt").write_text(kaist_rows(stamps))
    (sel / "conf0_60.txt").write_text("0.000000, 0.0, 0.0, 0.0, 0.0, -0.05, 0.27, 0.24, 0.28, 0.29\n" * 3)
    (root / "optimization" / "BFGS.txt").write_text("optimizer log\n")
    (root / "README.md").write_text("# ViO-Com\n")
    return root


def mrd_clone(parent: Path, rows: int = MIN_ROWS) -> Path:
    """A clone of MRDLab/mis-tool-characterization: three tool folders under data/ beside the code."""
    root = parent / MRD.clone
    for folder, runs in (("Tool_4_Maryland_L_2", ("00", "01", "10")), ("Tool_5_Maryland_L_2", ("00",)),
                         ("Tool_4_Maryland_L_Roll_1", ("000",))):
        d = root / "data" / folder
        d.mkdir(parents=True)
        for i, name in enumerate(runs):
            (d / f"{name}.TXT").write_text(mrd_rows(rows, 0.1 * (1 + i)))
        (d / "SerialLog.txt").write_text("debug output of the microcontroller\n")
    (root / "data" / "Tool_4_Maryland_L_Roll_1" / "ReadME.txt").write_text("This is a roll of -90 degrees\n")
    (root / "RAL-2018").mkdir()
    (root / "README.md").write_text("Medical Robotics and Devices Lab Data Repository\n")
    return root


def test_the_data_folder_is_the_setting_else_shared_data_beside_the_checkout(tmp_path, monkeypatch):
    monkeypatch.delenv(DATA_ENV, raising=False)
    assert data_root() == ROOT.parent / "shared" / "data"
    monkeypatch.setenv(DATA_ENV, str(tmp_path))
    assert data_root() == tmp_path
    assert dataset_dir(KAIST) == tmp_path / "kaist-tsm"                    # absent: the project's name
    kaist_clone(tmp_path)
    mrd_clone(tmp_path, rows=5)
    assert default_kaist_dir() == tmp_path / "hysteresis_compensation_ROS"
    assert default_mrd_dir() == tmp_path / "mis-tool-characterization"
    (tmp_path / "kaist-tsm").mkdir()                                      # the project's folder wins
    assert default_kaist_dir() == tmp_path / "kaist-tsm"
    why = skip_reason(MRD, tmp_path / "x")
    assert DATA_ENV in why and GUIDE in why and MRD.url in why and "\n" not in why


def test_the_kaist_resolver_finds_the_clones_configurations_by_their_names(tmp_path):
    root = kaist_clone(tmp_path)
    sel = root / "optimization" / "selected"
    for given in (root, sel):
        folder, found = kaist_files(given)
        assert folder == sel and [n for n, _ in found] == list(KAIST_CONFIGS)
        assert [p.name for _, p in found] == [f"{n}.txt" for n in KAIST_CONFIGS]
    assert config_of(sel / "60.txt") == 60 and config_of(tmp_path / "60.txt") is None
    assert config_of(tmp_path / "sine_config_240.txt") == 240
    own = tmp_path / "kaist-tsm"
    own.mkdir()
    (own / "sine_config_180.txt").write_text(kaist_rows(10))
    assert [n for n, _ in kaist_files(own)[1]] == [180]
    assert kaist_files(tmp_path / "nowhere") == (tmp_path / "nowhere", [])


def test_analyze_kaist_on_a_clones_root_reads_every_configuration_or_those_asked(tmp_path, monkeypatch):
    root = kaist_clone(tmp_path, stamps=400)
    seen: list = []

    def fake(recs, progress=False, **kw):
        seen.append([(r.config_deg, Path(r.source).name) for r in recs])
        return {"mode": "kaist", "configurations": []}, []
    monkeypatch.setattr(analyze, "analyze_kaist", fake)
    p = argparse.ArgumentParser()
    analyze.add_arguments(p)
    assert analyze.main_analyze(p.parse_args(["--kaist", str(root)])) == 0
    assert analyze.main_analyze(p.parse_args(["--kaist", str(root), "--configs", "0,120"])) == 0
    monkeypatch.setenv(DATA_ENV, str(tmp_path))                           # no DIR: the data folder's clone
    assert analyze.main_analyze(p.parse_args(["--kaist", "--configs", "60"])) == 0
    assert seen == [[(n, f"{n}.txt") for n in KAIST_CONFIGS], [(0, "0.txt"), (120, "120.txt")], [(60, "60.txt")]]
    with pytest.raises(DataError, match=r"selected: no configuration 30 \(--configs\); the folder holds 0, 60, 120, "
                                        r"180, 240$"):
        analyze.main_analyze(p.parse_args(["--kaist", str(root), "--configs", "30"]))
    with pytest.raises(ConfigError, match=r"--configs 0,x: expected bend angles"):
        analyze.main_analyze(p.parse_args(["--kaist", str(root), "--configs", "0,x"]))


def test_teleop_analyze_kaist_on_a_tiny_clone_stops_on_the_data_in_one_line(tmp_path, capsys):
    root = kaist_clone(tmp_path, stamps=10)
    assert main(["analyze", "--kaist", str(root), "--bootstrap", "0"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "0.txt: 10 samples, too few to split into training and test" in err[0], err
    assert main(["analyze", "--kaist", str(tmp_path)]) == 2                # not a clone: what to do
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"no KAIST recordings found under {tmp_path}: expected optimization/selected/<N>.txt" \
        in err[0] and "github.com/nhoyh/hysteresis_compensation_ROS" in err[0] and GUIDE in err[0], err


def test_the_mrd_resolver_takes_a_clones_root_its_data_or_one_tool_folder(tmp_path, capsys):
    root = mrd_clone(tmp_path)
    data, tool4 = root / "data", root / "data" / "Tool_4_Maryland_L_2"
    for given in (root, data):
        folder, files, note = find_mrd_folder(given)
        assert folder == tool4 and [f.name for f in files] == ["00.TXT", "01.TXT", "10.TXT"]
        assert "3 folders of runs; reading" in note and "Tool_4_Maryland_L_2" in note
    roll = data / "Tool_4_Maryland_L_Roll_1"
    assert find_mrd_folder(roll) == (roll, [roll / "000.TXT"], "")        # not SerialLog.txt nor ReadME.txt
    assert mrd_folder("Tool_5_Maryland_L_2", root) == data / "Tool_5_Maryland_L_2"
    runs, bad = load_mrd_dir(root)
    assert [r.name for r in runs] == ["00", "01", "10"] and bad == [] and [r.load_level for r in runs] == [0, 1, 2]
    assert "reading" in capsys.readouterr().err
    (data / "Tool_4_Maryland_L_2").rename(data / "Tool_4_Maryland_L_3")   # several folders, none the default
    with pytest.raises(DataError, match=r": 3 folders of runs \(data/Tool_4_Maryland_L_3, "
                                        r"data/Tool_4_Maryland_L_Roll_1, data/Tool_5_Maryland_L_2\): "
                                        r"give one of them$"):
        find_mrd_folder(root)
    with pytest.raises(DataError, match=r"no MRD recordings found under .*: expected data/Tool_<\.\.\.>/<NN>\.TXT"):
        find_mrd_folder(root / "RAL-2018")


def test_teleop_analyze_mrd_on_a_tiny_clone_stops_on_the_data_in_one_line(tmp_path, capsys, monkeypatch):
    root = mrd_clone(tmp_path, rows=50)
    monkeypatch.setenv(DATA_ENV, str(tmp_path))
    for argv in (["analyze", "--mrd", str(root)], ["analyze", "--mrd"]):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert f"{root / 'data' / 'Tool_4_Maryland_L_2'}: no readable run" in err[-1], err
        assert "00.TXT: 50 data rows, need at least 2000 (truncated file?)" in err[-1]


def test_the_format_is_told_by_content_whatever_the_name(tmp_path):
    kaist, mrd = kaist_clone(tmp_path, stamps=20), mrd_clone(tmp_path)
    selected = kaist / "optimization" / "selected" / "60.txt"
    run = mrd / "data" / "Tool_4_Maryland_L_2" / "00.TXT"
    misnamed = {"00.TXT": kaist_rows(5), "sine_config_0.txt": mrd_rows(5), "run.csv": mrd_rows(5),
                "11.TXT": "# units: time=s, x_in=m, T_in=N\ntime,x_in,T_in,T_out\n0,0,1,1\n0.001,0,1,1\n"}
    for name, text in misnamed.items():
        (tmp_path / name).write_text(text)
    os.symlink(run, tmp_path / "sine_config_60.txt")                      # a link named like a KAIST file
    assert recording_format(selected) == "kaist" and recording_format(run) == "mrd"
    assert [recording_format(tmp_path / n) for n in misnamed] == ["kaist", "mrd", "mrd", "csv"]
    assert recording_format(tmp_path / "sine_config_60.txt") == "mrd"
    assert recording_format(tmp_path / "00.TXT", "mrd") == "mrd"          # a format given is taken as given
    notes = tmp_path / "notes.txt"
    notes.write_text("measured on Tuesday\nwith the second rig\n")
    with pytest.raises(DataError) as e:
        recording_format(notes)
    msg = str(e.value)
    assert "\n" not in msg and str(notes) in msg and "not a recording of a known format" in msg
    assert all(f in msg for f in ("csv (", "kaist (", "mrd (")), msg
    (tmp_path / "utf16.txt").write_bytes("0,1,2,3,4,5,6,7\n".encode("utf-16"))
    with pytest.raises(DataError, match=r"utf16\.txt: not a recording of a known format \(looks like UTF-16"):
        recording_format(tmp_path / "utf16.txt")


def test_demo_recording_takes_the_instrument_of_the_format_its_content_shows(tmp_path):
    kaist, mrd = kaist_clone(tmp_path, stamps=20), mrd_clone(tmp_path)
    base = load_config(ROOT / "configs" / "sim.yaml")
    selected = kaist / "optimization" / "selected" / "60.txt"
    cfg = with_recording(base, argparse.Namespace(config=None, rig=None, recording=str(selected)))
    assert cfg.rig.type == "recording" and cfg.instrument.id == "kaist-bend"
    assert cfg.rig.recording.path == str(selected.resolve())
    run = mrd / "data" / "Tool_4_Maryland_L_2" / "00.TXT"
    link = tmp_path / "sine_config_0.txt"
    os.symlink(run, link)
    cfg = with_recording(base, argparse.Namespace(config=None, rig=None, recording=str(link)))
    assert cfg.instrument.id == "maryland-left" and cfg.rig.recording.path == str(run.resolve())


def test_the_commands_of_get_the_data_name_the_clones_as_they_are(tmp_path, monkeypatch):
    """Every command of docs/how-to/get-the-data.md parses, and the folders and files it names are found in clones
    laid out as upstream (the fixtures), with TSM_TELEOP_DATA naming their folder."""
    kaist_clone(tmp_path, stamps=5)
    mrd_clone(tmp_path, rows=5)
    monkeypatch.setenv(DATA_ENV, str(tmp_path))
    parser = argparse.ArgumentParser()
    analyze.add_arguments(parser)
    add_tool_argument(parser)
    lines = [ln for ln in (ROOT / GUIDE).read_text(encoding="utf-8").splitlines()
             if ln.startswith(("teleop ", "git clone", "python benchmarks/"))]
    kinds = set()
    for line in lines:
        words = os.path.expandvars(line).split()
        if words[:2] == ["git", "clone"]:
            kinds.add("clone")
            assert words[2] in (KAIST.url + ".git", MRD.url + ".git")
        elif words[:2] == ["teleop", "analyze"]:
            a = parser.parse_args(words[2:])
            if a.kaist is not None:
                kinds.add("kaist")
                found = [n for n, _ in kaist_files(find_kaist_dir(a.kaist or None))[1]]
                assert set(parse_configs(a.configs) or found) <= set(found), line
            else:
                kinds.add("mrd")
                assert find_mrd_folder(a.mrd or None)[1], line
        elif words[:2] == ["teleop", "demo"]:
            kinds.add("demo")
            assert recording_format(Path(words[words.index("--recording") + 1])) in ("kaist", "mrd"), line
        else:
            kinds.add("benchmark")
            assert Path(words[words.index("--repo") + 1], "data").is_dir(), line
    assert kinds == {"clone", "kaist", "mrd", "demo", "benchmark"}
