"""Rerun logging: .rrd files read back with rerun.chunk.RrdReader (rerun-sdk 0.41)."""
from __future__ import annotations

from collections import defaultdict
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest

pytest.importorskip("rerun")

from rerun.chunk import RrdReader  # noqa: E402

from estimator.phase import Phase  # noqa: E402
from teleop.errors import ConfigError  # noqa: E402
from teleop.rerun.logger import RerunLogger, signal_path  # noqa: E402


def _read(path: Path) -> tuple[RrdReader, dict[str, list[tuple[int | None, dict]]]]:
    """Entity path -> [(time [ns] or None if static, {component: value}), ...] sorted by time."""
    reader = RrdReader(path)
    rows: dict[str, list[tuple[int | None, dict]]] = defaultdict(list)
    for chunk in reader.stream().to_chunks():
        batch = chunk.to_record_batch()
        names = [n for n in batch.schema.names if ":" in n]
        times = (batch.column("time").cast(pa.int64()).to_pylist() if "time" in batch.schema.names
                 else [None] * batch.num_rows)
        columns = {n: batch.column(n).to_pylist() for n in names}
        for i, t in enumerate(times):
            rows[chunk.entity_path].append((t, {n: columns[n][i] for n in names
                                                if columns[n][i] is not None}))
    for entity in rows:
        rows[entity].sort(key=lambda r: -1 if r[0] is None else r[0])
    return reader, rows


def _tensor(value: list[dict]) -> list[float]:
    [tensor] = value
    assert tensor["shape"] == [len(tensor["buffer"])]
    return tensor["buffer"]


def _run(logger: RerunLogger, n: int = 20) -> tuple[np.ndarray, list[np.ndarray]]:
    s = np.linspace(0.0, 0.6, 12)
    hats = []
    for i in range(n):
        t = 0.01 * i
        hat = 10.0 * np.exp(-1.5 * s) + 0.1 * i
        hats.append(hat)
        logger.log_profile(t, s, hat, 10.0 * np.exp(-1.2 * s))
        logger.log_scalars(t, T_in=10.0 + i, T_out_true=8.0, T_out_hat=8.0 + 0.01 * i,
                           elongation_true=1e-3, elongation_hat=None, x_in=2e-3, marker=1.0)
        logger.log_phase(t, "pull" if i < 5 or i >= 15 else "release")
    return s, hats


def test_save_writes_rrd_that_reads_back(tmp_path):
    path = tmp_path / "out" / "live.rrd"
    with RerunLogger("teleop-test", "rec-save", "save", path) as logger:
        s, hats = _run(logger)
        stream = logger.recording  # a live reference must not keep the file unfinished
    assert path.stat().st_size > 0 and stream is not None
    reader, rows = _read(path)
    [entry] = reader.recordings()
    assert (entry.application_id, entry.recording_id) == ("teleop-test", "rec-save")
    assert reader.blueprints(), "the default blueprint is stored with the recording"
    assert reader.store().summary()  # footer written: the lazy (manifest) reader opens it
    assert {"/profile/T_hat", "/profile/T_true", "/tension/T_in", "/tension/T_out_true",
            "/tension/T_out_hat", "/elongation/elongation_true", "/displacement/x_in",
            "/signals/marker", "/phase"} <= set(rows)
    assert "/elongation/elongation_hat" not in rows  # None values are skipped

    t_in = [(t, r["Scalars:scalars"]) for t, r in rows["/tension/T_in"] if t is not None]
    assert t_in == [(i * 10_000_000, [10.0 + i]) for i in range(20)]  # 'time' in ns, 10 ms step
    [(static_t, style)] = [r for r in rows["/tension/T_out_hat"] if r[0] is None]
    assert style["SeriesLines:names"] == ["T_out_hat"]

    profile = [(t, r) for t, r in rows["/profile/T_hat"] if "BarChart:values" in r]
    assert [t for t, _ in profile] == [i * 10_000_000 for i in range(20)]
    for (_, r), hat in zip(profile, hats, strict=False):
        np.testing.assert_array_equal(_tensor(r["BarChart:values"]), hat)
    first = profile[0][1]
    np.testing.assert_array_equal(_tensor(first["BarChart:abscissa"]), s)
    assert "BarChart:color" in first
    assert sum("BarChart:abscissa" in r for _, r in rows["/profile/T_hat"]) == 1  # grid sent once

    phases = [r["StateChange:state"] for t, r in rows["/phase"]]
    assert phases == [["pull"], ["release"], ["pull"]]  # transitions only
    assert [t for t, _ in rows["/phase"]] == [0, 50_000_000, 150_000_000]


