"""``teleop slave`` and ``teleop master`` of a bimanual instrument: one process per side, one node per arm.

With a bimanual config (``--config configs/notes-bimanual.yaml``, :mod:`teleop.arms`) each side runs
every arm in one loop (:class:`teleop.node_group.NodeGroup`) on one Zenoh session:

* each arm is the ordinary node of its instrument (:class:`slave.node.SlaveNode`,
  :class:`master.node.MasterNode`) with its own links on its own keys ``teleop/<arm id>/...``, its own
  liveliness token, watchdog, state and heartbeat, its own calibration file
  (``<calibration.dir>/<arm id>.yaml``) and its own recordings in ``<run dir>/<arm id>/`` (``slave_joints.csv``,
  ``master.csv``, ``calibration.json``, ``<side>_stats.json``): a fault on one arm stays on that arm;
* one Rerun logger per side (``recording.rerun`` of the base; ``<run dir>/slave.rrd``, ``master.rrd``, one
  recording): both arms' joints in one 3D view, each arm's series under its name (:class:`ArmRerun`);
* the master's hands: each arm's device (``master.device`` of its entry, any registered type) is
  wrapped in :class:`master.pedal.PedalHand`, so the clutch button of either hand is the one foot pedal
  of both (:mod:`master.pedal`); each hand's deadman is its own device's, and each hand feels only its
  own arm's estimate;
* with ``ros2.enabled`` each arm publishes its CRTK topics under its own arm name (its ``instrument.id``);
* ``--inject SPEC`` (:mod:`live.faults`) takes ``arm=<name>`` besides its own keys: the faults then act
  on that arm's publishers only (without it, on every arm's);
* ``<run dir>/<side>_stats.json`` holds the loop's figures, each arm's step time and each arm's stats.

:func:`live.sides.run_slave` / :func:`live.sides.run_master` hand a bimanual config over to
:func:`run_slave_group` / :func:`run_master_group`.
"""
from __future__ import annotations

import argparse
import contextlib
import faulthandler
import json
import logging
import sys
from pathlib import Path
from typing import Any

from live.side_files import SideFiles
from live.sides import (
    SHUTDOWN_DUMP_S,
    load_or_recalibrate,
    master_links,
    open_session,
    side_run_dir,
    slave_links,
)
from teleop.arms import Arm, Bimanual, load_arms
from teleop.errors import ConfigError
from teleop.node_group import NodeGroup
from teleop.rerun.layout import joint_views
from teleop.wire.messages import Side

__all__ = ["split_arm", "run_slave_group", "run_master_group", "arm_dir"]


def split_arm(spec: str | None, bim: Bimanual) -> tuple[str | None, str | None]:
    """(arm name or None, the rest of the spec or None) of an ``--inject`` spec with ``arm=<name>``.

    Raises
    ------
    ConfigError
        ``arm=`` names no arm of ``bim``.
    """
    if not spec:
        return None, spec
    parts = [p.strip() for p in spec.split(",") if p.strip()]
    arms = [p.split("=", 1)[1] for p in parts if p.startswith("arm=")]
    rest = ",".join(p for p in parts if not p.startswith("arm="))
    if not arms:
        return None, spec
    names = [a.name for a in bim.arms]
    if len(arms) > 1 or arms[0] not in names:
        raise ConfigError(f"--inject: arm={','.join(arms)}: expected one arm of {bim.source} ({', '.join(names)})")
    return arms[0], rest or None


def arm_dir(run_dir: Path, arm: Arm) -> Path:
    """``<run dir>/<arm id>``, created: the arm's recordings and stats."""
    d = Path(run_dir) / arm.ident
    d.mkdir(parents=True, exist_ok=True)
    return d


def _prepare(args: argparse.Namespace, role: str, clock):
    """(bimanual config, run dir, session, fault injector or None, the arm it acts on or None) of a side: the
    session opened, the run id agreed and ``role`` claimed for every arm's instrument."""
    from live.discovery import claim_role
    bim = load_arms(args.config)
    target, spec = split_arm(getattr(args, "inject", None), bim)
    run_dir = side_run_dir(args, bim.arms[0].cfg, role)
    session = open_session(bim.arms[0].cfg, args, clock)
    for arm in bim.arms[1:]:
        claim_role(session, arm.cfg, role, run_dir.name)
    injector = None
    if spec:
        from live.faults import FaultInjector
        injector = FaultInjector(spec, clock)
        injector.install_signal()
        logging.getLogger("live.faults").warning("fault injection on %s: %s", target or "every arm", spec)
    return bim, run_dir, session, injector, target


