"""Fit the seed model's two parameters to a single-tendon recording and score it on held-out data.

Parameters fitted: the friction exponent K = mu * sum(theta) [-] (Phee et al. 2009, eq. (2)) and
the tendon compliance L/EA [m/N], for two estimators that share them:

* ``profile``: the tension-profile memory estimator (:mod:`estimator.online.distal`, envelope rule)
      T_out_hat = T_n,   x_out_hat = x_in - (L/EA) * mean_s T(s)
* ``phase``: the paper's phase formulas with the "tension at the last reversal" state
  (:class:`estimator.capstan.PhaseFormulaEstimator`, eqs. (1), (12), (14)-(25)).

Both elongations are L/EA times a function of K and the T_in history, which the fit uses to start
from the best of a grid of K with L/EA solved in closed form; ``scipy.optimize.least_squares`` then
refines (K, L/EA) jointly within K in [0, 5], L/EA > 0. The residual stacks the distal tension and
displacement errors, each divided by its measured range on the training block, on training samples
only; the estimator itself always runs over the whole recording from the first sample, so the
held-out block is scored with the state the training block left (as online use would).

The split is a time block: training = ``time < t0 + train_fraction * duration``, held-out = the rest
(never random samples: neighbouring samples are almost equal and would leak).

The phase formulas run here through a compiled copy of ``PhaseFormulaEstimator.step`` (about 100x
faster than the Python loop); tests/estimator/test_fit.py checks that both agree to 1e-12.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from estimator.capstan import phase_formula_batch
from estimator.sheath import SheathModel, profile_batch

__all__ = ["ESTIMATORS", "K_MAX", "Metrics", "ModelFit", "SingleTendonFit", "split_index", "predict",
           "fit_model", "fit_single"]

ESTIMATORS = ("profile", "phase")
K_MAX = 5.0
_K_GRID = (0.0, 0.05, 0.15, 0.35, 0.7, 1.2, 2.0, 3.2)


@dataclass(frozen=True)
class Metrics:
    """Errors of one signal on one block: rmse and max_abs in the signal's unit (N or m);
    full_scale is the measured signal's range over the whole recording (same unit)."""

    rmse: float
    max_abs: float
    full_scale: float

    @property
    def rmse_fs(self) -> float:
        """RMSE / full scale [-]."""
        return self.rmse / self.full_scale if self.full_scale > 0 else math.inf

    @property
    def max_fs(self) -> float:
        """max |error| / full scale [-] (Phee et al. 2010 report about 7 % for their rig)."""
        return self.max_abs / self.full_scale if self.full_scale > 0 else math.inf

    def as_dict(self) -> dict[str, float]:
        return {"rmse": self.rmse, "max_abs": self.max_abs, "full_scale": self.full_scale,
                "rmse_fs": self.rmse_fs, "max_fs": self.max_fs}


@dataclass(frozen=True)
class ModelFit:
    """One estimator fitted on the training block.

    estimator : "profile" or "phase"; K [-]; compliance L/EA [m/N] (None when only T_out was
    measured: it does not affect T_out); train and heldout : signal name ("T_out", "x_out") -> Metrics;
    cost : final least-squares cost (0.5 * sum of squared normalised training residuals).
    """

    estimator: str
    K: float
    compliance: float | None
    train: dict[str, Metrics] = field(default_factory=dict)
    heldout: dict[str, Metrics] = field(default_factory=dict)
    cost: float = math.nan

    def as_dict(self) -> dict:
        return {"K": self.K, "compliance": self.compliance, "cost": self.cost,
                "train": {k: m.as_dict() for k, m in self.train.items()},
                "heldout": {k: m.as_dict() for k, m in self.heldout.items()}}


@dataclass(frozen=True)
class SingleTendonFit:
    """Both estimators on one recording. split : first held-out sample index; split_time [s];
    n_train, n_heldout : sample counts; fits : estimator name -> ModelFit."""

    split: int
    split_time: float
    n_train: int
    n_heldout: int
    fits: dict[str, ModelFit]

    def as_dict(self) -> dict:
        return {"split_time": self.split_time, "n_train": self.n_train, "n_heldout": self.n_heldout,
                "estimators": {k: f.as_dict() for k, f in self.fits.items()}}