def test_profile_decimation_and_grid_change(tmp_path):
    path = tmp_path / "d.rrd"
    logger = RerunLogger("teleop-test", "rec-dec", "save", path, profile_every=3)
    for i in range(10):
        s = np.linspace(0, 0.5, 5) if i < 6 else np.linspace(0, 0.7, 8)
        logger.log_profile(0.1 * i, s, np.full(s.shape, float(i)))
    logger.close()
    _, rows = _read(path)
    logged = [(t, r) for t, r in rows["/profile/T_hat"] if "BarChart:values" in r]
    assert [_tensor(r["BarChart:values"])[0] for _, r in logged] == [0.0, 3.0, 6.0, 9.0]
    grids = [_tensor(r["BarChart:abscissa"]) for _, r in logged if "BarChart:abscissa" in r]
    assert [len(g) for g in grids] == [5, 8]
    assert "/profile/T_true" not in rows  # no truth given


def test_two_streams_coexist(tmp_path):
    a = RerunLogger("teleop-test", "rec-a", "save", tmp_path / "a.rrd")
    b = RerunLogger("teleop-test", "rec-b", "save", tmp_path / "b.rrd")
    a.log_scalars(0.0, T_in=1.0)
    b.log_scalars(0.0, T_out_hat=2.0)
    a.log_scalars(0.5, T_in=3.0)
    a.close()
    b.close()
    reader_a, rows_a = _read(tmp_path / "a.rrd")
    reader_b, rows_b = _read(tmp_path / "b.rrd")
    assert [e.recording_id for e in reader_a.recordings()] == ["rec-a"]
    assert [e.recording_id for e in reader_b.recordings()] == ["rec-b"]
    assert "/tension/T_in" in rows_a and "/tension/T_out_hat" not in rows_a
    assert "/tension/T_out_hat" in rows_b and "/tension/T_in" not in rows_b
    t_in = [r["Scalars:scalars"] for t, r in rows_a["/tension/T_in"] if t is not None]
    assert t_in == [[1.0], [3.0]]


def test_off_writes_nothing(tmp_path):
    logger = RerunLogger("teleop-test", "rec-off", "off", tmp_path / "never.rrd")
    assert not logger.enabled and logger.recording is None and logger.mode == "off"
    _run(logger, n=3)
    logger.flush()
    logger.close()
    assert list(tmp_path.iterdir()) == []


def test_spawn_without_display_falls_back_to_save(tmp_path, monkeypatch, capsys):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setattr("sys.platform", "linux")
    path = tmp_path / "fallback.rrd"
    logger = RerunLogger("teleop-test", "rec-spawn", "spawn", path)
    assert logger.mode == "save" and logger.path == path
    logger.log_scalars(0.0, T_in=1.0)
    logger.close()
    err = capsys.readouterr().err
    assert "no display" in err and f"saving to {path}" in err
    assert "/tension/T_in" in _read(path)[1]


def test_spawn_failure_falls_back_to_save(tmp_path, monkeypatch, capsys):
    import rerun

    def no_viewer(**kwargs):
        raise RuntimeError("Failed to find Rerun Viewer executable")

    monkeypatch.setattr("teleop.rerun.logger.display_available", lambda: True)
    monkeypatch.setattr(rerun, "spawn", no_viewer)
    with RerunLogger("teleop-test", "rec-nospawn", "spawn", tmp_path / "f.rrd") as logger:
        assert logger.mode == "save"
        logger.log_phase(0.0, Phase.HOLD)
        logger.log_phase(0.1, "hold")  # same phase: not logged again
    assert "could not spawn the viewer (Failed to find" in capsys.readouterr().err
    assert [r["StateChange:state"] for _, r in _read(tmp_path / "f.rrd")[1]["/phase"]] == [["hold"]]


def test_close_is_idempotent_and_later_calls_are_noops(tmp_path):
    path = tmp_path / "c.rrd"
    logger = RerunLogger("teleop-test", "rec-close", "save", path)
    logger.log_scalars(0.0, T_in=1.0)
    logger.close()
    size = path.stat().st_size
    logger.close()
    logger.log_scalars(1.0, T_in=2.0)
    logger.log_profile(1.0, np.arange(3.0), np.ones(3))
    assert not logger.enabled and path.stat().st_size == size