class ArmRerun:
    """One arm's view of its side's Rerun logger: the arm's joints and master axes logged under ``<arm>/<joint>``
    (``instrument/<arm>/<joint>/...``, ``joints/<arm>/<joint>/...``, ``master/<arm>/<joint>/...``), so that both
    arms share one recording; every other call goes to the logger as it is."""

    def __init__(self, logger: Any, arm: str):
        self.inner, self.arm = logger, arm

    def log_joint(self, t: float, joint: str, **kw: Any) -> None:
        """The arm's joint ``joint`` (:meth:`teleop.rerun.logger.RerunLogger.log_joint`)."""
        self.inner.log_joint(t, f"{self.arm}/{joint}", **kw)

    def log_master(self, t: float, *, axis: str | None = None, **kw: Any) -> None:
        """The arm's master series (:meth:`teleop.rerun.logger.RerunLogger.log_master`), ``axis`` under the arm."""
        self.inner.log_master(t, axis=self.arm if axis is None else f"{self.arm}/{axis}", **kw)

    def __getattr__(self, name: str) -> Any:
        if name == "inner":
            raise AttributeError(name)
        return getattr(self.inner, name)


def _rerun(stack: contextlib.ExitStack, mode: str, run_dir: Path, bim: Bimanual, side: str, files, **kw) -> list[Any]:
    """Each arm's view (:class:`ArmRerun`) of the side's one Rerun logger (``<run dir>/<side>.rrd``, recording id
    the run's: both arms in one recording, their joints stacked in the 3D view), behind the side's disk gate
    (``files``, :class:`live.side_files.SideFiles`); Nones when off."""
    if mode == "off":
        return [None] * len(bim.arms)
    import dataclasses

    from teleop.rerun.process import RerunProcessLogger as RerunLogger  # the loop only queues; a child process logs
    views = tuple(dataclasses.replace(v, name=f"{arm.name}/{v.name}") for arm in bim.arms for v in joint_views(arm.cfg))
    from teleop.rerun.serve import serve_spec
    logger = stack.enter_context(RerunLogger("teleop", run_dir.name, mode, run_dir / f"{side}.rrd", joints=views,
                                             serve=serve_spec(bim.arms[0].cfg, side), **kw))
    gated = files.rerun(logger)
    return [ArmRerun(gated, arm.name) for arm in bim.arms]


def _serve(group: NodeGroup, clock, args, run_dir: Path, side: str, injector, arms, waived, files) -> None:
    """Run the group until done (or ``--max-duration``); then the stats of the group and of every arm, with the
    disk use of the side's files (``files``, :class:`live.side_files.SideFiles`)."""
    from live.side_files import add_to_stats
    from teleop.recording.journal import close_journal, open_journal
    open_journal(run_dir, side)
    try:
        group.run(clock, max_duration=args.max_duration)
    finally:
        if sys.__stderr__ is not None:      # a slow shutdown leaves every thread's stack in the side's log
            with contextlib.suppress(OSError, ValueError):
                faulthandler.dump_traceback_later(SHUTDOWN_DUMP_S, exit=False, file=sys.__stderr__)
        close_journal()
        for arm, node in zip(arms, group.nodes, strict=False):
            path = arm_dir(run_dir, arm) / f"{side}_stats.json"
            path.write_text(json.dumps({**node.stats(), "arm": arm.name, "hand": arm.hand,
                                        "safety_waivers": waived}, indent=2) + "\n", encoding="utf-8")
        (run_dir / f"{side}_stats.json").write_text(json.dumps(group.stats(), indent=2) + "\n", encoding="utf-8")
        files.close()
        add_to_stats(run_dir / f"{side}_stats.json", "disk", files.summary())
        if injector is not None:
            (run_dir / f"{side}_faults.json").write_text(json.dumps(injector.stats(), indent=2) + "\n",
                                                         encoding="utf-8")


def _waivers(arms, log: logging.Logger) -> list[dict]:
    from teleop.config.bounds import announce_waivers
    return [dict(w, arm=a.name) for a in arms for w in announce_waivers(a.cfg, log)]


