"""Is the haptic loop quiet and transparent? Chatter and transparency from the two sides' recordings.

*Chatter* of a signal y(t) (the command ``x_in_cmd`` [m], the rendered force [N]): y resampled on a
uniform grid at the loop rate, high-passed above ``cutoff`` (30 Hz, 4th-order Butterworth, zero
phase: ``scipy.signal.sosfiltfilt``); reported as the RMS over the experiment and the RMS of the
worst ``window`` (100 ms) window. An operator's hand moves below ~10 Hz, so content above 30 Hz is
the loop's, not the surgeon's: a limit cycle shows as a worst window far above the experiment RMS.

*Transparency*: the rendered force F(t) against the force an ideal loop would render, the scaled
true distal tension ``-force_scale T_out(t)`` (the simulator's truth, interpolated at the master's
times; the two sides share one monotonic clock on one machine), so estimator error, delay, slew,
ramp and passivity damping all count::

    e(t) = F(t) + force_scale T_out(t)          [N]
    rms_fs = RMS(e) / (force_scale ptp(T_out)),  max_fs = max|e| / (force_scale ptp(T_out))   [-]

Where the error comes from, when the recordings carry the master's mapped force ``force_cmd`` (before
the passivity controller) and the slave's estimate ``T_out_hat``: the error splits exactly into three
shares, each reported as its RMS over the same full scale::

    e = s (T_out - T_out_hat)          estimate: the estimator's error (no tip sensor)
      + (force_cmd + s T_out_hat)      loop: the link's delay, the force ramp, slew and clamp, stale zeroing
      + (F - force_cmd)                passivity: the passivity controller's cut (and the device clamp)

(``s`` = force_scale; ``T_out_hat`` interpolated at the master's times like ``T_out``, so the time the
estimate takes to reach the master is the loop's share.) A transmission with a release band shows here: at
a joint's stop the distal torque holds while the hand draws back through the band, so rendering it on the
hand's motion hands energy back that the operator never put in, and the passivity controller takes that
force out (docs/concepts/haptic-loop.md).

The master rows of an experiment are those whose command seq the slave recorded under the
experiment's marker (the tendon master's CSV has no marker column). Chatter leaves out the windows
around rows where the master was not ENGAGED (a watchdog's safe event cuts the force at once and
ramps it in again: a step, not a limit cycle); ``not_engaged_s`` reports how long that was.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from estimator.errors import DataError

__all__ = ["CUTOFF_HZ", "WINDOW_S", "CHATTER_LIMITS", "TRANSPARENCY_LIMIT_FS", "chatter", "loop_metrics",
           "read_columns", "run_loop_metrics", "chatter_checks", "transparency_checks", "loop_metric_lines"]

ENGAGED = 3          # teleop.wire.messages.SideState.ENGAGED
CUTOFF_HZ = 30.0
WINDOW_S = 0.1
#: The demo's check: worst-window chatter below these (x_in_cmd [m], force [N]); docs/concepts/haptic-loop.md
#: "The checks' limits": 20 um of tendon = 100 um of hand at motion_scale 0.2, the order of the
#: surgeon's own physiological tremor; 0.05 N = the force JND (~10 %, Jones 1989; Pang et al. 1991)
#: of the smallest force worth feeling through the device, 0.5 N.
CHATTER_LIMITS = {"x_in_cmd_m": 20e-6, "force_N": 0.05}
#: The joint demo's check: transparency RMS error below this fraction of full scale, the stiffness JND
#: (23 %, Jones & Hunter 1990): below it the rendered tissue cannot be told from the true one by its
#: stiffness (docs/concepts/haptic-loop.md).
TRANSPARENCY_LIMIT_FS = 0.23


def chatter(t: np.ndarray, y: np.ndarray, *, cutoff: float = CUTOFF_HZ, window: float = WINDOW_S,
            rate: float = 1000.0, exclude: np.ndarray | None = None) -> tuple[float, float, float]:
    """(RMS above ``cutoff``, RMS of the worst ``window``, start time of that window) of ``y(t)``.

    t : ndarray, shape (n,) [s], increasing; y : ndarray, shape (n,) [any unit]; cutoff [Hz]; window
    [s]; rate [Hz] of the uniform grid; exclude : bool ndarray, shape (n,), optional: samples (e.g. not
    engaged) whose windows, widened by one ``window`` each side, are left out. Returns NaNs for fewer
    than 0.2 s of data.

    Raises
    ------
    DataError
        ``t`` and ``y`` of different shapes.
    """
    from scipy.signal import butter, sosfiltfilt

    t, y = np.asarray(t, float), np.asarray(y, float)
    if t.shape != y.shape or t.ndim != 1:
        raise DataError(f"chatter: time {t.shape} and signal {y.shape} must be 1-D of one length")
    ok = np.isfinite(t) & np.isfinite(y)
    bad = None if exclude is None else np.asarray(exclude, bool)[ok]
    t, y = t[ok], y[ok]
    if t.size < 2 or t[-1] - t[0] < 0.2:
        return math.nan, math.nan, math.nan
    keep = np.concatenate(([True], np.diff(t) > 0))
    t, y = t[keep], y[keep]
    tu = np.arange(t[0], t[-1], 1.0 / rate)
    yu = np.interp(tu, t, y)
    sos = butter(4, cutoff, btype="highpass", fs=rate, output="sos")
    h = sosfiltfilt(sos, yu)
    n = max(1, int(round(window * rate)))
    use = np.ones(tu.size, bool)
    if bad is not None and bad[keep].any():
        tb = t[bad[keep]]
        near = np.abs(tu[:, None] - tb[None, :]).min(axis=1) if tb.size < 2000 else \
            np.abs(tu - np.interp(tu, tb, tb, left=tb[0], right=tb[-1]))
        use = near > window
    hm = np.where(use, h, 0.0)
    if not use.any():
        return math.nan, math.nan, math.nan
    p2 = np.convolve(hm * hm, np.ones(n) / n, mode="valid") if h.size >= n else np.array([np.mean(hm * hm)])
    k = int(np.argmax(p2))
    return float(np.sqrt(np.sum(hm * hm) / use.sum())), float(np.sqrt(p2[k])), float(tu[k] - t[0])


def loop_metrics(master: dict, slave: dict, force_scale: float, experiments: dict[int, str]) -> dict:
    """Chatter and transparency per experiment (module docstring).

    Parameters
    ----------
    master : columns of ``master.csv`` (``time``, ``x_in``, ``force``, ``cmd_seq``, ``state``; ``force_cmd``
        optional), ndarrays (n_m,).
    slave : columns of ``slave.csv`` (``t_node``, ``T_out``, ``marker``, ``cmd_seq``; ``T_out_hat``
        optional), ndarrays (n_s,).
    force_scale : master.mapping.force_scale [-].
    experiments : marker -> experiment name.

    Returns
    -------
    dict: name -> {"chatter": {"x_in_cmd_rms_m", "x_in_cmd_worst_m", "force_rms_N", "force_worst_N",
    "worst_window_s"}, "transparency": {"force_error_rms_fs", "force_error_max_fs", "full_scale_N"[,
    "shares_rms_fs": {"estimate", "loop", "passivity"}]}}, the shares (module docstring) when both
    optional columns are given.

    Raises
    ------
    DataError
        A needed column is missing.
    """
    for side, cols, data in (("master", ("time", "x_in", "force", "cmd_seq", "state"), master),
                             ("slave", ("t_node", "T_out", "marker", "cmd_seq"), slave)):
        missing = [c for c in cols if c not in data]
        if missing:
            raise DataError(f"loop metrics: {side}.csv lacks column(s) {', '.join(missing)}")
    out: dict = {}
    order = np.argsort(slave["t_node"], kind="stable")
    ts, Ts = slave["t_node"][order], slave["T_out"][order]
    for m, name in experiments.items():
        seqs = slave["cmd_seq"][slave["marker"].astype(int) == m]
        if seqs.size == 0:
            continue
        sel = (master["cmd_seq"] >= seqs.min()) & (master["cmd_seq"] <= seqs.max())
        if sel.sum() < 10:
            continue
        t, x, f = master["time"][sel], master["x_in"][sel], master["force"][sel]
        # a safe event (watchdog: force cut at once, ramp on re-engage) is not the loop's oscillation
        off = master["state"][sel].astype(int) != ENGAGED
        xr, xw, tw = chatter(t, x, exclude=off)
        fr, fw, tf = chatter(t, f, exclude=off)
        ideal = -force_scale * np.interp(t, ts, Ts)
        fs = float(np.ptp(ideal))
        e = f - ideal
        transparency: dict[str, Any] = {
            "force_error_rms_fs": _rms_fs(e, fs),
            "force_error_max_fs": float(np.max(np.abs(e)) / fs) if fs > 0 else math.nan, "full_scale_N": fs}
        if "force_cmd" in master and "T_out_hat" in slave:
            hat = -force_scale * np.interp(t, ts, slave["T_out_hat"][order])
            fc = master["force_cmd"][sel]
            transparency["shares_rms_fs"] = {"estimate": _rms_fs(hat - ideal, fs), "loop": _rms_fs(fc - hat, fs),
                                             "passivity": _rms_fs(f - fc, fs)}
        out[name] = {
            "chatter": {"x_in_cmd_rms_m": xr, "x_in_cmd_worst_m": xw, "force_rms_N": fr, "force_worst_N": fw,
                        "worst_window_s": tw if xw / CHATTER_LIMITS["x_in_cmd_m"] >= fw / CHATTER_LIMITS["force_N"]
                        else tf},
            "not_engaged_s": float(np.sum(np.diff(t, prepend=t[0])[off])),
            "transparency": transparency,
        }
    return out


def _rms_fs(e: np.ndarray, fs: float) -> float:
    """RMS of ``e`` [N] over the full scale ``fs`` [N] (NaN when ``fs`` is not positive)."""
    return float(np.sqrt(np.mean(e * e)) / fs) if fs > 0 else math.nan


def read_columns(path) -> dict[str, np.ndarray]:
    """Every column of a recording CSV (``#`` comment lines, one header line) as float arrays.

    Raises
    ------
    DataError
        The file is missing, has no header or a malformed row.
    """
    try:
        with open(path, encoding="utf-8") as fh:
            lines = [ln for ln in fh if not ln.startswith("#") and ln.strip()]
    except OSError as e:
        raise DataError(f"{path}: cannot read ({e})") from e
    if len(lines) < 2:
        raise DataError(f"{path}: no header and data rows")
    names = lines[0].strip().split(",")
    try:
        a = np.loadtxt(lines[1:], delimiter=",", ndmin=2)
    except ValueError as e:
        raise DataError(f"{path}: malformed row ({e})") from e
    return {n: a[:, i] for i, n in enumerate(names)}


def run_loop_metrics(run_dir, force_scale: float, experiments: dict[int, str]) -> dict:
    """:func:`loop_metrics` of ``run_dir/master.csv`` and ``run_dir/slave.csv``."""
    from pathlib import Path
    d = Path(run_dir)
    return loop_metrics(read_columns(d / "master.csv"), read_columns(d / "slave.csv"), force_scale, experiments)


def chatter_checks(metrics: dict) -> dict[str, bool]:
    """Per experiment: worst-window chatter of x_in_cmd and of the force below :data:`CHATTER_LIMITS`."""
    lim = CHATTER_LIMITS
    return {f"{name}: no chatter (worst 100 ms above 30 Hz: x_in_cmd < {1e6 * lim['x_in_cmd_m']:g} um, "
            f"force < {lim['force_N']:g} N)": bool(r["chatter"]["x_in_cmd_worst_m"] < lim["x_in_cmd_m"]
                                                   and r["chatter"]["force_worst_N"] < lim["force_N"])
            for name, r in metrics.items()}


def transparency_checks(metrics: dict, limit: float = TRANSPARENCY_LIMIT_FS) -> dict[str, bool]:
    """Per experiment: the transparency RMS error below ``limit`` [-, of full scale] (NaN fails)."""
    return {f"{name}: transparency rms < {limit:g} FS": bool(r["transparency"]["force_error_rms_fs"] < limit)
            for name, r in metrics.items()}


def loop_metric_lines(metrics: dict) -> list[str]:
    """Printed lines: chatter and transparency per experiment."""
    out = [f"{'haptic loop':22s} {'chatter >30 Hz, worst 100 ms':34s} transparency (rendered vs scaled true T_out; "
           "RMS shares)"]
    for name, r in metrics.items():
        c, tr = r["chatter"], r["transparency"]
        sh = tr.get("shares_rms_fs")
        why = "" if sh is None else (f"  (estimate {sh['estimate']:.3f}, loop {sh['loop']:.3f}, "
                                     f"passivity {sh['passivity']:.3f})")
        out.append(f"{name:22s} x_in_cmd {1e6 * c['x_in_cmd_worst_m']:6.2f} um, force {c['force_worst_N']:5.3f} N  "
                   f"rms {tr['force_error_rms_fs']:.3f} FS, max {tr['force_error_max_fs']:.3f} FS{why}")
    return out
