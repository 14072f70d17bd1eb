"""The centre map on the MRD runs (``teleop analyze --mrd``): the load level read from the spindle's band.

Finding 4: what changes from run to run and the pair model's shared set misses is the load level; the
scored run's own band centre (spindle torque only) reads it (:mod:`estimator.online.spindle_centre`).
Two uses, each recording what was fitted on what:

* :func:`centre_folder` - the map fitted on all runs (in-sample) and refitted without each run
  (leave-one-run-out);
* :func:`centre_one_run` - the map fitted on calibration run(s) of one load level, where its load gain
  is not identifiable: held at 1 / n_k (the calibration run's encoders, the pulley ratio; a capstan pair
  with matched sensors gives 1 / (n_k cosh K) <= 1 / n_k), with the calibration's own fit cost profiled
  over the gain (:func:`estimator.offline.spindle_centre_fit.scale_profile`).
"""
from __future__ import annotations

from typing import Any, Callable

import numpy as np

from estimator.offline.spindle_centre_fit import fit_centre_map, run_centre, scale_profile
from estimator.offline.spindle_shared import RunData, kinematic_ratio
from estimator.online.spindle_centre import CentreParams, predict_centre_map

__all__ = ["centre_folder", "centre_one_run", "mid_centre_run", "score_centre", "profile_on_scored", "PROFILE_GAINS", "LOAD_SPREAD_NM"]

#: Load gains [-] of the calibration's cost profile.
PROFILE_GAINS = tuple(float(v) for v in np.round(np.arange(0.6, 1.41, 0.1), 2))
#: Band-centre spread [N m] of the calibration runs above which they count as several load levels.
LOAD_SPREAD_NM = 0.005


def _score(p: CentreParams, r: RunData, k0: int, fs: float) -> dict:
    pt = predict_centre_map(p, r.tau_p, r.theta_p, r.dt)
    e = pt[k0:] - r.tau_d[k0:]
    return {"torque_rmse_fs": float(np.sqrt(np.mean(e ** 2)) / fs), "torque_max_fs": float(np.max(np.abs(e)) / fs)}


def _agg(rows: list[dict]) -> dict:
    t = [r["torque_rmse_fs"] for r in rows]
    return {"median_torque_rmse_fs": float(np.median(t)), "max_torque_rmse_fs": float(np.max(t)),
            "max_torque_max_fs": float(max(r["torque_max_fs"] for r in rows))}


def mid_centre_run(runs: list[RunData]) -> str:
    """The run whose band centre (spindle torque only) lies nearest the middle of the runs' centres: the
    calibration run with the shortest worst-case extrapolation in load (a rule fixed before scoring)."""
    th = np.concatenate([r.theta_p[r.k0:] for r in runs])
    lo, hi = np.percentile(th, [20.0, 80.0])
    c = {r.name: run_centre(r, (float(lo), float(hi))) for r in runs}
    mid = 0.5 * (min(c.values()) + max(c.values()))
    return min(runs, key=lambda r: (abs(c[r.name] - mid), r.name)).name


def centre_folder(runs: list[RunData], fs: float, tick: Callable[[str], None], loro: bool = True) -> dict:
    """In-sample and leave-one-run-out scores of the centre map over a folder (JSON-ready)."""
    p, rms = fit_centre_map(runs, step=10)
    out: dict[str, Any] = {"fitted_on": "jaw torque of every run (in-sample); the scored run's centre from its "
                                        "spindle torque", "parameters": p.as_dict(), "fit_rms_Nm": rms,
                           "runs": {r.name: _score(p, r, r.k0, fs) for r in runs}}
    out["summary"] = _agg(list(out["runs"].values()))
    tick("centre map")
    if loro:
        lo = {}
        for r in runs:
            q, _ = fit_centre_map([s for s in runs if s is not r], step=20)
            lo[r.name] = {**_score(q, r, r.k0, fs), "load_gain": float(q.coef[1, 0]), "theta_z": q.theta_z}
            tick(f"centre without {r.name}")
        out["loro"] = {"fitted_on": "the other runs' jaw torque; the scored run's spindle signals only", "runs": lo,
                       "summary": _agg(list(lo.values()))}
    return out


def centre_one_run(cal: list[RunData], fs: float) -> tuple[CentreParams, dict]:
    """The centre map calibrated on ``cal``: load gain fitted when the runs' band centres spread over more
    than LOAD_SPREAD_NM, else held at 1 / n_k of their encoders, with the cost profile over PROFILE_GAINS.
    Returns the parameters and a JSON-ready record of what was fitted on what."""
    th = np.concatenate([r.theta_p[r.k0:] for r in cal])
    lo, hi = np.percentile(th, [20.0, 80.0])
    cents = [run_centre(r, (float(lo), float(hi))) for r in cal]
    rec: dict[str, Any] = {"inputs": ["spindle torque", "spindle encoder"], "targets": ["jaw torque"],
                           "band_centres_Nm": cents}
    if len(cal) > 1 and float(np.ptp(cents)) > LOAD_SPREAD_NM:
        p, rms = fit_centre_map(cal)
        rec["load_gain"] = {"value": float(p.coef[1, 0]), "from": "fitted across the calibration runs' loads"}
    else:
        n_k = kinematic_ratio(cal)
        p, rms = fit_centre_map(cal, scale=1.0 / n_k)
        rec["load_gain"] = {"value": 1.0 / n_k, "n_k": n_k, "from": "1 / n_k of the calibration run's encoders "
                            "(one load level: the gain is not identifiable, see profile)"}
        rec["profile"] = [{"load_gain": s, "fit_rms_fs": r / fs} for s, _, r in scale_profile(cal, np.array(PROFILE_GAINS))]
    rec["fit_rms_fs"] = rms / fs
    rec["parameters"] = p.as_dict()
    return p, rec


def profile_on_scored(cal: list[RunData], scored: list[tuple[RunData, int]], fs: float, rec: dict) -> None:
    """Diagnostic beside the calibration's cost profile (``rec["profile"]``, from :func:`centre_one_run`):
    the scored runs' median and worst torque RMSE [FS] at each load gain. It reads the scored runs' jaw
    torque and is never used for a choice: it shows what the flat calibration cost leaves open."""
    for row in rec.get("profile", []):
        p, _ = fit_centre_map(cal, scale=row["load_gain"])
        e = [_score(p, r, k0, fs)["torque_rmse_fs"] for r, k0 in scored]
        row["scored_median_rmse_fs"], row["scored_worst_rmse_fs"] = float(np.median(e)), float(np.max(e))


def score_centre(p: CentreParams, r: RunData, k0: int, fs: float) -> dict:
    """Torque RMSE and max |error| [FS] of the centre map on one run from sample ``k0``."""
    return _score(p, r, k0, fs)
