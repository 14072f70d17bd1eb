"""Stability sweep of the haptic loop: force scale x network delay x arm stiffness -> stable or not, chatter.

One process, no Zenoh: the real pieces of the loop stepped at 1 kHz on one clock (docs/concepts/haptic-loop.md)::

    scripted operator + arm/device (master.arm) -> MotionMap (motion_scale) -> delay d ->
    SimulatedRig (sheath, motor, load) -> DistalEstimator (true K, L/EA, route) -> delay d ->
    ForceMap (force_scale, ramp, clamp, slew) -> PassivityController -> the hand

The protocol is the paper's (pull to 20 N, release to 5 N, pull to 20 N, release to 0.3 N). For
each point: chatter of x_in_cmd and of the rendered force above 30 Hz (worst 100 ms window,
:mod:`teleop.timing.loop_metrics`) and the transparency RMS. A point is *stable* when both worst windows are
below :data:`teleop.timing.loop_metrics.CHATTER_LIMITS` (20 um, 0.05 N) and the protocol finished.

Usage: ``.venv/bin/python benchmarks/bench_stability.py [--quick] [--pc off|hard|reserve]``
(prints a table; ~1 s of CPU per point). ``--joints``: the same sweep on the torque axes of the 3-joint
instrument (benchmarks/stability_joints.py: the real slave and master nodes in one process; per
joint the worst of its two pulls; ~7 s of CPU per point); ``--joints --backlash-compensation``: that sweep
with the slave's backlash compensation on (``pair_control.backlash_compensation``, slave/pair_control.py).
"""
from __future__ import annotations

import argparse
import collections
import dataclasses
import time

import numpy as np

from estimator.online.distal import DistalEstimator
from estimator.sheath import SheathModel
from master.arm import ArmParameters
from master.mapping import ForceMap, MotionMap, clamp_force
from master.passivity import PassivityController
from master.protocols import PROTOCOLS
from master.simulated import ScriptedOperator
from slave.simulated import SimulatedRig
from teleop.config.schema import Config
from teleop.timing.loop_metrics import CHATTER_LIMITS, chatter


