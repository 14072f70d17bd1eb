"""Fit once, predict new tube shapes: choice of the shared structure, uncertainty, export and prediction.

The shared models of :mod:`estimator.offline.pair.shared` hold one parameter set for every configuration
with K_j = K0_j + mu N (N the configuration's bend angle [rad]). This module adds what is needed to
use that set on configurations it has never seen:

* :func:`choose_shared` - the structure is chosen on the training cycles only, by
  leave-one-configuration-out: for each candidate (:data:`estimator.offline.pair.shared.CHOICE`, in order)
  refit on the training cycles of all configurations but one and score the training cycle of the
  left-out one; forward choice with the project's price per parameter (S = (rms / rms_chosen)^2,
  accepted when S + PENALTY * extra parameters < 1).
* :func:`bootstrap` - uncertainty by a bootstrap over cycles: the (configuration, cycle) blocks are
  drawn with replacement, the model refitted (warm start) on each draw; standard deviation, 2.5-97.5 %
  interval and the correlation matrix of the parameters. :func:`local_correlation` gives the
  Gauss-Newton correlation (J^T J)^-1 at the optimum beside it.
* :func:`export_params` / :func:`predict_shared` - the set as JSON (``shared.params``) and the
  prediction of a new recording from its command, its measured pretension (first sample) and its
  bend alone, nothing refitted.
"""
from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from estimator.offline.diagnosis.thresholds import PENALTY
from estimator.offline.pair.diagnosis_fit import spread_deg
from estimator.offline.pair.shared import (
    CHOICE,
    COMPARED,
    LEAVE_ONE_OUT,
    SHARED_MODELS,
    SharedModel,
    config_values,
    fit_shared,
    leave_one_out,
    predict_config,
    score,
    shared_params,
)

__all__ = ["choose_shared", "bootstrap", "loco_bootstrap", "local_correlation", "export_params", "predict_shared",
           "shared_analysis", "CV_NFEV"]

#: Most residual evaluations of a leave-one-out or bootstrap refit (warm-started from the full fit).
CV_NFEV = 40


def _rmse_deg(err: np.ndarray) -> float:
    return math.degrees(float(np.sqrt(np.mean(np.square(err)))))


def choose_shared(recs: list, bends: list[float], train: list, candidates: tuple[str, ...],
                  fitted: dict[str, dict], progress: Callable[[str], None] | None = None) -> dict:
    """Forward choice of the shared structure by leave-one-configuration-out on the training cycles.

    Parameters
    ----------
    recs, bends : recordings and bend angles N [rad]
    train : per recording, the training samples (slice); nothing else is used
    candidates : model names of :data:`estimator.offline.pair.shared.SHARED_MODELS`, in forward order
    fitted : name -> values of each candidate fitted on ``train`` of all recordings (warm starts)

    Returns
    -------
    dict: ``chosen`` (name), ``candidates`` {name: {loco_train_rmse_deg [per configuration],
    rms_deg, n_params, score, price, accepted}}, ``rule``.

    Raises
    ------
    ValueError
        Fewer than 3 recordings.
    """
    if len(recs) < 3:
        raise ValueError("leave-one-configuration-out needs at least 3 configurations")
    tick = progress or (lambda label: None)
    rows: dict[str, dict] = {}
    for name in candidates:
        m = SHARED_MODELS[name]
        per = []
        for i in range(len(recs)):
            keep = [j for j in range(len(recs)) if j != i]
            v = fit_shared(m, [recs[j] for j in keep], [bends[j] for j in keep], [train[j] for j in keep],
                           starts=[fitted[name]], max_nfev=CV_NFEV)
            err = predict_config(m, v, recs[i], bends[i])[train[i]] - np.asarray(recs[i].angle, dtype=float)[train[i]]
            per.append(_rmse_deg(err))
        tick(f"choice {name}")
        rows[name] = {"loco_train_rmse_deg": per, "rms_deg": float(np.sqrt(np.mean(np.square(per)))),
                      "n_params": len(shared_params(m, len(recs))), "accepted": False}
    chosen = candidates[0]
    rows[chosen].update(score=1.0, price=None, accepted=True)
    for name in candidates[1:]:
        S = (rows[name]["rms_deg"] / rows[chosen]["rms_deg"]) ** 2
        price = S + PENALTY * (rows[name]["n_params"] - rows[chosen]["n_params"])
        rows[name].update(score=S, price=price)
        if price < 1.0:
            rows[name]["accepted"] = True
            chosen = name
    return {"chosen": chosen, "candidates": rows,
            "rule": f"leave one configuration out, fitted and scored on the training cycles only; a candidate "
                    f"replaces the chosen one when (rms / rms_chosen)^2 + {PENALTY} x (extra parameters) < 1"}


