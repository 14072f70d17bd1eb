"""Calibration of the spindle pair model (:mod:`estimator.online.spindle`) and its baselines.

Every fit maps the spindle signals (torque tau_p [N m], angle theta_p [rad]) of the calibration
data to the jaw torque and angle of the same data; the predictions of other data use their
spindle signals only. Fits use ``scipy.optimize.least_squares`` (torque, nonlinear in Q and K)
and linear least squares (angle: n_k, n_k lam, theta_0 given the cable profiles; then the
backlash half-width by a bounded scalar search).

Torque models are named by the parameters they free on top of the base (rho, Q, K, b), e.g.
``("k_p", "f")``. Baselines (:func:`fit_baselines`):

* ``constant``  - the calibration's mean jaw torque; the angle by theta_d = a theta_p + c;
* ``linear``    - regression of the jaw torque (and angle) on tau_p, the direction of motion
  tanh(omega_p / OMEGA_S), theta_p and 1;
* ``phase``     - the seed paper's phase formulas (:func:`estimator.capstan.phase_formula_batch`)
  on each cable tension (S1), the jaw torque rho (T_a,out - T_b,out) + b and the angle from the two
  elongations, with K, Q, rho, b fitted.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares, minimize_scalar

from estimator.capstan import phase_formula_batch
from estimator.online.spindle import OMEGA_S, Batch, SpindleParams, elongation_difference, play_batch, predict_torque

__all__ = ["BASE", "EXTENSIONS", "EXTENSION_STARTS", "BOUNDS", "fit_torque", "fit_angle", "fit_model", "fit_baselines",
           "Baseline", "band_centre"]

BASE = ("rho", "Q", "K_a", "b")
#: Extension parameter -> (literature number, what it stands for).
EXTENSIONS = {
    "K_b": ("E13", "a second friction exponent for the other cable (asymmetric routing: band grows with load)"),
    "rho_1": ("E7", "torque ratio changing with the jaw angle (cable lever arm at the jaw), first order"),
    "rho_2": ("E7", "torque ratio changing with the jaw angle, second order"),
    "k_p": ("E11", "elastic torque inside the proximal end (loads the spindle, not the jaw)"),
    "k_d": ("E11", "angle-dependent torque at the jaw side (jaw spring, load)"),
    "f": ("E11/E12", "Coulomb friction beyond the jaw pulley (jaw pivot, load motor)"),
    "f_s": ("E8/E2", "friction at the spindle ahead of the cables (tension-independent), reversing over "
                     "a spindle travel of 0.05 rad (pre-sliding)"),
    "c_v": ("E3", "viscous torque at the spindle (rate dependence)"),
    "theta_c": ("E2", "pre-sliding: the jaw torque approaches the capstan value over a travel theta_c"),
}
#: (lo, hi, scale) per torque parameter.
BOUNDS = {"rho": (0.0, 5.0, 0.1), "Q": (1e-3, 5.0, 0.05), "K_a": (0.0, 3.0, 0.1), "K_b": (0.0, 3.0, 0.1),
          "b": (-1.0, 1.0, 0.01), "rho_1": (-3.0, 3.0, 0.05), "rho_2": (-5.0, 5.0, 0.05), "k_p": (-0.2, 0.2, 0.005),
          "k_d": (-0.2, 0.2, 0.005), "f": (-0.1, 0.1, 0.001),
          "f_s": (-0.2, 0.2, 0.005), "theta_s": (0.005, 1.0, 0.02), "c_v": (-0.2, 0.2, 0.005),
          "theta_c": (0.0, 0.5, 0.01)}
#: Start of an extension parameter when it is added to a fitted model (0 unless listed).
EXTENSION_STARTS = {"theta_c": 0.03, "f_s": -0.01}
#: Starting points; Q in multiples of its lower bound (1.02 max |tau_p|).
_STARTS = ({"K_a": 0.3, "K_b": 0.3, "Q": 1.5}, {"K_a": 0.8, "K_b": 0.8, "Q": 1.1}, {"K_a": 0.1, "K_b": 0.1, "Q": 5.0})


def band_centre(tau_p: np.ndarray) -> float:
    """Middle of the spindle torque band [N m]: mean of its 2nd and 98th percentiles."""
    lo, hi = np.percentile(np.asarray(tau_p, dtype=float), [2.0, 98.0])
    return float(0.5 * (lo + hi))


def fit_torque(bt: Batch, target: np.ndarray, free: tuple[str, ...] = (), start: SpindleParams | None = None,
               weights: np.ndarray | None = None, max_nfev: int = 300,
               fixed: tuple[str, ...] = (), multistart: bool = False) -> tuple[SpindleParams, float]:
    """Fit the torque parameters BASE + ``free`` to ``target`` [N m], shape (n,), over a batch.

    ``weights`` (shape (n,), >= 0) scale the residuals (0 leaves a sample out); ``start`` gives
    one starting point (else three); at most ``max_nfev`` evaluations per start; ``fixed`` names
    base parameters held at their ``start`` values (e.g. rho from known pulley radii: with rho free,
    K and Q are only known through rho cosh K and Q tanh K); ``multistart`` runs the three
    starting points from ``start`` (the fixed values kept) instead of the single one.
    Q is kept above 1.02 max |tau_p| at every start (both cables taut). Returns the parameters and
    the rms residual [N m]. Raises ValueError for an unknown parameter name or a shape mismatch.
    """
    names = tuple(n for n in BASE if n not in fixed) + tuple(n for n in free if n not in BASE)
    for n in names:
        if n not in BOUNDS:
            raise ValueError(f"unknown torque parameter {n!r}; known: {', '.join(BOUNDS)}")
    y = np.asarray(target, dtype=float)
    if y.shape != bt.tau_p.shape:
        raise ValueError(f"target shape {y.shape} does not match the batch {bt.tau_p.shape}")
    wts = np.ones_like(y) if weights is None else np.asarray(weights, dtype=float)
    qmin = 1.02 * float(np.max(np.abs(bt.tau_p)))
    lo = np.array([max(BOUNDS[n][0], qmin) if n == "Q" else BOUNDS[n][0] for n in names])
    hi = np.array([BOUNDS[n][1] for n in names])
    scale = np.array([BOUNDS[n][2] for n in names])
    base = start or SpindleParams()

    def params(x) -> SpindleParams:
        v = dict(zip(names, x, strict=False))
        if "K_b" not in names:      # one friction exponent for both cables
            v["K_b"] = v["K_a"]
        return base.with_values(**v)

    def residual(x):
        return wts * (predict_torque(params(x), bt) - y)

    best = None
    several = start is None or multistart
    starts = [dict(s) for s in _STARTS] if several else [dict()]
    for s in starts:
        p0 = base.with_values(**{k: (v * qmin if k == "Q" and several else v) for k, v in s.items()})
        x0 = np.clip([getattr(p0, n) for n in names], lo + 1e-9, hi - 1e-9)
        if several and "b" in names:        # linear start for rho (unless fixed) and b
            Td = predict_torque(p0.with_values(rho=1.0, b=0.0, k_d=0.0, f=0.0), bt)
            if "rho" in names:
                (r0, b0), *_ = np.linalg.lstsq(np.column_stack([Td, np.ones_like(Td)]), y, rcond=None)
                x0[names.index("rho")] = np.clip(r0, 1e-3, 4.9)
            else:
                b0 = float(np.mean(y - p0.rho * Td))
            x0[names.index("b")] = np.clip(b0, -0.9, 0.9)
        sol = least_squares(residual, x0, bounds=(lo, hi), x_scale=scale, diff_step=1e-4, max_nfev=max_nfev)
        if best is None or sol.cost < best.cost:
            best = sol
    assert best is not None
    p = params(best.x)
    return p, float(np.sqrt(np.mean((predict_torque(p, bt) - y) ** 2)))


def fit_angle(p: SpindleParams, bt: Batch, target: np.ndarray, backlash: bool = True,
              weights: np.ndarray | None = None) -> SpindleParams:
    """Fit n_k, lam, theta_0 (linear least squares given the profiles of ``p``) and, when
    ``backlash``, the E12 half-width beta in [0, 0.1] rad, to the jaw angle ``target`` [rad];
    samples with ``weights`` (shape (n,)) == 0 are left out of the fit."""
    y = np.asarray(target, dtype=float)
    m = np.ones(y.shape, dtype=bool) if weights is None else np.asarray(weights) > 0
    dE = elongation_difference(p, bt)
    A = np.column_stack([bt.theta_p, -dE, np.ones_like(y)])
    (nk, nl, th0), *_ = np.linalg.lstsq(A[m], y[m], rcond=None)
    q = p.with_values(n_k=nk, lam=nl / nk if abs(nk) > 1e-9 else 0.0, theta0=th0, beta=0.0)
    if not backlash:
        return q
    base = nk * bt.theta_p - nl * dE

    def cost(beta):
        th = play_batch(base, bt.starts, beta)[m]
        return float(np.var(y[m] - th))

    res = minimize_scalar(cost, bounds=(0.0, 0.1), method="bounded", options={"xatol": 1e-5})
    beta = float(res.x) if res.fun < cost(0.0) else 0.0
    th0 = float(np.mean((y - play_batch(base, bt.starts, beta))[m]))
    return q.with_values(beta=beta, theta0=th0)


def fit_model(bt: Batch, tau_d: np.ndarray, theta_d: np.ndarray, free: tuple[str, ...] = (),
              backlash: bool = True) -> SpindleParams:
    """Torque then angle parameters on one batch (:func:`fit_torque`, :func:`fit_angle`)."""
    p, _ = fit_torque(bt, tau_d, free)
    return fit_angle(p, bt, theta_d, backlash)


@dataclass(frozen=True)
class Baseline:
    """A fitted baseline: name, parameters (name -> value) and a predictor batch -> (torque [N m], angle [rad])."""

    name: str
    params: dict
    predict: Callable[[Batch], tuple[np.ndarray, np.ndarray]]


def _direction(bt: Batch) -> np.ndarray:
    return np.tanh(bt.omega_p / OMEGA_S)


def _phase(bt: Batch, Q: float, K: float) -> tuple[np.ndarray, np.ndarray]:
    """(T_a,out - T_b,out, e_a - e_b) of the paper's phase formulas, run by run [N m]."""
    Td, dE = np.empty_like(bt.tau_p), np.empty_like(bt.tau_p)
    for i0, i1 in zip(bt.starts[:-1], bt.starts[1:], strict=False):
        u = bt.tau_p[i0:i1]
        Ta, Tb = 0.5 * (Q + u), 0.5 * (Q - u)
        oa, ea, _ = phase_formula_batch(Ta, K, 1.0, deadband=0.002 * Q, T0=float(Ta[0]))
        ob, eb, _ = phase_formula_batch(Tb, K, 1.0, deadband=0.002 * Q, T0=float(Tb[0]))
        Td[i0:i1], dE[i0:i1] = oa - ob, ea - eb
    return Td, dE