def run_loop(force_scale: float = 0.2, delay: float = 0.001, arm: ArmParameters | None = None,
             pc: str = "reserve", static_arm: bool = False, motion_scale: float = 0.2,
             protocol: str = "paper", t_max: float = 30.0, force_limit: float | None = None,
             trace: list | None = None) -> dict:
    """One closed-loop run; returns chatter, transparency and whether the protocol finished.

    force_scale [-], delay: one-way network delay [s] (each way), pc: 'off' | 'hard' | 'reserve'
    (passivity controller: none, Hannaford-Ryu, with the 5 mJ reserve), static_arm: the massless
    spring of the first scripted operator.
    """
    cfg = Config()
    dt = 1e-3
    rig = SimulatedRig.from_config(cfg)
    model = SheathModel.from_geometry(cfg.sheath.geometry(), cfg.rig.simulated.mu, cfg.sheath.EA)
    est = DistalEstimator(model, n_nodes=cfg.estimator.n_nodes)
    op = ScriptedOperator(PROTOCOLS[protocol], arm=arm or ArmParameters(), static_arm=static_arm)
    motion = MotionMap(motion_scale)
    m = cfg.master.mapping
    if force_limit is not None:
        m = dataclasses.replace(m, force_limit=float(force_limit))
    fmap = ForceMap(force_scale, m.force_limit, m.ramp_time, m.force_rate_limit)
    passivity = PassivityController(m.force_limit, enabled=pc != "off", reserve=0.005 if pc == "reserve" else 0.0)
    nd = max(0, int(round(delay / dt)))
    cmd_q: collections.deque = collections.deque([0.0] * nd)
    est_q: collections.deque = collections.deque([(0.0, 0.0, 0.0)] * nd)
    seen = (0.0, 0.0, 0.0)                   # (T_in, T_out_hat, T_out true) at the master
    p_prev, force = 0.0, 0.0
    motion.anchor(0.0, 0.0)
    fmap.engage()
    log = []
    t = 0.0
    while t < t_max and not op.finished:
        # master
        op.watch(seen[0], True)
        p = op.read(t).position
        x_cmd = motion.command(p)
        f_cmd = fmap.step(seen[1], t)
        v = (p - p_prev) / dt
        p_prev = p
        force = clamp_force(passivity.step(f_cmd, v, dt), m.force_limit)
        op.set_force(force, t)
        log.append((t, x_cmd, force, -force_scale * seen[2]))
        if trace is not None:
            trace.append((t, seen[0], op.index, op.direction))
        # network out, slave, network back
        cmd_q.append(x_cmd)
        rs = rig.step(cmd_q.popleft(), dt)
        e = est.step(rs.T_in, rs.x_in, rs.t)
        est_q.append((rs.T_in, e.T_out, rs.truth.T_out))
        seen = est_q.popleft()
        t += dt
    a = np.array(log)
    _, xw, _ = chatter(a[:, 0], a[:, 1])
    _, fw, _ = chatter(a[:, 0], a[:, 2])
    err = a[:, 2] - a[:, 3]
    fs = float(np.ptp(a[:, 3])) or float("nan")
    stable = bool(op.finished and xw < CHATTER_LIMITS["x_in_cmd_m"] and fw < CHATTER_LIMITS["force_N"])
    return {"stable": stable, "finished": bool(op.finished), "x_in_cmd_worst_um": 1e6 * xw, "force_worst_N": fw,
            "transparency_rms_fs": float(np.sqrt(np.mean(err ** 2)) / fs), "duration_s": t,
            "pc_active_steps": passivity.active_steps}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="a 2 x 2 x 2 grid")
    ap.add_argument("--pc", default="all", choices=("off", "hard", "reserve", "all"))
    ap.add_argument("--boundary", action="store_true",
                    help="the loop without passivity control at high force scales, force limit 40 N")
    ap.add_argument("--joints", action="store_true",
                    help="the 3-joint instrument's torque axes (benchmarks/stability_joints.py, ~7 s CPU a point)")
    ap.add_argument("--backlash-compensation", action="store_true",
                    help="with --joints: the sweep with pair_control.backlash_compensation on")
    args = ap.parse_args()
    if args.boundary:
        boundary()
        return
    if args.joints:
        joints(args.quick, args.backlash_compensation)
        return
    scales = (0.2, 0.8) if args.quick else (0.1, 0.2, 0.4, 0.8)
    delays = (0.001, 0.02) if args.quick else (0.001, 0.005, 0.02, 0.05)
    stiff = (100.0, 800.0) if args.quick else (100.0, 300.0, 800.0)
    modes = ("off", "hard", "reserve") if args.pc == "all" else (args.pc,)
    t0 = time.process_time()
    print("before/after at the defaults (force_scale 0.2, 1 ms each way, k_arm 300 N/m):")
    for label, kw in (("massless arm + hard PC (before)", dict(static_arm=True, pc="hard")),
                      ("massless arm, no PC", dict(static_arm=True, pc="off")),
                      ("arm + device, hard PC", dict(pc="hard")),
                      ("arm + device, PC with reserve (default)", dict(pc="reserve"))):
        r = run_loop(**kw)
        print(f"  {label:42s} stable {str(r['stable']):5s} x_in_cmd {r['x_in_cmd_worst_um']:8.2f} um  "
              f"force {r['force_worst_N']:6.3f} N  transparency rms {r['transparency_rms_fs']:.3f} FS")
    print()
    print(f"{'pc':8s} {'f_scale':>7s} {'delay_ms':>8s} {'k_arm':>6s} {'stable':>6s} {'x_worst_um':>10s} "
          f"{'F_worst_N':>9s} {'transp_rms':>10s} {'fin':>4s}")
    for mode in modes:
        for fs in scales:
            for d in delays:
                for k in stiff:
                    arm = dataclasses.replace(ArmParameters(), stiffness=k)
                    r = run_loop(force_scale=fs, delay=d, arm=arm, pc=mode)
                    print(f"{mode:8s} {fs:7.2f} {1e3 * d:8.0f} {k:6.0f} {str(r['stable']):>6s} "
                          f"{r['x_in_cmd_worst_um']:10.2f} {r['force_worst_N']:9.3f} {r['transparency_rms_fs']:10.3f} "
                          f"{'y' if r['finished'] else 'n':>4s}", flush=True)
    print(f"CPU {time.process_time() - t0:.1f} s")