def split_index(time: np.ndarray, train_fraction: float = 0.6) -> int:
    """First sample of the held-out block: the first ``time >= t0 + train_fraction * duration``.

    Raises
    ------
    ValueError
        ``train_fraction`` outside (0, 1), or either block would have fewer than 2 samples.
    """
    if not (0.0 < train_fraction < 1.0):
        raise ValueError(f"train_fraction must be in (0, 1), got {train_fraction!r}")
    t = np.asarray(time, dtype=float)
    k = int(np.searchsorted(t, t[0] + train_fraction * (t[-1] - t[0]), side="left"))
    if k < 2 or t.size - k < 2:
        raise ValueError(f"a {train_fraction:.0%} time split of {t.size} samples leaves a block "
                         "with fewer than 2 samples")
    return k


def _unit_run(estimator: str, T_in: np.ndarray, K: float, n_nodes: int, pretension: float, deadband: float):
    """(T_out_hat [N], elongation / compliance [N]) for compliance 1 (elongation is linear in L/EA)."""
    if estimator == "profile":
        log_gain, weight = SheathModel(K=K, compliance=1.0).nodes(n_nodes)
        T_out, e1, _ = profile_batch(np.full(log_gain.size, pretension), log_gain, weight, T_in)
        return T_out, e1
    if estimator == "phase":
        T_out, e1, _ = phase_formula_batch(T_in, K, 1.0, deadband, pretension)
        return T_out, e1
    raise ValueError(f"estimator must be one of {ESTIMATORS}, got {estimator!r}")


def predict(estimator: str, T_in: np.ndarray, x_in: np.ndarray, K: float, compliance: float, *,
            n_nodes: int = 100, pretension: float | None = None, deadband: float = 0.1):
    """Distal estimates of one estimator over a recording.

    Parameters
    ----------
    estimator : "profile" or "phase"
    T_in, x_in : ndarray, shape (n,), proximal tension [N] and displacement [m]
    K : float [-] ; compliance : float, L/EA [m/N]
    n_nodes : profile elements ; pretension : initial tension [N], default ``T_in[0]``
    deadband : reversal dead band of the phase formulas [N]

    Returns
    -------
    T_out_hat : ndarray, shape (n,) [N] ; x_out_hat : ndarray, shape (n,) [m]
    """
    T_in = np.ascontiguousarray(T_in, dtype=np.float64)
    T0 = float(T_in[0]) if pretension is None else float(pretension)
    T_out, e1 = _unit_run(estimator, T_in, K, n_nodes, T0, deadband)
    return T_out, np.asarray(x_in, dtype=float) - compliance * e1


def _metrics(err: np.ndarray, full_scale: float) -> Metrics:
    return Metrics(float(np.sqrt(np.mean(err ** 2))), float(np.max(np.abs(err))), full_scale)