def fit_baselines(bt: Batch, tau_d: np.ndarray, theta_d: np.ndarray,
                  mask: np.ndarray | None = None) -> dict[str, Baseline]:
    """The three baselines (module docstring) fitted on one batch; ``mask`` (bool, shape (n,)) selects
    the samples fitted (all by default; the phase formulas still run from the first sample)."""
    y, th = np.asarray(tau_d, dtype=float), np.asarray(theta_d, dtype=float)
    k = np.ones(y.shape, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
    out: dict[str, Baseline] = {}
    A1 = np.column_stack([bt.theta_p, np.ones_like(y)])
    (a, c), *_ = np.linalg.lstsq(A1[k], th[k], rcond=None)
    m = float(np.mean(y[k]))

    def pred_constant(b: Batch) -> tuple[np.ndarray, np.ndarray]:
        return np.full(b.tau_p.shape, m), a * b.theta_p + c

    out["constant"] = Baseline("constant", {"tau_d": m, "a": float(a), "c": float(c)}, pred_constant)

    def feats(b):
        return np.column_stack([b.tau_p, _direction(b), b.theta_p, np.ones_like(b.tau_p)])

    ct, *_ = np.linalg.lstsq(feats(bt)[k], y[k], rcond=None)
    ca, *_ = np.linalg.lstsq(feats(bt)[k], th[k], rcond=None)

    def pred_linear(b: Batch) -> tuple[np.ndarray, np.ndarray]:
        return feats(b) @ ct, feats(b) @ ca

    out["linear"] = Baseline("linear", {"torque": [float(v) for v in ct], "angle": [float(v) for v in ca],
                                        "features": ["tau_p", "direction", "theta_p", "1"]}, pred_linear)
    qmin = 1.02 * float(np.max(np.abs(bt.tau_p)))

    def res(x):
        Td, _ = _phase(bt, x[0], x[1])
        return (x[2] * Td + x[3] - y)[k]

    best = None
    for Q0, K0 in ((max(1.5, qmin), 0.3), (max(3.0, qmin), 0.8)):
        s = least_squares(res, [Q0, K0, 1.0, 0.0], bounds=([qmin, 0.0, 0.0, -1.0], [5.0, 3.0, 5.0, 1.0]),
                          x_scale=[0.05, 0.1, 0.1, 0.01], diff_step=1e-4, max_nfev=200)
        if best is None or s.cost < best.cost:
            best = s
    assert best is not None
    Q, K, rho, b0 = map(float, best.x)
    _, dE = _phase(bt, Q, K)
    cang, *_ = np.linalg.lstsq(np.column_stack([bt.theta_p, -dE, np.ones_like(th)])[k], th[k], rcond=None)

    def pred_phase(b, Q=Q, K=K, rho=rho, b0=b0, cang=cang):
        Td, dE = _phase(b, Q, K)
        return rho * Td + b0, np.column_stack([b.theta_p, -dE, np.ones_like(b.tau_p)]) @ cang

    out["phase"] = Baseline("phase", {"Q": Q, "K": K, "rho": rho, "b": b0, "n_k": float(cang[0]),
                                      "n_k_lam": float(cang[1]), "theta0": float(cang[2])}, pred_phase)
    return out