def run_slave_group(args: argparse.Namespace) -> int:
    """``teleop slave --config <bimanual>``: every arm's slave node in one loop (module docstring)."""
    from slave.node import SlaveNode, recording, warm_up
    from slave.rigs import make_rig
    from teleop.recording.csv_proc import ProcessCsvRecorder as CsvRecorder
    from teleop.recording.measured import raise_on_sigterm
    from teleop.timing.clock import MonotonicClock

    log = logging.getLogger("teleop.slave")
    clock = MonotonicClock()
    bim, run_dir, session, injector, target = _prepare(args, "slave", clock)
    arms = bim.arms
    waived = _waivers(arms, log)
    cals = [load_or_recalibrate(a.cfg, getattr(args, "recalibrate", False)) for a in arms]
    for a in arms:
        warm_up(a.cfg)
    with raise_on_sigterm(), session, contextlib.ExitStack() as stack:
        nodes = []
        files = SideFiles(run_dir, arms[0].cfg, "slave", ("<arm>/slave_joints.csv", "slave.rrd"))   # the disk gates
        stack.callback(files.close)
        views = _rerun(stack, args.rerun or arms[0].cfg.recording.rerun, run_dir, bim, "slave", files)
        for arm, (calibration, cal_path), rr in zip(arms, cals, views, strict=False):
            rig = make_rig(arm.cfg, session)
            stack.callback(rig.close)
            name, columns, meta = recording(arm.cfg, rig)
            rec = stack.enter_context(CsvRecorder(arm_dir(run_dir, arm) / name, columns, meta, flush_every=500))
            links = slave_links(session, arm.ident, injector if target in (None, arm.name) else None)
            if arm.cfg.ros2.enabled:     # the arm's CRTK topics under its own name (teleop/ros2/side.py)
                from teleop.ros2.side import attach_slave
                attach_slave(session, arm.cfg, links)
            nodes.append(SlaveNode(arm.cfg, rig, links, recorder=files.csv(rec), rerun=rr,
                                   run_dir=arm_dir(run_dir, arm),
                                   stop_on_master_stop=args.exit_on_master_stop, calibration=calibration,
                                   calibration_file=cal_path))
        group = NodeGroup(nodes, [a.name for a in arms], Side.SLAVE, arms[0].cfg.rig.rate_hz, arms[0].cfg)
        _serve(group, clock, args, run_dir, "slave", injector, arms, waived, files)
    faulthandler.cancel_dump_traceback_later()
    log.info("slave done (%s): %s", ", ".join(a.name for a in arms), run_dir)
    return 0


def _devices(bim: Bimanual, protocol: str, stack: contextlib.ExitStack) -> list[Any]:
    """Each hand's device (its arm's ``master.device``), closed on leaving ``stack``, wrapped with the
    shared foot pedal (:mod:`master.pedal`)."""
    from master.devices import make_device
    from master.pedal import FootPedal, PedalHand
    pedal = FootPedal([a.cfg.master.mapping.clutch_button for a in bim.arms])
    out = []
    for i, arm in enumerate(bim.arms):
        dev = make_device(arm.cfg, protocol)
        stack.callback(dev.close)
        out.append(PedalHand(dev, pedal, i))
    return out


def run_master_group(args: argparse.Namespace) -> int:
    """``teleop master --config <bimanual>``: both hands' master nodes in one loop (module docstring)."""
    from master.node import MasterNode, csv_columns, csv_units
    from teleop.recording.csv_proc import ProcessCsvRecorder as CsvRecorder
    from teleop.recording.measured import raise_on_sigterm
    from teleop.timing.clock import MonotonicClock

    log = logging.getLogger("teleop.master")
    clock = MonotonicClock()
    bim = load_arms(args.config)
    waived = _waivers(bim.arms, log)
    with contextlib.ExitStack() as devices_open:
        devices = _devices(bim, args.protocol, devices_open)   # closed on every exit path, zero force first
        bim, run_dir, session, injector, target = _prepare(args, "master", clock)
        arms = bim.arms
        with raise_on_sigterm(), session, contextlib.ExitStack() as stack:
            nodes = []
            files = SideFiles(run_dir, arms[0].cfg, "master", ("<arm>/master.csv", "master.rrd"))   # the disk gates
            stack.callback(files.close)
            views = _rerun(stack, getattr(args, "rerun", None) or arms[0].cfg.recording.rerun, run_dir, bim, "master",
                           files, wall_clock=True)
            for arm, dev, rr in zip(arms, devices, views, strict=False):
                meta = {"source": "teleop master", "instrument": arm.ident, "device": arm.cfg.master.device.type,
                        "arm": arm.name, "hand": arm.hand}
                rec = stack.enter_context(CsvRecorder(arm_dir(run_dir, arm) / "master.csv", csv_columns(arm.cfg), meta,
                                                      units=csv_units(arm.cfg), flush_every=100))
                links = master_links(session, arm.ident, injector if target in (None, arm.name) else None)
                if arm.cfg.ros2.enabled:
                    from teleop.ros2.side import attach_master
                    attach_master(session, arm.cfg, links)
                nodes.append(MasterNode(arm.cfg, dev, links, recorder=files.csv(rec), rerun=rr))
            group = NodeGroup(nodes, [a.name for a in arms], Side.MASTER, arms[0].cfg.master.rate_hz, arms[0].cfg)
            _serve(group, clock, args, run_dir, "master", injector, arms, waived, files)
    faulthandler.cancel_dump_traceback_later()
    for arm, node in zip(arms, nodes, strict=False):
        lat = node.latency_stats()
        log.info("master %s done: %s commands, rtt p50 %s ms, p99 %s ms", arm.name, node.commands_sent,
                 lat["p50_ms"], lat["p99_ms"])
    return 0 if all(getattr(d, "finished", True) for d in devices) else 1