def bootstrap(m: SharedModel, recs: list, bends: list[float], blocks: list[list[slice]], values: dict,
              n_draws: int = 20, seed: int = 0) -> dict:
    """Bootstrap over cycles: draw the (configuration, cycle) blocks with replacement, refit.

    Parameters
    ----------
    m, recs, bends : the shared model, its recordings and bend angles [rad]
    blocks : per recording, its cycles (sample slices) that the fit used
    values : the fit on every block (the warm start and the centre)
    n_draws : bootstrap draws (>= 5)

    Returns
    -------
    dict name -> {value, std, ci95 [lo, hi]} under ``params``, ``correlation`` {names, matrix}
    (of the draws), ``n_draws``, ``method``.

    Raises
    ------
    ValueError
        ``n_draws`` < 5.
    """
    if n_draws < 5:
        raise ValueError(f"n_draws must be >= 5, got {n_draws}")
    rng = np.random.default_rng(seed)
    units = [(i, b) for i, bl in enumerate(blocks) for b in bl]
    names = list(values)
    draws = []
    for _ in range(n_draws):
        pick = [units[k] for k in rng.integers(0, len(units), len(units))]
        idx = [np.concatenate([np.arange(b.start, b.stop) for i2, b in pick if i2 == i] or [np.arange(0)])
               for i in range(len(recs))]
        use = [i for i in range(len(recs)) if idx[i].size]
        v = fit_shared(m, [recs[i] for i in use], [bends[i] for i in use], [idx[i] for i in use],
                       starts=[values], max_nfev=CV_NFEV)
        draws.append([v[n] for n in names])
    d = np.asarray(draws)
    corr = np.corrcoef(d, rowvar=False) if d.shape[0] > 1 else np.eye(len(names))
    corr = np.where(np.isfinite(corr), corr, 0.0)
    return {"params": {n: {"value": float(values[n]), "std": float(np.std(d[:, j], ddof=1)),
                           "ci95": [float(np.percentile(d[:, j], 2.5)), float(np.percentile(d[:, j], 97.5))]}
                       for j, n in enumerate(names)},
            "correlation": {"names": names, "matrix": np.round(corr, 3).tolist()}, "n_draws": n_draws,
            "method": "bootstrap over cycles: (configuration, cycle) blocks drawn with replacement, refitted"}


