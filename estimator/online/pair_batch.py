"""The joint estimator over recorded arrays (compiled), and the KAIST pair driven through it.

:func:`estimate_pair_batch` is the maths of :class:`estimator.online.pair.PairEstimator` ((J1)-(J6) there)
in one compiled loop; :func:`predict_pair_angle` maps a recording of the KAIST flexible-endoscope pair
(two proximal tensions, one motor command, the distal angle) onto it.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from estimator.distal_slip import elongation
from estimator.online.pair import DEFAULT_PLAY, KAIST_PLAY, PairBatch, PairEstimator
from estimator.online.pair_coupling import couple, weighted_angle
from estimator.sheath import SheathModel, profile_update

__all__ = ["estimate_pair_batch", "predict_pair_angle"]


@njit(cache=True)
def _batch(Ta, xa, Tb, xb, Pa, Pb, ga, gb, wa, wb, dloa, dhia, dlob, dhib, r, hw, coupling, taut,
           torque, angle, T_out, elong):  # pragma: no cover - compiled
    Ka = ga[-1]
    Kb = gb[-1]
    x0a = 0.0
    x0b = 0.0
    state = np.array([-1.0, 0.0, 0.0, 0.0, 0.0])
    for k in range(Ta.shape[0]):
        Ta_prev = Pa[-1]
        Tb_prev = Pb[-1]
        profile_update(Pa, ga, Ta[k])
        profile_update(Pb, gb, Tb[k])
        ea = elongation(Pa, wa)
        eb = elongation(Pb, wb)
        if k == 0:
            x0a = xa[0] - ea
            x0b = xb[0] - eb
        if coupling:
            ua = (xa[k] - ea - x0a) / r
            ub = -(xb[k] - eb - x0b) / r
            couple(Pa, dloa, dhia, wa, Ka, Pb, dlob, dhib, wb, Kb, Ta_prev, Tb_prev, ua, ub, r, hw, state)
            ea = elongation(Pa, wa)
            eb = elongation(Pb, wb)
        T_out[k, 0] = Pa[-1]
        T_out[k, 1] = Pb[-1]
        elong[k, 0] = ea
        elong[k, 1] = eb
        torque[k] = r * (Pa[-1] - Pb[-1])
        angle[k] = weighted_angle((xa[k] - ea - x0a) / r, -(xb[k] - eb - x0b) / r, Ta[k], Tb[k], taut)


def estimate_pair_batch(T_a, x_a, T_b, x_b, model_a: SheathModel, model_b: SheathModel, pulley_radius: float, *,
                         n_nodes: int = 100, pretension: float | tuple[float, float] = 0.0, coupling: bool = True,
                         play: float = DEFAULT_PLAY, taut_tension: float = 0.1,
                         tension_noise: float | tuple[float, float] = 0.0, time: np.ndarray | None = None) -> PairBatch:
    """The maths of :class:`PairEstimator` over recorded arrays (compiled), zero pose at sample 0.

    Parameters
    ----------
    T_a, x_a, T_b, x_b : ndarray, shape (n,)
        Proximal tensions [N] and displacements [m] of tendons a and b.
    model_a, model_b, pulley_radius, n_nodes, pretension, coupling, play, taut_tension, tension_noise
        As :class:`PairEstimator`; with a noise band (``tension_noise`` > 0) the estimator is stepped sample by sample
        (the same numbers as its live :meth:`PairEstimator.step`).
    time : ndarray, shape (n,), optional
        Sample times [s] for the banded update's proximal velocities (default 1 kHz); unused without a band.

    Raises
    ------
    ValueError
        Arrays not 1-D of one length, with NaN/inf (the first bad index is named), or bad settings.
    """
    arrs = [np.ascontiguousarray(v, dtype=np.float64) for v in (T_a, x_a, T_b, x_b)]
    n = arrs[0].shape
    for name, a in zip(("T_a", "x_a", "T_b", "x_b"), arrs, strict=False):
        if a.ndim != 1 or a.shape != n:
            raise ValueError(f"T_a, x_a, T_b, x_b must be 1-D of equal length, got {name} of shape {a.shape}")
        bad = np.flatnonzero(~np.isfinite(a))
        if bad.size:
            raise ValueError(f"{name} has a non-finite value at sample {bad[0]}")
    ref = PairEstimator(model_a, model_b, pulley_radius, n_nodes=n_nodes, pretension=pretension, coupling=coupling,
                         play=play, taut_tension=taut_tension, tension_noise=tension_noise)   # validates, builds nodes
    ta, tb = ref.tendons
    m = n[0]
    if ta.tension_noise > 0.0 or tb.tension_noise > 0.0:
        t = np.arange(m) * 1e-3 if time is None else np.asarray(time, dtype=float)
        if t.shape != n:
            raise ValueError(f"time must have the shape of the samples {n}, got {t.shape}")
        Ta, xa, Tb, xb = arrs
        out = [ref.step(float(Ta[k]), float(xa[k]), float(Tb[k]), float(xb[k]), float(t[k])) for k in range(m)]
        return PairBatch(torque=np.array([s.torque for s in out]), angle=np.array([s.angle for s in out]),
                          T_out=np.array([s.T_out for s in out]).reshape(m, 2),
                          elongation=np.array([s.elongation for s in out]).reshape(m, 2))
    (dloa, dhia), (dlob, dhib) = ref._dgain
    torque, angle = np.empty(m), np.empty(m)
    T_out, elong = np.empty((m, 2)), np.empty((m, 2))
    _batch(*arrs, ta.profile.copy(), tb.profile.copy(), ta.log_gain, tb.log_gain, ta.weight, tb.weight, dloa, dhia,
           dlob, dhib, ref.r, ref.half_width, bool(coupling), ref.taut, torque, angle, T_out, elong)
    return PairBatch(torque=torque, angle=angle, T_out=T_out, elongation=elong)


def predict_pair_angle(p, command, T_a, T_b, n_nodes: int = 50, play: float = KAIST_PLAY) -> np.ndarray:
    """Distal angle [rad], shape (n,), of a pair driven as the KAIST robot drives it, by this estimator.

    The motor turns both tendons, x_in,a = +g c and x_in,b = -g c for the command c [rad]; with the
    pulley radius r, g and the compliances not separately observable, the estimator runs in units of
    r (r = 1): x_in,a = G c, x_in,b = -G c, L/EA_j = 2 lam_j [rad/N], from uniform profiles at the
    first measured tensions (the pretension), so that (J3) reads

        theta = G (c - c_0) - lam_a (E_a - E_a(0)) + lam_b (E_b - E_b(0)) + theta_0,   E_j = mean_s T_j

    - the seed pair model of :mod:`estimator.offline.pair.fit` with the pair coupling (J4)-(J6) acting on the
    profiles. ``p`` is an :class:`estimator.offline.pair.fit.PairParams`; ``play`` [rad] the coupling's play.
    Use with :func:`estimator.offline.pair.fit.fit_pair` (``predict=predict_pair_angle``).
    """
    c = np.asarray(command, dtype=float)
    Ta = np.asarray(T_a, dtype=float)
    Tb = np.asarray(T_b, dtype=float)
    models = [SheathModel(K=K, compliance=max(2.0 * lam, 1e-12)) for K, lam in ((p.K_a, p.lam_a), (p.K_b, p.lam_b))]
    b = estimate_pair_batch(Ta, p.G * c, Tb, -p.G * c, models[0], models[1], 1.0, n_nodes=n_nodes,
                             pretension=(float(Ta[0]), float(Tb[0])), play=play)
    return b.angle + p.G * c[0] + p.theta0