def joints(quick: bool = False, backlash: bool = False) -> None:
    """The joint-axis sweep: force scale x one-way delay x arm stiffness on the 3-joint instrument, the
    real nodes in one process (benchmarks/stability_joints.py); the reserve's gain shaped
    (master.passivity: release, fade) and, at the defaults, not (the gain in one sample) for the before/after,
    and with the slave's backlash compensation (slave/pair_control.py); ``backlash``: the sweep with it."""
    from stability_joints import arm_with, calibration, run_joints, summarize

    import master.passivity as passivity

    t0 = time.process_time()
    cal = calibration()
    print(f"calibrated at power-up in {time.process_time() - t0:.1f} s CPU")

    def line(label: str, s: dict) -> None:
        tr = " ".join(f"{v:.3f}" for v in s["transparency_rms_fs"].values())
        print(f"{label} {str(s['stable']):>6s} {s['x_worst_um']:10.2f} {s['force_worst_N']:9.3f}   {tr}   "
              f"{'y' if s['finished'] else 'n'} {s['safe_events']}   {s['worst_at']}", flush=True)

    head = f"{'x_worst_um':>10s} {'F_worst_N':>9s}   transparency rms FS (bend_ud bend_lr grasp)   fin safe  F worst at"
    print(f"{'defaults (fs 0.2, 1 ms, k 300)':32s} {'stable':>6s} " + head)
    keep = passivity.RELEASE_TIME, passivity.FADE_TIME
    passivity.RELEASE_TIME = passivity.FADE_TIME = 1e-9
    line(f"{'gain in one sample (before)':32s}", summarize(run_joints(cal)))
    passivity.RELEASE_TIME, passivity.FADE_TIME = keep
    line(f"{'release 50 ms, fade 10 ms (after)':32s}", summarize(run_joints(cal)))
    line(f"{'no passivity controller':32s}", summarize(run_joints(cal, passivity=False)))
    comp = {"pair_control.backlash_compensation": True}
    line(f"{'backlash compensation':32s}", summarize(run_joints(cal, overrides=comp)))
    print()
    if backlash:
        print("with backlash compensation (pair_control.backlash_compensation):")
    scales = (0.2, 0.8) if quick else (0.1, 0.2, 0.4, 0.8)
    delays = (0.001, 0.02) if quick else (0.001, 0.02, 0.05)
    stiff = (100.0, 800.0) if quick else (100.0, 300.0, 800.0)
    print(f"{'f_scale':>7s} {'delay_ms':>8s} {'k_arm':>6s} {'stable':>6s} " + head)
    for fs in scales:
        for d in delays:
            for k in stiff:
                line(f"{fs:7.2f} {1e3 * d:8.0f} {k:6.0f}",
                     summarize(run_joints(cal, fs, d, arm_with(k), overrides=comp if backlash else None)))
    print(f"CPU {time.process_time() - t0:.1f} s")


def boundary() -> None:
    """Where the force loop through the tendon itself goes unstable (no PC, force limit 40 N); the
    small-gain estimate L0 = force_scale motion_scale k_t / k_arm with k_t = dT_out/dx_in ~ 1700 N/m."""
    print(f"{'f_scale':>7s} {'delay_ms':>8s} {'k_arm':>6s} {'L0':>6s} {'stable':>6s} {'x_worst_um':>10s} "
          f"{'F_worst_N':>9s} {'transp_rms':>10s}")
    for fs in (0.8, 1.6, 3.2, 6.4):
        for d in (0.001, 0.02, 0.05):
            for k in (100.0, 800.0):
                r = run_loop(force_scale=fs, delay=d, arm=dataclasses.replace(ArmParameters(), stiffness=k),
                             pc="off", force_limit=40.0, t_max=20.0)
                print(f"{fs:7.2f} {1e3 * d:8.0f} {k:6.0f} {fs * 0.2 * 1700 / k:6.2f} {str(r['stable']):>6s} "
                      f"{r['x_in_cmd_worst_um']:10.2f} {r['force_worst_N']:9.3f} {r['transparency_rms_fs']:10.3f}",
                      flush=True)


if __name__ == "__main__":
    main()