def test_bad_arguments(tmp_path):
    with pytest.raises(ConfigError, match="expected one of save, spawn, serve, off, got 'file'"):
        RerunLogger("a", "b", "file", tmp_path / "x.rrd")
    with pytest.raises(ConfigError, match="mode 'save' needs a path"):
        RerunLogger("a", "b", "save", None)
    with pytest.raises(ConfigError, match="profile_every must be >= 1"):
        RerunLogger("a", "b", "off", None, profile_every=0)
    logger = RerunLogger("a", "b", "save", tmp_path / "x.rrd")
    with pytest.raises(ValueError, match=r"s_positions \(3,\), T_estimated \(4,\)"):
        logger.log_profile(0.0, np.arange(3.0), np.arange(4.0))
    with pytest.raises(ValueError, match=r"T_true \(2,\)"):
        logger.log_profile(0.0, np.arange(3.0), np.arange(3.0), np.arange(2.0))
    logger.close()


def test_signal_paths():
    assert [signal_path(n) for n in ("T_in", "T_out_hat", "elongation_true", "x_out", "seq")] == [
        "tension/T_in", "tension/T_out_hat", "elongation/elongation_true", "displacement/x_out",
        "signals/seq"]


def test_route_geometry_follows_the_config_runs():
    from teleop.rerun.layout import route_points
    runs = [(0.3, float("inf")), (0.6, 0.191), (0.3, float("inf"))]
    p = route_points(runs)
    length = np.linalg.norm(np.diff(p, axis=0), axis=1).sum()
    assert length == pytest.approx(1.2, rel=2e-3)                 # chords of the arc: slightly short
    # the ~180 deg bend turns the route back: the last run heads -x, 2 r above the first
    assert p[-1][1] == pytest.approx(2 * 0.191 * np.sin(0.6 / 0.191 / 2) ** 2, rel=1e-2)   # 1 - cos = 2 sin^2
    assert p[-1][0] < p[-2][0] and p[1][0] == pytest.approx(0.3)


def test_sheath_view_master_series_and_states_are_logged(tmp_path):
    from teleop.rerun.layout import tension_colors
    path = tmp_path / "view.rrd"
    with RerunLogger("test", "view", "save", path, route=[(0.5, float("inf")), (0.5, 0.2)]) as rr:
        rr.log_scalars(0.0, T_in=0.0)                             # first log: route, range, rest profile
        s = np.linspace(0.0, 1.0, 20)
        rr.log_profile(0.1, s, np.linspace(10.0, 5.0, 20), np.linspace(10.0, 5.2, 20))
        rr.log_master(0.1, x_in_cmd=1e-3, force=-1.0, force_cmd=-1.1, rtt=0.001, console="ENGAGED",
                      experiment="paper")
        rr.log_master(0.2, x_in_cmd=1e-3, force=-1.0, force_cmd=-1.1, rtt=None, console="ENGAGED",
                      experiment="paper")
    _, rows = _read(path)
    for entity in ("/sheath/route", "/sheath/tension", "/sheath/tension_true", "/sheath/distal", "/profile/range",
                   "/master/force", "/master/x_in_cmd", "/master/console", "/experiment"):
        assert entity in rows, entity
    assert len(rows["/sheath/tension"]) == 2                      # the rest profile, then the estimate
    assert len(rows["/master/console"]) == 1 and len(rows["/master/rtt"]) == 2   # static style + one value
    c = tension_colors(np.array([0.0, 25.0, 100.0]))
    assert c[0][2] == 255 and c[1][0] == 255 and (c[1] == c[2]).all()            # blue low, red high, clipped