def loco_bootstrap(m: SharedModel, recs: list, bends: list[float], blocks: list[list[slice]], test: list[slice],
                   rows: list[dict], n_draws: int = 20, seed: int = 0) -> list[dict]:
    """Uncertainty of each leave-one-configuration-out figure, by a bootstrap over cycles.

    For each left-out configuration i the (configuration, cycle) blocks of the *other* configurations
    are drawn with replacement, the shared model refitted on them (warm start: the leave-one-out fit
    ``rows[i]["params"]``, :data:`CV_NFEV` evaluations) and configuration i predicted from its command,
    pretension and bend; its test-block RMSE is recorded. Nothing of configuration i enters a fit.

    Parameters
    ----------
    m, recs, bends : the shared model, recordings and bend angles [rad]
    blocks : per recording, its cycles (sample slices) a leave-one-out fit may use
    test : per recording, the scored samples
    rows : :func:`estimator.offline.pair.shared.leave_one_out` output (``params`` of each refit)
    n_draws : draws per configuration (>= 5)

    Returns
    -------
    list (one per recording) of {std_deg, ci95_deg [2.5, 97.5 %], n_draws, method}.

    Raises
    ------
    ValueError
        ``n_draws`` < 5 or fewer than 2 recordings.
    """
    if n_draws < 5:
        raise ValueError(f"n_draws must be >= 5, got {n_draws}")
    if len(recs) < 2:
        raise ValueError("a leave-one-out bootstrap needs at least 2 configurations")
    rng = np.random.default_rng(seed)
    out = []
    for i, (rec, bend, te) in enumerate(zip(recs, bends, test, strict=False)):
        units = [(j, b) for j, bl in enumerate(blocks) if j != i for b in bl]
        y = np.asarray(rec.angle, dtype=float)[te]
        xs: list[float] = []
        while len(xs) < n_draws:
            pick = [units[k] for k in rng.integers(0, len(units), len(units))]
            use = sorted({j for j, _ in pick})
            if m.per_config and len(use) < 2:
                continue                                  # per-configuration parameters need two configurations
            idx = [np.concatenate([np.arange(b.start, b.stop) for j2, b in pick if j2 == j]) for j in use]
            v = fit_shared(m, [recs[j] for j in use], [bends[j] for j in use], idx, starts=[rows[i]["params"]],
                           max_nfev=CV_NFEV)
            xs.append(_rmse_deg(predict_config(m, v, rec, bend)[te] - y))
        out.append(spread_deg(xs, "bootstrap over the other configurations' cycles, refitted; this configuration "
                                  "predicted, its test block scored"))
    return out


def local_correlation(result, names: list[str]) -> dict:
    """Gauss-Newton correlation of the parameters at a least-squares optimum (``result.jac``):
    cov ~ (J^T J)^-1; {names, matrix}. A local figure (residuals are autocorrelated, so its
    standard errors would be too small; only the correlations are reported)."""
    J = np.asarray(result.jac, dtype=float)
    cov = np.linalg.pinv(J.T @ J)
    sd = np.sqrt(np.clip(np.diag(cov), 1e-300, None))
    corr = np.clip(cov / np.outer(sd, sd), -1.0, 1.0)
    return {"names": list(names), "matrix": np.round(corr, 3).tolist()}


def export_params(m: SharedModel, values: dict, fitted_on: str, uncertainty: dict | None = None) -> dict:
    """The shared set as JSON: ``model`` (name, structure, effects and the laws), ``values`` {name:
    {value, unit[, std, ci95]}}, ``fitted_on``. Read back by :func:`predict_shared`."""
    units = {p.name: p.unit for p in shared_params(m)}
    unc = (uncertainty or {}).get("params", {})
    vals = {k: {"value": float(x), "unit": units[k], **{q: unc[k][q] for q in ("std", "ci95") if k in unc}}
            for k, x in values.items()}
    laws = ["K_j = K0_j + mu * N (N: bend angle [rad])"] + [f"{k} = {x:g} (held: not identifiable)"
                                                           for k, x in m.fixed]
    if m.g_slope:
        laws.append("G = G + G_N * N")
    if m.stiffness_ratio:
        laws.append("lam = G / s" + (" + lam_N * N" if m.lam_slope else ""))
    if m.k_slope:
        laws.append("k = k + k_N * N")
    laws.append("initial tensions: the recording's first sample (pretension); angle offset: its first sample")
    return {"model": {"name": m.name, "structure": m.structure, "effects": list(m.effects), "laws": laws},
            "values": vals, "fitted_on": fitted_on}