def fit_model(estimator: str, T_in, x_in, *, T_out=None, x_out=None, n_train: int, n_nodes: int = 100,
              pretension: float | None = None, deadband: float = 0.1) -> ModelFit:
    """Fit (K, L/EA) of one estimator on the first ``n_train`` samples and score the rest.

    Parameters
    ----------
    estimator : "profile" or "phase"
    T_in, x_in : ndarray, shape (n,) [N], [m]
    T_out, x_out : ndarray, shape (n,) [N], [m], optional; at least one is needed
    n_train : int, training samples from the start (normally ``split_index(time)``), >= 2

    Raises
    ------
    ValueError
        Neither T_out nor x_out given, ``n_train`` < 2, or a measured distal signal is constant on
        the training block.
    """
    T_in = np.ascontiguousarray(T_in, dtype=np.float64)
    x_in = np.asarray(x_in, dtype=float)
    if T_out is None and x_out is None:
        raise ValueError("fitting needs a measured distal signal: T_out or x_out")
    if not 2 <= n_train <= T_in.size:
        raise ValueError(f"n_train must be in [2, {T_in.size}], got {n_train}")
    train = slice(0, int(n_train))
    T0 = float(T_in[0]) if pretension is None else float(pretension)
    signals = {k: np.asarray(v, dtype=float) for k, v in (("T_out", T_out), ("x_out", x_out)) if v is not None}
    scale = {}
    for name, y in signals.items():
        scale[name] = float(np.ptp(y[train]))
        if not scale[name] > 0:
            raise ValueError(f"measured {name} is constant on the training block: nothing to fit")
    has_x = "x_out" in signals

    def best_c(e1: np.ndarray) -> float:          # closed-form L/EA for x_out = x_in - c e1
        a, b = e1[train], (x_in - signals["x_out"])[train]
        return max(float(a @ b) / max(float(a @ a), 1e-300), 1e-12)

    def residual(K: float, c: float) -> np.ndarray:
        Th, e1 = _unit_run(estimator, T_in[: train.stop], K, n_nodes, T0, deadband)
        parts = []
        if "T_out" in signals:
            parts.append((Th[train] - signals["T_out"][train]) / scale["T_out"])
        if has_x:
            parts.append((x_in[train] - c * e1[train] - signals["x_out"][train]) / scale["x_out"])
        return np.concatenate(parts)

    # start: best K of a grid, L/EA in closed form at each
    starts = []
    for K in _K_GRID:
        c = best_c(_unit_run(estimator, T_in[: train.stop], K, n_nodes, T0, deadband)[1]) if has_x else 1.0
        starts.append((float(np.sum(residual(K, c) ** 2)), K, c))
    _, K0, c0 = min(starts)
    if has_x:   # both parameters, L/EA scaled by its start so the solver sees O(1) numbers
        sol = least_squares(lambda p: residual(p[0], p[1] * c0), [max(K0, 1e-3), 1.0],
                            bounds=([0.0, 1e-9], [K_MAX, np.inf]), diff_step=1e-4, x_scale=[0.1, 0.1])
        K, c = float(sol.x[0]), float(sol.x[1] * c0)
    else:       # T_out does not depend on L/EA
        sol = least_squares(lambda p: residual(p[0], 1.0), [max(K0, 1e-3)], bounds=([0.0], [K_MAX]),
                            diff_step=1e-4, x_scale=[0.1])
        K, c = float(sol.x[0]), None  # type: ignore[assignment]  # no compliance without T_out
    Th, xh = predict(estimator, T_in, x_in, K, c if c is not None else 1.0, n_nodes=n_nodes,
                     pretension=T0, deadband=deadband)
    fits_tr, fits_ho = {}, {}
    for name, y in signals.items():
        err = (Th if name == "T_out" else xh) - y
        fs = float(np.ptp(y))
        fits_tr[name] = _metrics(err[train], fs)
        if n_train < T_in.size:
            fits_ho[name] = _metrics(err[n_train:], fs)
    return ModelFit(estimator, K, c, fits_tr, fits_ho, float(sol.cost))


def fit_single(time, T_in, x_in, *, T_out=None, x_out=None, train_fraction: float = 0.6,
               n_nodes: int = 100, pretension: float | None = None, deadband: float = 0.1) -> SingleTendonFit:
    """Fit both estimators on the first ``train_fraction`` of the time span, score on the rest.

    Parameters
    ----------
    time : ndarray, shape (n,), strictly increasing [s]
    T_in, x_in, T_out, x_out, n_nodes, pretension, deadband : as :func:`fit_model`

    Raises
    ------
    ValueError
        As :func:`split_index` and :func:`fit_model`.
    """
    k = split_index(time, train_fraction)
    fits = {name: fit_model(name, T_in, x_in, T_out=T_out, x_out=x_out, n_train=k, n_nodes=n_nodes,
                            pretension=pretension, deadband=deadband) for name in ESTIMATORS}
    n = int(np.shape(time)[0])
    return SingleTendonFit(k, float(np.asarray(time)[k]), k, n - k, fits)
