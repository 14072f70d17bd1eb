"""Distal bending angle of a joint driven by an antagonistic tendon pair, from proximal signals.

Seed pair model (kinematic path of Phee et al. 2009 applied to each tendon)::

    x_in,a = +g c,   x_in,b = -g c                      motor drives A in, B out [m]; c command [rad]
    e_j(t) = (L/EA)_j * mean_s T_j(s, t),  j = a, b     elongation of the profile-memory model [m]
             T_j(s, t): envelope rule of estimator.sheath with K_j, from T_j(s, 0) = T_j(0) (pretension)
    x_out,j = x_in,j - (e_j(t) - e_j(0))                distal tendon displacement [m]
    theta   = (x_out,a - x_out,b) / (2 r) + theta_0     both tendons taut on a joint pulley of radius r

which, with g, r and L/EA not separately observable, is fitted as

    theta = G c - lam_a (E_a - E_a(0)) + lam_b (E_b - E_b(0)) + theta_0,    E_j = mean_s T_j(s)  [N]

Parameters: G = g / r >= 0 [-], K_a, K_b in 0..5 [-], lam_j = (L/EA)_j / (2 r) >= 0 [rad/N],
theta_0 [rad]. Inputs: the command and the two measured proximal tensions only. The fit
(``scipy.optimize.least_squares``) uses the training samples at the start of the recording (the
first command cycle); the model always runs from the first sample, so test samples are predicted
with the state the training part left. Baselines: the linear map ``theta = a c + b`` (the
uncompensated case) and, as a diagnostic for equivalent backlash (docs/concepts/effects.md E1b/E12), that map
through a play operator of half-width w. :func:`reversal_dead_zones` measures the dead zones
without any model.

Force path (diagnostic, same profile memory used for the distal *tensions* instead of the
elongations; the joint as an elastic load of stiffness k, docs/concepts/effects.md E11)::

    k theta = r (T_out,a - T_out,b) + k theta_0   =>   theta = beta (T_out,a - T_out,b) + theta_0

with T_out,j the distal node of the envelope rule (one K for both tendons), beta = r / k >= 0
[rad/N]; the command is not used.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
from numba import njit
from scipy.optimize import least_squares, lsq_linear

from estimator.sheath import SheathModel, profile_batch

__all__ = ["PairParams", "PairFit", "mean_tension", "distal_tension", "predict_angle", "fit_pair",
           "fit_force_path", "fit_linear", "play", "fit_play_map", "DeadZone", "reversal_dead_zones", "rmse"]

K_MAX = 5.0
_K_GRID = (0.0, 0.1, 0.25, 0.5, 0.8, 1.2, 2.0, 3.0)


@dataclass(frozen=True)
class PairParams:
    """Seed pair model parameters: G [-], K_a, K_b [-], lam_a, lam_b [rad/N], theta0 [rad]."""

    G: float
    K_a: float
    K_b: float
    lam_a: float
    lam_b: float
    theta0: float

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


@dataclass(frozen=True)
class PairFit:
    """A fitted model: name, params (name -> value, SI), prediction over the whole recording
    [rad] shape (n,), and the final least-squares cost on the training samples [rad^2]."""

    name: str
    params: dict[str, float]
    prediction: np.ndarray
    cost: float


def rmse(err: np.ndarray) -> float:
    """Root mean square of ``err`` (any shape), in its unit."""
    return float(np.sqrt(np.mean(np.square(err))))


def mean_tension(T: np.ndarray, K: float, n_nodes: int = 50, pretension: float | None = None) -> np.ndarray:
    """E(t) - E(0), E = mean_s T(s, t) of the profile-memory model driven by ``T`` [N].

    Parameters
    ----------
    T : ndarray, shape (n,), proximal tension [N]
    K : float, friction exponent in [0, 5]
    n_nodes : profile elements
    pretension : initial uniform profile [N], default ``T[0]``

    Returns
    -------
    ndarray, shape (n,) [N]; times L/EA gives the elongation change [m] (Phee et al. 2009, eq. (12)
    on a pull branch, the stored profile otherwise).
    """
    _, E, E0 = _run(T, K, n_nodes, pretension)
    return E - E0


def _run(T, K: float, n_nodes: int, pretension: float | None) -> tuple[np.ndarray, np.ndarray, float]:
    """(T_out [N], mean_s T [N], its initial value [N]) of the envelope rule driven by ``T``."""
    T = np.ascontiguousarray(T, dtype=np.float64)
    T0 = float(T[0]) if pretension is None else float(pretension)
    log_gain, weight = SheathModel(K=K, compliance=1.0).nodes(n_nodes)
    T_out, E, _ = profile_batch(np.full(log_gain.size, T0), log_gain, weight, T)
    return T_out, E, float(weight.sum() * T0)


def distal_tension(T: np.ndarray, K: float, n_nodes: int = 50, pretension: float | None = None) -> np.ndarray:
    """T_out(t) [N], shape (n,), of the profile-memory model driven by the proximal tension ``T``
    [N], shape (n,), from a uniform profile at ``pretension`` (default ``T[0]``)."""
    return _run(T, K, n_nodes, pretension)[0]


def predict_angle(p: PairParams, command: np.ndarray, T_a: np.ndarray, T_b: np.ndarray,
                  n_nodes: int = 50) -> np.ndarray:
    """Distal angle of the seed pair model [rad], shape (n,); command [rad], tensions [N], shape (n,)."""
    return (p.G * np.asarray(command, dtype=float) - p.lam_a * mean_tension(T_a, p.K_a, n_nodes)
            + p.lam_b * mean_tension(T_b, p.K_b, n_nodes) + p.theta0)


def fit_pair(command, T_a, T_b, angle, n_train: int, n_nodes: int = 50, *, predict=None,
             name: str = "seed pair model") -> PairFit:
    """Fit the seed pair model on the first ``n_train`` samples.

    Start: for every (K_a, K_b) of a grid, the linear parameters (G, lam_a, lam_b, theta_0) by
    bounded linear least squares; then ``least_squares`` on all six from the best start.

    Parameters
    ----------
    command : ndarray, shape (n,) [rad] ; T_a, T_b : ndarray, shape (n,) [N] ; angle : ndarray, shape (n,) [rad]
    n_train : int, training samples, in [8, n]
    predict : callable (PairParams, command, T_a, T_b, n_nodes) -> angle [rad], optional
        Another model with the same six parameters (default :func:`predict_angle`; e.g.
        :func:`estimator.online.pair_batch.predict_pair_angle`, the joint estimator with its pair coupling).
    name : str, the fitted model's name

    Raises
    ------
    ValueError
        Arrays of unequal length or ``n_train`` out of range.
    """
    c, Ta, Tb, y = (np.asarray(v, dtype=float) for v in (command, T_a, T_b, angle))
    if not (c.shape == Ta.shape == Tb.shape == y.shape and c.ndim == 1):
        raise ValueError("command, T_a, T_b and angle must be 1-D arrays of equal length")
    if not 8 <= n_train <= c.size:
        raise ValueError(f"n_train must be in [8, {c.size}], got {n_train}")
    tr = slice(0, int(n_train))
    Ea = {K: mean_tension(Ta[tr], K, n_nodes) for K in _K_GRID}
    Eb = {K: mean_tension(Tb[tr], K, n_nodes) for K in _K_GRID}
    lo, hi = [0.0, 0.0, 0.0, -np.inf], [np.inf, np.inf, np.inf, np.inf]
    best = None
    for Ka in _K_GRID:
        for Kb in _K_GRID:
            A = np.column_stack([c[tr], -Ea[Ka], Eb[Kb], np.ones(int(n_train))])
            sol = lsq_linear(A, y[tr], bounds=(lo, hi))
            if best is None or sol.cost < best[0]:
                best = (sol.cost, Ka, Kb, sol.x)
    assert best is not None                       # _K_GRID is not empty
    _, Ka, Kb, (G, la, lb, th0) = best

    predict = predict or predict_angle

    def residual(q: np.ndarray) -> np.ndarray:
        p = PairParams(*q)
        return predict(p, c[tr], Ta[tr], Tb[tr], n_nodes) - y[tr]

    x0 = np.array([G, Ka, Kb, la, lb, th0])
    lb_ = np.array([0.0, 0.0, 0.0, 0.0, 0.0, -np.inf])
    ub_ = np.array([np.inf, K_MAX, K_MAX, np.inf, np.inf, np.inf])
    sol = least_squares(residual, np.clip(x0, lb_ + 1e-9, ub_), bounds=(lb_, ub_), diff_step=1e-3,
                        x_scale=[0.1, 0.1, 0.1, 0.01, 0.01, 0.01])
    p = PairParams(*map(float, sol.x))
    return PairFit(name, p.as_dict(), predict(p, c, Ta, Tb, n_nodes), float(sol.cost))


def fit_force_path(T_a, T_b, angle, n_train: int, n_nodes: int = 50) -> PairFit:
    """Force-path diagnostic theta = beta (T_out,a - T_out,b) + theta_0 (module docstring), fitted
    on the first ``n_train`` samples: grid of K with (beta, theta_0) by bounded linear least
    squares, then ``least_squares`` on (K, beta, theta_0), K in [0, 5], beta >= 0.

    Parameters
    ----------
    T_a, T_b : ndarray, shape (n,) [N] ; angle : ndarray, shape (n,) [rad] ; n_train : int
    """
    Ta, Tb, y = (np.asarray(v, dtype=float) for v in (T_a, T_b, angle))
    tr = slice(0, int(n_train))

    def diff(K: float, sl: slice) -> np.ndarray:
        return distal_tension(Ta[sl], K, n_nodes) - distal_tension(Tb[sl], K, n_nodes)

    best = None
    for K in _K_GRID:
        A = np.column_stack([diff(K, tr), np.ones(int(n_train))])
        sol = lsq_linear(A, y[tr], bounds=([0.0, -np.inf], [np.inf, np.inf]))
        if best is None or sol.cost < best[0]:
            best = (sol.cost, K, sol.x)
    assert best is not None
    _, K0, (b0, t0) = best
    sol = least_squares(lambda q: q[1] * diff(q[0], tr) + q[2] - y[tr], [max(K0, 1e-3), b0, t0],
                        bounds=([0.0, 0.0, -np.inf], [K_MAX, np.inf, np.inf]), diff_step=1e-3,
                        x_scale=[0.1, 0.01, 0.01])
    K, beta, th0 = map(float, sol.x)
    return PairFit("force path", {"K": K, "beta": beta, "theta0": th0},
                   beta * diff(K, slice(None)) + th0, float(sol.cost))


def fit_linear(command, angle, n_train: int) -> PairFit:
    """The uncompensated map theta = a c + b [rad], least squares on the first ``n_train`` samples."""
    c, y = np.asarray(command, dtype=float), np.asarray(angle, dtype=float)
    A = np.column_stack([c, np.ones_like(c)])
    (a, b), *_ = np.linalg.lstsq(A[:n_train], y[:n_train], rcond=None)
    pred = a * c + b
    return PairFit("linear map", {"a": float(a), "b": float(b)}, pred,
                   0.5 * float(np.sum((pred[:n_train] - y[:n_train]) ** 2)))


@njit(cache=True)
def _play(u, w, y0, out):  # pragma: no cover - compiled
    y = y0
    for k in range(u.shape[0]):
        if y < u[k] - w:
            y = u[k] - w
        elif y > u[k] + w:
            y = u[k] + w
        out[k] = y


def play(u: np.ndarray, w: float, y0: float | None = None) -> np.ndarray:
    """Play (backlash) operator y_k = min(max(y_{k-1}, u_k - w), u_k + w), shape of ``u``.

    ``w`` >= 0 is the half-width (output units); ``y0`` the state before the first sample, default
    ``u[0]`` (centred in the play).
    """
    u = np.ascontiguousarray(u, dtype=np.float64)
    out = np.empty_like(u)
    if u.size:
        _play(u, float(max(w, 0.0)), float(u[0] if y0 is None else y0), out)
    return out


def fit_play_map(command, angle, n_train: int) -> PairFit:
    """Diagnostic map theta = P_w(a c + b): the linear map through a play of half-width w [rad]
    (equivalent backlash, Kaneko et al. 1991; docs/concepts/effects.md E1b/E12). Fitted on the first
    ``n_train`` samples with ``least_squares`` from a few starting widths."""
    c, y = np.asarray(command, dtype=float), np.asarray(angle, dtype=float)
    tr = slice(0, int(n_train))
    a0 = max(float(np.ptp(y[tr]) / max(np.ptp(c[tr]), 1e-12)), 1e-3)
    best = None
    for w0 in (0.02, 0.1, 0.3, 0.6):
        sol = least_squares(lambda q: play(q[0] * c[tr] + q[1], q[2]) - y[tr], [a0, 0.0, w0],
                            bounds=([0.0, -np.inf, 0.0], [np.inf, np.inf, np.inf]), diff_step=1e-4)
        if best is None or sol.cost < best.cost:
            best = sol
    assert best is not None
    a, b, w = map(float, best.x)
    return PairFit("linear map + play", {"a": a, "b": b, "w": w}, play(a * c + b, w), float(best.cost))


@dataclass(frozen=True)
class DeadZone:
    """After one command reversal: index of the reversal sample; command_travel [rad] until the
    angle has moved by the threshold (nan if it never does); K_release, K_pull [-]: half the log
    ratio of the released / pulled tendon's proximal tension at the reversal and when the angle
    starts to move (the capstan band is T0 e^{-+2K}, Phee et al. 2009, eqs. (14)-(25)); nan where a
    tension is not positive."""

    index: int
    command_travel: float
    K_release: float
    K_pull: float


def reversal_dead_zones(command, angle, T_a, T_b, threshold: float = math.radians(1.0),
                        min_amplitude: float = 0.5) -> list[DeadZone]:
    """Model-free dead zones after each reversal of the command.

    A reversal is a local extremum of the command beyond ``min_amplitude`` times its largest
    magnitude. At a maximum tendon A (whose tension rises with + command) is released and B pulled;
    at a minimum the roles swap.

    Parameters
    ----------
    command, angle : ndarray, shape (n,) [rad] ; T_a, T_b : ndarray, shape (n,) [N]
    threshold : angle change that ends the dead zone [rad]
    """
    c, y, Ta, Tb = (np.asarray(v, dtype=float) for v in (command, angle, T_a, T_b))
    dc = np.diff(c)
    amp = float(np.max(np.abs(c))) if c.size else 0.0
    out: list[DeadZone] = []
    for r in np.flatnonzero(np.sign(dc[1:]) * np.sign(dc[:-1]) < 0) + 1:
        if abs(c[r]) < min_amplitude * amp:
            continue
        moved = np.flatnonzero(np.abs(y[r:] - y[r]) > threshold)
        if moved.size == 0:
            out.append(DeadZone(int(r), math.nan, math.nan, math.nan))
            continue
        k = int(r + moved[0])
        rel, pul = (Ta, Tb) if c[r] > 0 else (Tb, Ta)
        out.append(DeadZone(int(r), float(abs(c[k] - c[r])), _half_log_ratio(rel[r], rel[k]),
                            _half_log_ratio(pul[k], pul[r])))
    return out


def _half_log_ratio(num: float, den: float) -> float:
    """0.5 ln(num / den), nan when either tension is not positive (a load cell with an offset, or a
    released tendon read at or below zero: no capstan ratio)."""
    return 0.5 * math.log(num / den) if num > 0.0 and den > 0.0 else math.nan