def predict_shared(params: dict, rec, bend: float) -> tuple[np.ndarray, dict]:
    """Predict a recording with an exported shared set (:func:`export_params`), nothing refitted.

    Parameters
    ----------
    params : the ``shared.params`` dict
    rec : recording (command [rad], T_a, T_b [N] (first samples used), angle [rad]), shape (n,)
    bend : its bend angle N [rad]

    Returns
    -------
    angle : ndarray (n,) [rad]; values : the kernel values used (K_a, K_b, G, lam, ...)

    Raises
    ------
    ValueError
        Unknown model name or missing parameters in ``params``.
    """
    try:
        name = params["model"]["name"]
        m = SHARED_MODELS[name]
        values = {k: float(v["value"]) for k, v in params["values"].items()}
    except (KeyError, TypeError) as e:
        raise ValueError(f"shared parameter set: missing or unknown entry {e}") from None
    missing = [p.name for p in shared_params(m) if p.name not in values]
    if missing:
        raise ValueError(f"shared parameter set ({name}): missing {', '.join(missing)}")
    return predict_config(m, values, rec, bend), config_values(m, values, rec, bend)


def shared_analysis(recs: list, bends: list[float], train: list[slice], test: list[slice],
                    progress: Callable[[str], None] | None = None, drift: bool = False,
                    n_bootstrap: int = 20, blocks: list[list[slice]] | None = None) -> tuple[dict, dict]:
    """The shared fits, the choice of the shared structure on the training cycles, its
    leave-one-out predictions, its uncertainty, the E6 test and the exported parameter set.

    Parameters
    ----------
    recs, bends : recordings and their bend angles N [rad]
    train, test : per recording, the training and test sample slices (KAIST: cycle 1 and the later
        cycles); the fits and the choice use ``train`` only; the leave-one-out refits use every
        sample up to the end of each *other* configuration's test block
    drift : also fit the models with parameters per configuration (``capstan, X per configuration``)
    n_bootstrap : bootstrap draws of the exported set and of each leave-one-out figure of the chosen
        structure (:func:`loco_bootstrap`; 0: none)
    blocks : per recording, its cycles (for the bootstrap); default: [train, test]

    Returns
    -------
    summary : dict, JSON-ready
        ``models``: name -> {params {name: {value, unit}}, n_params, rmse_test_deg (all test blocks
        pooled), configurations [per recording: rmse_train_deg, rmse_test_deg, max_abs_test_deg, K_a,
        K_b]}; ``choice`` (:func:`estimator.offline.pair.general.choose_shared`); ``chosen`` (name);
        ``leave_one_out``: name -> [per recording: rmse_test_deg, rmse_all_deg, params and, for the chosen
        structure with ``n_bootstrap``, ``rmse_test_bootstrap`` (:func:`loco_bootstrap`)]; ``E6``:
        {score S of capstan against mu = 0 on the pooled test rmse, price, accepted}; ``mu`` [1/rad];
        ``params`` (the chosen set refitted on every sample of every configuration, with bootstrap
        std / ci95: :func:`estimator.offline.pair.general.export_params`); ``uncertainty`` (bootstrap
        correlation matrix, local correlation); ``samples`` (what was used for what).
    details : dict of per-sample predictions [rad] (``models`` / ``leave_one_out`` -> name -> list of
        arrays), for figures; not JSON.
    """
    tick = progress or (lambda label: None)
    summary: dict = {"models": {}, "leave_one_out": {}}
    details: dict = {"models": {}, "leave_one_out": {}}
    names = list(dict.fromkeys(("capstan",) + COMPARED + CHOICE))
    names += [n for n, m in SHARED_MODELS.items() if m.per_config and drift]
    fitted = _fit_models(names, recs, bends, train, test, summary, details, tick)
    choice = choose_shared(recs, bends, train, CHOICE, fitted, tick)
    chosen = choice["chosen"]
    summary.update(choice=choice, chosen=chosen)
    upto = [slice(0, te.stop) for te in test]
    cyc = blocks or [[tr, te] for tr, te in zip(train, test, strict=False)]
    for name in dict.fromkeys(LEAVE_ONE_OUT + (chosen,)):
        rows = leave_one_out(SHARED_MODELS[name], recs, bends, upto, test, fitted[name], tick)
        details["leave_one_out"][name] = [r.pop("angle") for r in rows]
        if n_bootstrap and name == chosen:
            for r, u in zip(rows, loco_bootstrap(SHARED_MODELS[name], recs, bends, cyc, test, rows,
                                                 n_draws=n_bootstrap), strict=False):
                r["rmse_test_bootstrap"] = u
            tick("leave-one-out bootstrap")
        summary["leave_one_out"][name] = rows
    ms = summary["models"]
    S = (ms["capstan"]["rmse_test_deg"] / ms["capstan, mu = 0"]["rmse_test_deg"]) ** 2
    price = S + PENALTY * (ms["capstan"]["n_params"] - ms["capstan, mu = 0"]["n_params"])
    summary["E6"] = {"score": S, "price": price, "accepted": price < 1.0}
    summary["mu"] = fitted["capstan"]["mu"]
    _export(SHARED_MODELS[chosen], recs, bends, upto, cyc, fitted[chosen], n_bootstrap, summary, tick)
    summary["samples"] = {"fit": "training block of every configuration", "choice": choice["rule"],
                          "test": "once per model: its reported figures",
                          "leave_one_out": "refit on every sample of the other configurations, scored on the "
                                           "left-out configuration's test block"
                                           + ("; its uncertainty: the other configurations' cycles redrawn and "
                                              "refitted, the same block scored" if n_bootstrap else ""),
                          "params": "refit on every sample of every configuration, for new configurations"}
    return summary, details


