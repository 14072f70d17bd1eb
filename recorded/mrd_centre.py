"""The centre map on the MRD runs (``teleop analyze --mrd``): the load level read from the spindle's band.

On the MRD runs (docs/results/mrd.md) what changes from run to run and the pair model's shared set misses is the load
level; the scored run's own band centre (spindle torque only) reads it (:mod:`estimator.online.spindle_centre`). Two
uses, each recording what was fitted on what:

* :func:`centre_folder` - the map fitted on all runs (in-sample) and refitted without each run
  (leave-one-run-out);
* :func:`centre_one_run` - the map fitted on calibration run(s) of one load level, where its load gain
  is not identifiable: held at 1 / n_k (the calibration run's encoders, the pulley ratio; a capstan pair
  with matched sensors gives 1 / (n_k cosh K) <= 1 / n_k), with the calibration's own fit cost profiled
  over the gain (:func:`estimator.offline.spindle.centre_fit.scale_profile`);
* :func:`centre_time_split` - its calibration-only score (first half fits, second half scores) for the
  headline's model choice in :mod:`study.mrd.report`; :func:`model_choice` admits only candidates whose
  :func:`implied_load_gain` the calibration runs' own reading allows (LOAD_RULE).

Predictions hold the shape along the stroke outside the calibration's angles
(:func:`estimator.offline.spindle.centre_fit.predict_held`).

Every score starts once the run's band-centre reading holds both edges
(:func:`estimator.online.spindle_centre.centre_ready`); ``from_k0`` keeps the score from the first reversal.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from estimator.offline.spindle.centre_fit import (
    fit_centre_map,
    held_parts,
    predict_held,
    run_centre,
    scale_profile,
    within_run_gain,
)
from estimator.offline.spindle.shared import RunData, kinematic_ratio
from estimator.online.spindle_centre import CentreParams, centre_ready

__all__ = ["CENTRE", "model_choice", "implied_load_gain", "LOAD_RULE", "LOAD_FALLBACK", "gain_identifiability",
           "centre_agg", "centre_folder", "centre_implied_gain", "centre_one_run", "centre_time_split",
           "folder_load_gain", "mid_centre_run", "score_centre",
           "profile_on_scored", "PROFILE_GAINS", "LOAD_SPREAD_NM"]

#: The centre map's name among the headline's candidates (``model_choice``).
CENTRE = "centre map"
#: Load gains [-] of the calibration's cost profile.
PROFILE_GAINS = tuple(float(v) for v in np.round(np.arange(0.6, 1.41, 0.1), 2))
#: Band-centre spread [N m] of the calibration runs above which they count as several load levels.
LOAD_SPREAD_NM = 0.005
#: Uniform spindle-torque shift [N m] of :func:`implied_load_gain`.
SHIFT_NM = 0.002
#: When no candidate is eligible: the nearest to the calibration run's own reading, not the best time split (on the
#: source repository's other folders the best split picks a pair model whose implied load gain is 0.07-0.27, four or
#: more times below that reading, with headline medians of 0.28-0.40 FS on 14 of 39 stroke windows;
#: docs/results/mrd.md).
LOAD_FALLBACK = ("no candidate eligible: the one whose load slope 1 / g lies nearest the calibration runs' own "
                 "interval (|log| of the ratio to its nearer end), the time split breaking a tie")
#: The headline's eligibility rule (:func:`model_choice`; it reads calibration data only).
LOAD_RULE = ("the time split cannot test the load gain (at one load level not at all), so a candidate is eligible "
             "only if its load slope 1 / g (g: jaw torque change per N m of uniform spindle-torque shift, on the "
             "calibration inputs) lies inside the interval of the calibration runs' own reading of it "
             "(within_run_gain pooled over the calibration runs: spindle torque on jaw torque after the shape along "
             "the stroke per direction; slope +- the wider of its 95 % profile half-width and 1.96 jackknife SE); "
             "among the eligible the lower time-split RMSE, all candidates when none is eligible")


def _score(p: CentreParams, r: RunData, k0: int, fs: float) -> dict:
    """Scored from max(k0, the instant the centre reading has both band edges: centre_ready); the same
    figures from k0 under ``from_k0`` (the one-edge initialisation included)."""
    pt = predict_held(p, r.tau_p, r.theta_p, r.dt)
    k = max(k0, centre_ready(r.theta_p, r.dt, p.window))
    e, e0 = pt[k:] - r.tau_d[k:], pt[k0:] - r.tau_d[k0:]
    return {"torque_rmse_fs": float(np.sqrt(np.mean(e ** 2)) / fs), "torque_max_fs": float(np.max(np.abs(e)) / fs),
            "scored_from_s": k * r.dt, "from_k0": {"torque_rmse_fs": float(np.sqrt(np.mean(e0 ** 2)) / fs),
                                                   "torque_max_fs": float(np.max(np.abs(e0)) / fs)}}


def centre_agg(rows: list[dict]) -> dict:
    """Median and worst torque RMSE and the largest |error| [FS] of per-run centre-map scores (and the same
    from k0 when every row has it)."""
    t = [r["torque_rmse_fs"] for r in rows]
    out: dict[str, Any] = {"median_torque_rmse_fs": float(np.median(t)), "max_torque_rmse_fs": float(np.max(t)),
                           "max_torque_max_fs": float(max(r["torque_max_fs"] for r in rows))}
    if all("from_k0" in r for r in rows):
        out["from_k0"] = centre_agg([r["from_k0"] for r in rows])
    return out


def mid_centre_run(runs: list[RunData]) -> str:
    """The run whose band centre (spindle torque only) lies nearest the middle of the runs' centres: the
    calibration run with the shortest worst-case extrapolation in load (a rule fixed before scoring)."""
    th = np.concatenate([r.theta_p[r.k0:] for r in runs])
    lo, hi = np.percentile(th, [20.0, 80.0])
    c = {r.name: run_centre(r, (float(lo), float(hi))) for r in runs}
    mid = 0.5 * (min(c.values()) + max(c.values()))
    return min(runs, key=lambda r: (abs(c[r.name] - mid), r.name)).name


def gain_identifiability(runs: list[RunData], folder_gain: float | None = None) -> dict:
    """Diagnostic, never used by an estimate: each run's load gain from its own signals alone
    (:func:`estimator.offline.spindle.centre_fit.within_run_gain`, the centre map's shape taken out) with its
    95 % profile interval, and each run's encoder ratio n_k (:func:`kinematic_ratio`). Reads every run's jaw
    torque. ``folder_gain``: the load gain fitted across all runs' loads, recorded beside for comparison.
    On the MRD folder the per-run gains scatter far beyond the +-4 % a one-run calibration needs
    (docs/results/mrd.md)."""
    rows = {r.name: {**within_run_gain(r), "n_k": kinematic_ratio([r]),
                     "n_k_stretch": kinematic_ratio([r], stretch=True),
                     "jaw_mean_Nm": float(np.mean(r.tau_d[r.k0:]))} for r in runs}
    g = np.array([v["gain"] for v in rows.values()])
    nk = np.array([v["n_k"] for v in rows.values()])
    ns = np.array([v["n_k_stretch"] for v in rows.values()])
    jm = np.array([v["jaw_mean_Nm"] for v in rows.values()])
    out: dict[str, Any] = {
        "what": "load gain 1 / s from each run alone: its spindle torque on its own jaw torque after the centre "
                "map's shape (degree-4 polynomial of the spindle angle per direction) is taken out; n_k: jaw / "
                "spindle angle in full motion (n_k_stretch: with a cable-stretch term in the spindle torque)",
        "runs": rows,
        "summary": {"gain_median": float(np.median(g)), "gain_min": float(g.min()), "gain_max": float(g.max()),
                    "n_k_mean": float(nk.mean()), "n_k_sd": float(nk.std()),
                    "n_k_stretch_min": float(ns.min()), "n_k_stretch_max": float(ns.max())}}
    if np.ptp(jm) > 0:                               # the encoders' ratio extrapolated to zero jaw torque
        out["summary"]["n_k_at_zero_load"] = float(np.polyfit(jm, nk, 1)[1])
        out["summary"]["n_k_stretch_at_zero_load"] = float(np.polyfit(jm, ns, 1)[1])
    if folder_gain is not None:
        out["summary"]["folder_gain"] = folder_gain
        out["summary"]["runs_within_4pc_of_folder_gain"] = int(np.sum(np.abs(g / folder_gain - 1.0) <= 0.04))
    return out


def centre_folder(runs: list[RunData], fs: float, tick: Callable[[str], None], loro: bool = True) -> dict:
    """In-sample and leave-one-run-out scores of the centre map over a folder (JSON-ready)."""
    p, rms = fit_centre_map(runs, step=10)
    out: dict[str, Any] = {"fitted_on": "jaw torque of every run (in-sample); the scored run's centre from its "
                                        "spindle torque", "parameters": p.as_dict(), "fit_rms_Nm": rms,
                           "runs": {r.name: _score(p, r, r.k0, fs) for r in runs}}
    out["summary"] = centre_agg(list(out["runs"].values()))
    out["within_run_gain"] = gain_identifiability(runs, float(p.coef[1, 0]))
    out["load_gain"] = folder_load_gain(p, runs)
    tick("centre map")
    if loro:
        lo = {}
        implied = []
        for r in runs:
            rest = [s for s in runs if s is not r]
            q, _ = fit_centre_map(rest, step=20)
            implied.append(centre_implied_gain(q, rest))
            lo[r.name] = {**_score(q, r, r.k0, fs), "load_gain": float(q.coef[1, 0]), "implied_load_gain": implied[-1],
                          "theta_z": q.theta_z}
            tick(f"centre without {r.name}")
        out["loro"] = {"fitted_on": "the other runs' jaw torque; the scored run's spindle signals only", "runs": lo,
                       "summary": centre_agg(list(lo.values()))}
        if len(runs) > 2 and out["load_gain"]["several_loads"]:
            g, n = np.array(implied), len(runs)
            out["load_gain"]["jackknife_se"] = float(np.sqrt((n - 1) / n * np.sum((g - g.mean()) ** 2)))
            out["load_gain"]["leave_one_run_out_range"] = [float(g.min()), float(g.max())]
    return out


def centre_implied_gain(p: CentreParams, runs: list[RunData]) -> float:
    """:func:`implied_load_gain` [-] of the centre map ``p`` (shape held outside its angles) on ``runs``; the
    spindle-angle blocks of each run (:func:`held_parts`) are computed once for its two shifted torques."""
    if "shape_range" not in p.notes:
        return implied_load_gain(lambda c, u: predict_held(p, c.tau_p + u, c.theta_p, c.dt), runs)
    parts = {id(r): held_parts(p, r.theta_p, r.dt) for r in runs}
    return implied_load_gain(lambda c, u: predict_held(p, c.tau_p + u, c.theta_p, c.dt, parts[id(c)]), runs)


def folder_load_gain(p: CentreParams, runs: list[RunData]) -> dict:
    """The folder's load gain as a one-run calibration uses it (JSON-ready): the centre map ``p`` fitted across
    the folder's loads, its jaw-torque change per N m of uniform spindle-band shift averaged over the stroke
    of every run (:func:`implied_load_gain`; 0.943 on the shipped folder, docs/results/mrd.md), beside its value
    b_0 at the reference angle. The number ``--calibration gain=G:RUN`` (or ``gain=THIS.json:RUN``) carries to
    another folder - another tool of the same model - whose single calibration run cannot give it. Reads every
    run's jaw torque (a folder diagnosis). ``several_loads`` False: the folder has one load level, where the gain is
    not identifiable (the value is then not a measurement of it)."""
    several = _several_loads(runs)
    return {"value": centre_implied_gain(p, runs), "b_0": float(p.coef[1, 0]), "several_loads": several,
            "what": "jaw torque change per N m of uniform spindle-band shift, stroke-averaged over every run, of the "
                    "centre map fitted across the folder's loads (about 1 / (r cosh K))",
            "use": "--calibration gain=G:RUN (or gain=<this JSON>:RUN) on another tool of the same model"}


def _centres(cal: list[RunData]) -> list[float]:
    """Band centre [N m] of each calibration run over the runs' common 20-80 % angle window (spindle only)."""
    th = np.concatenate([r.theta_p[r.k0:] for r in cal])
    lo, hi = np.percentile(th, [20.0, 80.0])
    return [run_centre(r, (float(lo), float(hi))) for r in cal]


def _several_loads(cal: list[RunData], cents: list[float] | None = None) -> bool:
    """True when the calibration runs' band centres spread over more than LOAD_SPREAD_NM (several load levels)."""
    return len(cal) > 1 and float(np.ptp(_centres(cal) if cents is None else cents)) > LOAD_SPREAD_NM


def _fit_rule(cal: list[RunData], cents: list[float], given: float | None = None) -> tuple[CentreParams, float]:
    """The calibration rule: a ``given`` load gain (a design value) when there is one; else fitted when the band
    centres spread over LOAD_SPREAD_NM, else 1 / n_k."""
    if given is not None:
        return fit_centre_map(cal, scale=given)
    if _several_loads(cal, cents):
        return fit_centre_map(cal)
    return fit_centre_map(cal, scale=1.0 / kinematic_ratio(cal))


def centre_time_split(cal: list[RunData], fs: float, given: float | None = None) -> float:
    """Torque RMSE [FS] of the centre map on a time split of the calibration data only: fitted (by the rule
    of :func:`centre_one_run`) on each calibration run's first half of its scored part (k0 to the middle,
    the split of the pair model's extension selection), scored on the second half. Jaw torque of the
    calibration runs only; no scored run is read. ``given``: a design load gain (:func:`centre_one_run`)."""
    first = [RunData(r.name, r.tau_p[:m], r.theta_p[:m], r.tau_d[:m], r.theta_d[:m], r.k0, r.dt)
             for r in cal for m in [(r.k0 + r.tau_p.size) // 2]]
    p, _ = _fit_rule(first, _centres(first), given)
    sq, n = 0.0, 0
    for r in cal:
        m = max((r.k0 + r.tau_p.size) // 2, centre_ready(r.theta_p, r.dt, p.window))
        e = predict_held(p, r.tau_p, r.theta_p, r.dt)[m:] - r.tau_d[m:]
        sq, n = sq + float(e @ e), n + e.size
    return float(np.sqrt(sq / max(n, 1)) / fs)


def implied_load_gain(predict: Callable[[RunData, float], np.ndarray], cal: list[RunData],
                      delta: float = SHIFT_NM) -> float:
    """A candidate's load gain [-]: the change of its predicted jaw torque per N m of a uniform shift of the
    spindle torque (``predict(run, shift)`` [N m]), from each calibration run's k0 on, averaged over the runs
    (central difference over +-``delta`` [N m]). A load change moves the whole band by the same amount; this
    is how far the candidate carries it to the jaw. Calibration runs' spindle signals only."""
    g = [float(np.mean(predict(r, delta)[r.k0:] - predict(r, -delta)[r.k0:])) / (2.0 * delta) for r in cal]
    return float(np.mean(g))


def _load_check(cal: list[RunData], gains: dict[str, float]) -> dict:
    """Which candidates' load gains agree with the calibration runs' own reading of it (LOAD_RULE)."""
    w = within_run_gain(cal)
    half = max(0.5 * (w["profile_ci95"][1] - w["profile_ci95"][0]), 1.96 * (w["jackknife_se"] or 0.0))
    lo, hi = w["slope"] - half, w["slope"] + half
    ok = {n: bool(g != 0.0 and lo <= 1.0 / g <= hi) for n, g in gains.items()}
    return {"rule": LOAD_RULE, "implied_load_gain": gains, "slope": w["slope"], "slope_interval": [lo, hi],
            "profile_ci95": w["profile_ci95"], "jackknife_se": w["jackknife_se"], "eligible": ok}


def model_choice(pair: str, pair_split_fs: float, pair_in_fs: float, cal: list[RunData], fs: float,
                 centre_in_fs: float, gains: dict[str, float] | None = None, given: float | None = None) -> dict:
    """Which estimate the headline keys report, chosen on calibration data only (a rule fixed before scoring):
    the lower torque RMSE [FS] on the calibration runs' time split. ``pair_split_fs``: the pair model's
    extension selection's validation RMSE on that split (the split also chose its extensions: optimistic for
    the pair model); the centre map's from :func:`centre_time_split`. The in-sample fit RMSEs ``pair_in_fs``
    and ``centre_in_fs`` [FS] are recorded beside it, never used.

    ``gains`` (candidate -> :func:`implied_load_gain`): the time split cannot test the load gain (not at all at
    one load level), so only candidates whose load slope 1 / gain lies inside the interval of the calibration
    runs' own reading (:func:`within_run_gain`, pooled over the runs) are eligible (LOAD_RULE); when
    none is, the one whose slope lies nearest that interval (LOAD_FALLBACK). ``given``: the centre map's design
    load gain, if any (:func:`centre_one_run`). Returns a JSON-ready dict."""
    cands = {pair: pair_split_fs, CENTRE: centre_time_split(cal, fs, given)}
    out: dict[str, Any] = {
        "rule": "lower jaw torque RMSE [FS] on the calibration runs' time split: fitted on the first half of "
                "each calibration run's scored part, scored on the second half (calibration data only)",
        "candidates": cands, "angle": "the pair model's (the centre map estimates torque only)",
        "in_sample_not_used": {pair: pair_in_fs, CENTRE: centre_in_fs, "note": "fit RMSE [FS] on all the "
                               "calibration data; recorded beside the rule, never used by it"}}
    eligible = list(cands)
    if gains is not None:
        lc = out["load_gain_check"] = _load_check(cal, {n: gains[n] for n in cands})
        eligible = [n for n in cands if lc["eligible"][n]]
        if not eligible:            # the nearest to the reading, not the best split (LOAD_FALLBACK)
            lo, hi = lc["slope_interval"]
            far = {n: _log_distance(1.0 / gains[n] if gains[n] > 0 else math.inf, lo, hi) for n in cands}
            # JSON has no infinity: None where no finite distance exists (a non-positive slope or interval end)
            lc["log_distance"] = {n: d if math.isfinite(d) else None for n, d in far.items()}
            lc["fallback"] = LOAD_FALLBACK
            eligible = [min(cands, key=lambda n: (far[n], cands[n], n))]
    out["chosen"] = min(eligible, key=lambda n: (cands[n], n))
    return out


def _log_distance(slope: float, lo: float, hi: float) -> float:
    """How far ``slope`` lies outside [lo, hi], as |log| of the ratio to the nearer end (0 inside; inf for a
    non-positive slope or interval end)."""
    if lo <= slope <= hi:
        return 0.0
    end = lo if slope < lo else hi
    if not (slope > 0.0 and end > 0.0 and math.isfinite(slope)):
        return math.inf
    return abs(math.log(slope / end))


def centre_one_run(cal: list[RunData], fs: float, given: float | None = None) -> tuple[CentreParams, dict]:
    """The centre map calibrated on ``cal``: load gain fitted when the runs' band centres spread over more
    than LOAD_SPREAD_NM, else held at 1 / n_k of their encoders, with the cost profile over PROFILE_GAINS;
    ``given`` [-]: a design value of the load gain (jaw torque per N m of band-centre shift, about
    1 / (r cosh K); ``--calibration gain=G:RUN``) used instead (the shape's load terms b_k, e_k are then 0).
    Returns the parameters and a JSON-ready record of what was fitted on what."""
    cents = _centres(cal)
    rec: dict[str, Any] = {"inputs": ["spindle torque", "spindle encoder"], "targets": ["jaw torque"],
                           "band_centres_Nm": cents}
    p, rms = _fit_rule(cal, cents, given)
    several = _several_loads(cal, cents)
    if given is not None:
        rec["load_gain"] = {"value": float(given), "from": "given (--calibration gain=G:...): a design value from "
                            "outside the data, not fitted"}
    elif several:
        rec["load_gain"] = {"value": float(p.coef[1, 0]), "from": "fitted across the calibration runs' loads"}
    else:
        n_k = 1.0 / float(p.coef[1, 0])
        rec["load_gain"] = {"value": 1.0 / n_k, "n_k": n_k, "from": "1 / n_k of the calibration run's encoders "
                            "(one load level: the gain is not identifiable, see profile)"}
    if not several:     # one load level: the calibration's fit cost over the gain, however the gain was set
        rec["profile"] = [{"load_gain": s, "fit_rms_fs": r / fs}
                          for s, _, r in scale_profile(cal, np.array(PROFILE_GAINS))]
    if given is None and not several:
        rec["within_run_gain"] = {**within_run_gain(cal[0]), "used": False,
                                  "note": "the gain from the calibration run's own signals (spindle torque on its "
                                          "jaw torque, shape taken out), with its 95 % profile interval: not used"}
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
