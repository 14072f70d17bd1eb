"""Scores of the live estimate on a recorded MRD run, beside the offline analysis of the same run.

:func:`play_run` drives the recording rig and the recorded spindle axis in process (no transport): one
:meth:`~slave.recording.rig.RecordedSpindle.step` and one :meth:`~slave.recording.spindle.RecordedSpindleAxis.observe`
per recorded sample, each timed. :func:`score_run` scores the live jaw torque the way ``teleop analyze --mrd``
scores its own (:mod:`study.mrd.report`): RMSE over the full scale from the first spindle reversal after
0.5 s, for the centre map from the first sample at which its band reading holds both edges; and the offline
figure of the same run and calibration (the batch model: :func:`recorded.mrd_centre.score_centre` for the
centre map, :func:`estimator.online.spindle.predict_torque` for a pair model).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from estimator.online.spindle import make_batch, predict_torque
from estimator.online.spindle_centre import centre_ready
from recorded.mrd import MrdRun
from recorded.mrd_calibration import run_data
from recorded.mrd_centre import score_centre
from slave.recording.rig import RecordedSpindle
from slave.recording.spindle import CENTRE, RecordedModel, RecordedSpindleAxis
from teleop.config.schema import Config

__all__ = ["Played", "play_run", "scored_from", "score_run", "score_live"]


@dataclass(frozen=True)
class Played:
    """The live estimates of one run, shape (n,): jaw ``torque`` [N m], ``angle`` [rad]; ``step_s`` the wall
    time [s] of each cycle (rig step and estimate), ``cpu_s`` its thread CPU time [s] (the wall time less what
    other processes took from it on a shared machine)."""

    torque: np.ndarray
    angle: np.ndarray
    step_s: np.ndarray
    cpu_s: np.ndarray


def play_run(cfg: Config, model: RecordedModel, run: MrdRun) -> Played:
    """Every sample of ``run`` through the recording rig and the recorded axis of ``model`` (module docstring)."""
    rig = RecordedSpindle(run, cfg.instrument.joints[0].name)
    axis = RecordedSpindleAxis(cfg, cfg.instrument.joints[0], 0)
    axis.start_model(model, rig.state)
    n = len(run)
    tq, an, dt, cpu = np.empty(n), np.empty(n), np.zeros(n), np.zeros(n)
    tq[0], an[0] = axis.sample.torque, axis.sample.angle
    cmd, dt_run = np.zeros(1), run.dt
    clock, cpu_clock = time.perf_counter, time.thread_time
    for k in range(1, n):
        t0, c0 = clock(), cpu_clock()
        st = rig.step(cmd, dt_run)
        a, _ = axis.observe(st)
        dt[k], cpu[k] = clock() - t0, cpu_clock() - c0
        tq[k], an[k] = a.effort_hat, a.position_hat
    return Played(tq, an, dt[1:], cpu[1:])


def scored_from(model: RecordedModel, run: MrdRun) -> int:
    """First scored sample of ``run``: its first spindle reversal after 0.5 s; with the centre map not before
    its band reading holds both edges (as ``teleop analyze --mrd``)."""
    k0 = run_data(run).k0
    if model.chosen == CENTRE and model.centre_map is not None:
        k0 = max(k0, centre_ready(run.theta_p, run.dt, model.centre_map.window))
    return k0


def score_live(est: np.ndarray, truth: np.ndarray, k: int, fs: float) -> float:
    """RMSE of ``est`` against ``truth`` (both [N m], shape (n,)) from sample ``k``, over ``fs`` [N m]."""
    e = np.asarray(est)[k:] - np.asarray(truth)[k:]
    return float(np.sqrt(np.mean(e ** 2)) / fs) if e.size else math.nan


def score_run(cfg: Config, model: RecordedModel, run: MrdRun, fs: float, played: Played | None = None) -> dict:
    """Live and offline jaw torque RMSE [FS] of ``run`` from :func:`scored_from`, their difference, the live
    angle RMSE [deg] and the step times [s] (p50, p99, max)."""
    p = played or play_run(cfg, model, run)
    k = scored_from(model, run)
    rd = run_data(run)
    if model.chosen == CENTRE and model.centre_map is not None:
        offline = score_centre(model.centre_map, rd, rd.k0, fs)["torque_rmse_fs"]
    else:
        b = make_batch([(run.tau_p, run.theta_p)], model.band_centre, model.theta_ref, run.dt)
        offline = score_live(predict_torque(model.pair, b), run.tau_d, k, fs)
    live = score_live(p.torque, run.tau_d, k, fs)
    ea = p.angle[k:] - run.theta_d[k:]
    return {"run": run.name, "live_rmse_fs": live, "offline_rmse_fs": offline, "difference_fs": live - offline,
            "angle_rmse_deg": float(math.degrees(np.sqrt(np.mean(ea ** 2)))) if ea.size else math.nan,
            "scored_from_s": float(run.time[k]) if k < len(run) else math.nan,
            "step_p50_s": float(np.percentile(p.step_s, 50)), "step_p99_s": float(np.percentile(p.step_s, 99)),
            "step_max_s": float(np.max(p.step_s)), "cpu_p50_s": float(np.percentile(p.cpu_s, 50)),
            "cpu_p99_s": float(np.percentile(p.cpu_s, 99))}
