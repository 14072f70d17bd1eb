"""One parameter set of the spindle pair model for many runs: extension selection and leave-one-run-out.

The runs are given as :class:`RunData` (spindle torque and angle, the jaw truth, and the index
from which a run is scored: after its initialisation stroke). Procedure (the held-out discipline of
:mod:`estimator.offline.pair_diagnosis`):

1. :func:`select_extensions` - every run's first half (after its initialisation) fits, its second
   half validates. Starting from the base model (rho, Q, K_a, b), each extension of
   :data:`estimator.offline.spindle_fit.EXTENSIONS` not yet chosen is fitted (warm start from the chosen
   model, the new parameter at 0) and scored S = (validation rmse / base validation rmse)^2; the
   best is accepted when S / S_chosen + PENALTY (its extra parameters) < 1, and the rounds go on
   until nothing is accepted.
2. :func:`shared_fit` - the chosen model on all of every run (after initialisation).
3. :func:`leave_one_out` - for each run, the chosen model refitted on the others (warm start from
   the shared fit) predicts it from its spindle signals.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from estimator.offline.diagnosis import PENALTY
from estimator.offline.spindle_fit import EXTENSION_STARTS, EXTENSIONS, fit_angle, fit_torque
from estimator.online.spindle import Batch, SpindleParams, make_batch, predict_angle, predict_torque

__all__ = ["RunData", "batch_of", "select_extensions", "shared_fit", "leave_one_out"]


@dataclass(frozen=True, eq=False)
class RunData:
    """One run: tau_p [N m], theta_p [rad], tau_d [N m], theta_d [rad] (shape (n,)), k0 the first
    scored sample (after the initialisation stroke), dt [s]."""

    name: str
    tau_p: np.ndarray
    theta_p: np.ndarray
    tau_d: np.ndarray
    theta_d: np.ndarray
    k0: int
    dt: float


def batch_of(runs: list[RunData], centre: float, theta_ref: float, step: int,
             part: str = "all") -> tuple[Batch, np.ndarray, np.ndarray, np.ndarray]:
    """(batch, jaw torque [N m], jaw angle [rad], weights) of the runs decimated by ``step``.

    ``part``: ``"all"`` weights every sample from k0 on, ``"first"`` / ``"second"`` the samples from
    k0 to the middle of the scored part / from there to the end (the model still runs from t = 0).
    """
    bt = make_batch([(r.tau_p, r.theta_p) for r in runs], centre, theta_ref, runs[0].dt, step)
    ws = []
    for r in runs:
        i = np.arange(len(r.tau_p))[::step]
        mid = (r.k0 + len(r.tau_p)) // 2
        m = {"all": i >= r.k0, "first": (i >= r.k0) & (i < mid), "second": i >= mid}[part]
        ws.append(m.astype(float))
    return (bt, np.concatenate([r.tau_d[::step] for r in runs]), np.concatenate([r.theta_d[::step] for r in runs]),
            np.concatenate(ws))


def _rmse(p: SpindleParams, bt: Batch, y: np.ndarray, w: np.ndarray) -> float:
    e = (predict_torque(p, bt) - y)[w > 0]
    return float(np.sqrt(np.mean(e ** 2)))


def select_extensions(runs: list[RunData], centre: float, theta_ref: float, step: int = 50,
                      candidates: tuple[str, ...] | None = None,
                      progress: Callable[[str], None] | None = None) -> dict:
    """Forward selection of torque extensions on a time split of every run (module docstring).

    Returns a JSON-ready dict: ``base`` {params, rmse_fit, rmse_val} [N m], ``rounds`` (per round:
    candidate -> {rmse_val [N m], S, price}), ``chosen`` (extension ids in order), ``params``
    (the chosen model's values).
    """
    tick = progress or (lambda label: None)
    cands = list(candidates if candidates is not None else EXTENSIONS)
    bf, yf, _, wf = batch_of(runs, centre, theta_ref, step, "first")
    bv, yv, _, wv = batch_of(runs, centre, theta_ref, step, "second")
    p0, _ = fit_torque(bf, yf, (), weights=wf)
    tick("base")
    base_val = _rmse(p0, bv, yv, wv)
    out = {"base": {"params": p0.as_dict(), "rmse_fit": _rmse(p0, bf, yf, wf), "rmse_val": base_val},
           "rounds": [], "chosen": []}
    chosen, p_ch, s_ch = [], p0, 1.0
    while True:
        rnd = {}
        best = None
        for c in [c for c in cands if c not in chosen]:
            q, _ = fit_torque(bf, yf, tuple(chosen) + (c,), start=p_ch.with_values(**{c: EXTENSION_STARTS.get(c, 0.0)}),
                              weights=wf, max_nfev=80)
            v = _rmse(q, bv, yv, wv)
            S = (v / base_val) ** 2
            price = S / s_ch + PENALTY * 1
            rnd[c] = {"rmse_val": v, "S": S, "price": price}
            tick(f"+{c}")
            if best is None or price < best[0]:
                best = (price, c, q, S)
        out["rounds"].append(rnd)
        if best is None or best[0] >= 1.0:
            break
        chosen.append(best[1])
        p_ch, s_ch = best[2], best[3]
    out["chosen"], out["params"] = chosen, p_ch.as_dict()
    out["rmse_val"] = _rmse(p_ch, bv, yv, wv)
    return out


def shared_fit(runs: list[RunData], free: tuple[str, ...], centre: float, theta_ref: float, step: int = 50,
               start: SpindleParams | None = None, max_nfev: int = 300) -> SpindleParams:
    """The model BASE + ``free`` fitted to every run from its k0 on (torque, then angle)."""
    bt, yt, ya, w = batch_of(runs, centre, theta_ref, step)
    p, _ = fit_torque(bt, yt, free, start=start, weights=w, max_nfev=max_nfev)
    return fit_angle(p, bt, ya, weights=w)


def leave_one_out(runs: list[RunData], free: tuple[str, ...], centre: float, theta_ref: float, start: SpindleParams,
                  step: int = 50, progress: Callable[[str], None] | None = None
                  ) -> list[tuple[SpindleParams, np.ndarray, np.ndarray]]:
    """For each run: (parameters refitted without it, predicted jaw torque [N m], angle [rad] at full rate)."""
    tick = progress or (lambda label: None)
    out = []
    for r in runs:
        q = shared_fit([s for s in runs if s is not r], free, centre, theta_ref, step, start=start, max_nfev=60)
        b = make_batch([(r.tau_p, r.theta_p)], centre, theta_ref, r.dt)
        out.append((q, predict_torque(q, b), predict_angle(q, b)))
        tick(f"leave out {r.name}")
    return out