def _fit_models(names: list[str], recs: list, bends: list[float], train: list[slice], test: list[slice],
                summary: dict, details: dict, tick: Callable[[str], None]) -> dict[str, dict[str, float]]:
    """Fit each named shared model on the training slices and score it (:func:`shared_analysis`); fills
    ``summary["models"]`` and ``details["models"]`` and returns the fitted values by name."""
    fitted: dict[str, dict[str, float]] = {}
    for name in names:
        m = SHARED_MODELS[name]
        # variants of the angle-only capstan model start from its fit (their extra freedom at its values)
        warm = [dict(fitted["capstan"])] if (m.structure == "capstan" and m.grows and "capstan" in fitted
                                             and not m.tension_weight) else []
        v = fit_shared(m, recs, bends, train, starts=warm + list(m.starts[:1]) if warm else None)
        tick(f"shared {name}")
        fitted[name] = v
        rows = score(m, v, recs, bends, train, test)
        details["models"][name] = [r.pop("angle") for r in rows]
        err2 = [np.square(a - np.asarray(r.angle, dtype=float))[te] for a, r, te in
                zip(details["models"][name], recs, test, strict=False)]
        units = {p.name: p.unit for p in shared_params(m, len(recs))}
        summary["models"][name] = {"params": {k: {"value": x, "unit": units[k]} for k, x in v.items()},
                                   "n_params": len(v), "configurations": rows,
                                   "rmse_test_deg": math.degrees(float(np.sqrt(np.mean(np.concatenate(err2)))))}
    return fitted


def _export(m: SharedModel, recs: list, bends: list[float], upto: list[slice], cyc: list[list[slice]],
            start: dict[str, float], n_bootstrap: int, summary: dict, tick: Callable[[str], None]) -> None:
    """The exported set: the chosen structure ``m`` refitted on every sample of every configuration, with
    its bootstrap and local correlation (``summary["params"]`` and ``summary["uncertainty"]``)."""
    v_all, res = fit_shared(m, recs, bends, upto, starts=[start], full=True)
    tick("shared set, all samples")
    unc = bootstrap(m, recs, bends, cyc, v_all, n_draws=n_bootstrap) if n_bootstrap else None
    tick("bootstrap")
    summary["params"] = export_params(m, v_all, "every sample up to the end of the test block of "
                                      f"{len(recs)} configurations (bends {', '.join(f'{b:.3f}' for b in bends)} rad)",
                                      unc)
    summary["uncertainty"] = {"bootstrap": None if unc is None else {k: unc[k] for k in ("correlation", "n_draws",
                                                                                        "method")},
                              "local_correlation": local_correlation(res, list(v_all))}
