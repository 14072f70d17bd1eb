"""``teleop demo --config configs/notes-bimanual.yaml``: both arms of a bimanual instrument end to end.

The flow of every demo (:mod:`live.demo.main`) for two arms (:mod:`teleop.arms`):

1. ``runs/<id>/config.yaml`` is the bimanual file with ``calibration.dir`` set to ``runs/<id>/calibration``
   and, on a machine of fewer than :data:`teleop.timing.realtime.CO_LOCATED_MIN_CPUS` CPUs, the sides'
   ``realtime_priority`` 0, said in one line (:func:`live.demo.run.co_located`, as for one arm;
   ``--keep-realtime`` keeps the configured priorities); each arm's resolved config goes to
   ``runs/<id>/<arm id>/config.yaml``;
2. ``teleop calibrate`` of each arm (in this process, simulated as fast as it computes): every tendon of
   every pair into its joint limit both ways, ``runs/<id>/calibration/<arm id>.yaml``, which the slave reloads;
3. one ``teleop record`` per arm (its arm's config, into ``runs/<id>/<arm id>/recorder``, completing its recording
   from its arm's records in the sides' journals in ``runs/<id>``, ``--journals``), then the slave
   (both arms in one loop, :mod:`live.bimanual_sides`) and the master (both hands in one loop, scripted
   operators running the paper's protocol on every joint of their arm) as two processes over Zenoh on
   127.0.0.1; the sides connect to both recorders;
4. each arm is evaluated as a joint instrument (:class:`live.demo.joints.JointDemo` on ``runs/<id>/<arm id>``:
   calibration against the simulator, per-joint torque error on the paper's protocol against 0.05 FS,
   chatter and transparency per joint and pulled tendon), its loops and round trip reported, and its
   recorder checked for loss (messages missing by seq);
5. the table is printed and ``summary.json`` written (``arms.<name>``: each arm's summary; ``slave_group``,
   ``master_group``: the shared loops and each arm's step time); exit 0 when every check of every arm passed.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import yaml

from estimator.errors import DataError
from live.demo.run import (
    RecorderRun,
    check_protocol,
    co_located,
    finish,
    loop_lines,
    master_console_line,
    read_json,
    run_processes,
    verdict_lines,
)
from teleop.arms import Bimanual, load_arms
from teleop.config.load import write_config
from teleop.config.reader import read_yaml

__all__ = ["main_bimanual", "recorder_check", "format_bimanual", "bimanual_figure", "OVERRUN_TARGET"]

#: The loops' overrun fraction the bimanual demo aims below (reported, not checked: it depends on the machine).
OVERRUN_TARGET = 0.005


def _resolved(src: Path, run_dir: Path, loaded: Bimanual, keep_realtime: bool = False) -> tuple[Bimanual, str | None]:
    """The bimanual file ``src`` (``loaded``: as :func:`teleop.arms.load_arms` read it) with ``calibration.dir`` =
    ``<run_dir>/calibration``, ``recording.csv_every`` = 1 (the chatter check reads every cycle) and, unless
    ``keep_realtime``, the sides' real-time priorities of one machine that runs both sides and the recorders
    (:func:`live.demo.run.co_located`) written to ``<run_dir>/config.yaml``, loaded; each arm's config written to
    ``<run_dir>/<arm id>/config.yaml``. Returns (the loaded file, the line that says why the priorities changed, or
    None)."""
    data, _ = read_yaml(src)
    data["calibration"] = {**(data.get("calibration") or {}), "dir": str(run_dir / "calibration")}
    data["recording"] = {**(data.get("recording") or {}), "csv_every": 1}
    why = None
    if not keep_realtime:      # the sides' sections are shared by both arms: one loop per side
        cfg, why = co_located(loaded.arms[0].cfg)
        if why is not None:
            data["master"] = {**(data.get("master") or {}), "realtime_priority": cfg.master.realtime_priority}
            data["slave"] = {**(data.get("slave") or {}), "realtime_priority": cfg.slave.realtime_priority}
    out = run_dir / "config.yaml"
    out.write_text("# resolved bimanual configuration of this run (teleop/arms.py)\n"
                   + yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    bim = load_arms(out)
    for arm in bim.arms:
        (run_dir / arm.ident).mkdir(parents=True, exist_ok=True)
        write_config(arm.cfg, run_dir / arm.ident / "config.yaml")
    return bim, why


def recorder_check(out_dir: Path) -> tuple[bool, str]:
    """(no loss, one line) of a finished recorder: it heard messages and none is missing by seq."""
    s = read_json(out_dir / "summary.json")
    streams = s.get("streams", {}).values()
    count, missing = sum(v.get("count", 0) for v in streams), sum(v.get("missing", 0) for v in streams)
    return bool(count > 0 and missing == 0), \
        f"{count} messages on {len(s.get('streams', {}))} streams, {missing} missing"


def _processes(args, bim: Bimanual, run_dir: Path, problems: list[str]) -> None:
    """Two recorders, the slave and the master (module docstring, step 3); what went wrong into ``problems``."""
    timeout = f"{float(args.timeout):g}"
    recorders = [RecorderRun(f"recorder of {arm.name}", ["--config", str(run_dir / arm.ident / "config.yaml"),
                                                         "--run-dir", str(run_dir / arm.ident), "--journals",
                                                         str(run_dir), "--max-duration", timeout], run_dir / arm.ident)
                 for arm in bim.arms]
    run_processes(args, run_dir / "config.yaml", run_dir, problems, recorders=recorders,
                  doing=f"protocol {args.protocol} on every joint",
                  sides=f"slave and master of {', '.join(a.name for a in bim.arms)}", report=False)


def _evaluate(bim: Bimanual, run_dir: Path, summary: dict, problems: list[str]) -> dict[str, bool]:
    """Each arm's evaluation into ``summary["arms"]``; every arm's checks, named by arm."""
    from live.demo.joints import JointDemo
    checks: dict[str, bool] = {}
    for arm in bim.arms:
        d = run_dir / arm.ident
        s: dict = {"run_dir": str(d), "instrument": arm.ident, "hand": arm.hand,
                   "axes": [j.name for j in arm.cfg.instrument.joints],
                   "master": read_json(d / "master_stats.json"), "slave": read_json(d / "slave_stats.json")}
        own: list[str] = []
        verdicts = JointDemo.evaluate(s, d, arm.cfg, own)
        ok, line = recorder_check(d / "recorder")
        s["recorder"] = line
        verdicts[f"recorder: nothing lost ({line})"] = ok
        checks.update({f"{arm.name}: {k}": v for k, v in verdicts.items()})
        problems += [f"{arm.name}: {p}" for p in own]
        summary["arms"][arm.name] = s
    for side in ("slave", "master"):
        g = read_json(run_dir / f"{side}_stats.json")
        summary[f"{side}_group"] = {k: g.get(k) for k in ("pacer", "arm_steps", "safe_events")}
    return checks


def bimanual_figure(bim: Bimanual, run_dir: Path, out_png: Path) -> Path:
    """One panel per arm and joint: the true distal joint torque and the estimate from the proximal sensors
    over the engaged run, from each arm's ``slave_joints.csv`` (matplotlib, PNG at ``out_png``).

    Raises
    ------
    DataError
        An arm's recording is missing or unreadable.
    """
    from live.demo.joints import read_joint_csv
    from teleop.recording.figures import pyplot, save_figure
    plt = pyplot()
    n = max(len(a.cfg.instrument.joints) for a in bim.arms)
    fig, axes = plt.subplots(len(bim.arms), n, figsize=(3.6 * n, 3.0 * len(bim.arms)), squeeze=False)
    for r, arm in enumerate(bim.arms):
        cols = read_joint_csv(run_dir / arm.ident / "slave_joints.csv")
        sel = cols["state"] == 3                      # SideState.ENGAGED: the protocol's rows
        t = cols["time"][sel] - (cols["time"][sel][0] if sel.any() else 0.0)
        for c, j in enumerate(arm.cfg.instrument.joints):
            ax = axes[r][c]
            ax.plot(t, 1e3 * cols[f"{j.name}.torque"][sel], color="#1f5fa8", lw=1.2, label="true")
            ax.plot(t, 1e3 * cols[f"{j.name}.torque_hat"][sel], color="#e07b00", lw=0.9, ls="--", label="estimated")
            ax.set_title(f"{arm.name} arm: {j.name}", fontsize=9)
            ax.set_xlabel("time [s]", fontsize=8)
            ax.set_ylabel("distal torque [mN m]", fontsize=8)
            ax.tick_params(labelsize=7)
        axes[r][0].legend(fontsize=7)
    return save_figure(fig, out_png, 110)


def format_bimanual(s: dict) -> str:
    """The printed table of a bimanual summary (:func:`main_bimanual`)."""
    from live.demo.joints import JointDemo
    L = [f"teleop demo (bimanual {', '.join(s['arms'])}): {s['run_dir']}", ""]
    for name, a in s["arms"].items():
        L += [f"==== arm {name} ({a['instrument']}, {a['hand']} hand: {', '.join(a['axes'])})", ""]
        L += JointDemo.lines(a)
        L += ["", master_console_line(a.get("master", {}))]
        L += [ln for ln in loop_lines(a, detailed=False) if ln.startswith("round trip")]
        L += [f"recorder: {a.get('recorder', 'no summary')}", ""]
    L += ["==== both arms: one loop per side", ""]
    L += loop_lines({"master": {"pacer": s.get("master_group", {}).get("pacer") or {}},
                     "slave": {"pacer": s.get("slave_group", {}).get("pacer") or {}}}, detailed=True)
    for side in ("slave", "master"):
        steps = (s.get(f"{side}_group") or {}).get("arm_steps") or {}
        L.append(f"{side:6s} step per arm: " + "; ".join(f"{n} p50 {v['p50_ms']:.3f} ms, p99 {v['p99_ms']:.3f} ms"
                                                          for n, v in steps.items()))
    L.append(f"(overrun target {100 * OVERRUN_TARGET:.1f} % of cycles, reported not checked)")
    L += ["", *verdict_lines(s), ""]
    if s.get("figure"):
        L.append(f"figure:     {s['figure']}  (distal torque of every joint: truth vs estimate)")
    L.append(f"recordings: {s['run_dir']}/<arm id>/ (slave_joints.csv, master.csv, recorder/); summary: "
             f"{s['run_dir']}/summary.json")
    return "\n".join(L)


def main_bimanual(args, cfg_path: Path) -> int:
    """``teleop demo`` of the bimanual config at ``cfg_path``: 0 when every arm's checks passed, else 1."""
    from live.calibrate import run_calibrate
    from live.sides import prepare_run_dir
    from slave.kinds import axis_kind
    bim = load_arms(cfg_path)
    for arm in bim.arms:
        check_protocol(arm.cfg, args.protocol)
    run_dir = prepare_run_dir(args, bim.arms[0].cfg).resolve()
    bim, scheduling = _resolved(Path(cfg_path), run_dir, bim, getattr(args, "keep_realtime", False))
    if scheduling is not None:
        print(scheduling, flush=True)
    t0 = time.monotonic()
    problems: list[str] = []
    summary: dict = {"run_dir": str(run_dir), "config": str(run_dir / "config.yaml"), "kind": "bimanual",
                     "protocol": args.protocol, "scheduling": scheduling or "as configured", "arms": {}}
    try:
        for arm in bim.arms:
            names = ", ".join(j.name for j in arm.cfg.instrument.joints)
            print(f"calibrating {arm.ident} ({arm.hand} hand: {names}): {axis_kind(arm.cfg).routine_text} ...",
                  flush=True)
            run_calibrate(argparse.Namespace(config=str(run_dir / arm.ident / "config.yaml"), out=None))
        _processes(args, bim, run_dir, problems)
    except KeyboardInterrupt:
        print(f"teleop demo: interrupted; partial recordings in {run_dir}", file=sys.stderr)
        raise
    checks = _evaluate(bim, run_dir, summary, problems)
    try:
        summary["figure"] = str(bimanual_figure(bim, run_dir, run_dir / "bimanual.png"))
    except (DataError, KeyError, IndexError) as e:
        problems.append(f"figure: {e}")
    return finish(summary, checks, problems, t0, run_dir, format_bimanual)