def test_joint_instrument_view_logs_each_joint_and_its_tendons(tmp_path):
    """A joint instrument's view: per joint the torque and angle series, both tendons' routes and their
    tension in 3D, the tip labelled; an unknown joint is an error; the experiment label names each joint."""
    from master.protocols import experiment_label
    from teleop.config.load import load_config
    from teleop.rerun.layout import JOINT_SPACING, joint_views
    cfg = load_config(Path(__file__).resolve().parents[2] / "configs" / "instrument-3dof.yaml")
    views = joint_views(cfg)
    assert [v.name for v in views] == ["bend_ud", "bend_lr", "grasp"]
    assert views[0].angle_range == tuple(cfg.instrument.joints[0].limits)
    assert views[0].torque_range[1] == pytest.approx(1.2 * 0.004 * cfg.calibration.target_tension)
    path = tmp_path / "joints.rrd"
    with RerunLogger("test", "joints", "save", path, joints=views) as rr:
        rr.log_joint(0.0, "bend_ud", torque_hat=0.01, torque_true=0.012, angle_hat=0.2, angle_true=0.21,
                     profiles=(np.linspace(8.0, 4.0, 11), np.full(11, 0.5)))
        rr.log_joint(0.1, "grasp", torque_hat=-0.002, angle_hat=-0.1)
        with pytest.raises(KeyError):
            rr.log_joint(0.2, "wrist", torque_hat=0.0)
    _, rows = _read(path)
    for entity in ("/joints/bend_ud/torque/hat", "/joints/bend_ud/torque/true", "/joints/bend_ud/angle/hat",
                   "/joints/grasp/torque/hat", "/instrument/bend_ud/a/tension", "/instrument/bend_ud/b/tension",
                   "/instrument/grasp/b/route", "/instrument/bend_ud/tip"):
        assert entity in rows, entity
    assert len(rows["/instrument/grasp/a/tension"]) == 1 and "/joints/grasp/torque/true" not in rows  # at rest only
    assert len(rows["/instrument/bend_ud/a/tension"]) == 2                                         # rest, then 8-4 N
    [(_, tip)] = rows["/instrument/bend_ud/tip"]
    [label] = tip["Points3D:labels"]
    assert label == "bend_ud, torque 0.010 (true 0.012) N m, angle 0.200 (true 0.210) rad"
    [(_, route_a)] = rows["/instrument/grasp/a/route"]
    z = np.asarray(route_a["LineStrips3D:strips"][0])[:, 2]
    assert z == pytest.approx(-2 * JOINT_SPACING)                   # the third pair sits two spacings down
    assert experiment_label(0, ("a", "b")) == "none" and experiment_label(1, ("x",)) == "paper"
    assert experiment_label(1 | (2 << 8), ("bend_ud", "bend_lr", "grasp")) == "bend_ud paper_a, grasp paper_b"


def test_a_saved_recording_goes_on_in_segments_that_each_read_alone(tmp_path):
    """Past its segment time a saved recording finalises its file and goes on in ``<stem>.1.rrd`` with the
    same recording id; the new file carries the routes, series styles, profile grid and phase again."""
    from teleop.rerun.segments import segment_path
    path = tmp_path / "slave.rrd"
    route = [(0.3, float("inf")), (0.3, 0.1)]
    with RerunLogger("teleop-test", "rec-seg", "save", path, route=route, segment_s=3600.0) as logger:
        _run(logger, n=10)
        logger._segment_end = 0.0            # the segment's wall-clock time is over
        s = np.linspace(0.0, 0.6, 12)
        for i in range(10, 20):
            t = 0.01 * i
            logger.log_profile(t, s, np.full(12, float(i)))
            logger.log_scalars(t, T_in=10.0 + i)
            logger.log_phase(t, "release")
        files = logger.segments
    assert files == [path, segment_path(path, 1)] == [path, tmp_path / "slave.1.rrd"]
    reader0, first = _read(path)
    reader1, second = _read(files[1])
    assert [e.recording_id for e in reader1.recordings()] == ["rec-seg"]
    assert reader1.store().summary()                     # finalised (footer) like the first
    t_first = [t for t, _ in first["/tension/T_in"] if t is not None]
    t_second = [t for t, _ in second["/tension/T_in"] if t is not None]
    assert t_first == [i * 10_000_000 for i in range(10)]
    assert t_second == [i * 10_000_000 for i in range(10, 20)]   # no row in both files, none lost
    assert any(t is None and r.get("SeriesLines:names") == ["T_in"] for t, r in second["/tension/T_in"])
    assert any(t is None for t, _ in second["/sheath/route"])    # the route again, static
    grid = [r for _, r in second["/profile/T_hat"] if "BarChart:abscissa" in r]
    assert len(grid) == 1 and "BarChart:color" in grid[0]        # the profile grid again, once
    assert [r["StateChange:state"] for _, r in second["/phase"]] == [["release"]]
