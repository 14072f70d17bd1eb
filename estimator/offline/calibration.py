"""Joint-limit initialisation (Phee et al. 2009, Sec. IV): M_e and K from proximal signals only.

The joint is pulled against its limit. Before the knee the distal end moves and the proximal
tension rises slowly (load spring); after it the distal end is fixed, so every further proximal
displacement is tendon elongation:

    dx_in = M_e dT_in          beyond the knee, with the profile in full pull slip     eqs. (5)-(12)

(this is e_out / T_in of the paper, read as a slope so that a load carried before the knee does not
bias it). K then solves eq. (13),

    M_e = (1/EA) int_0^L exp(-K theta(s)/theta_total) ds   (= L (1 - e^-K)/(EA K) at constant curvature)

by Newton's method, with L and EA from the tendon's datasheet and, when known, the route shape.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from estimator.capstan import K_from_M_e
from estimator.data import noise_level
from estimator.errors import CalibrationError
from estimator.sheath import SheathModel, pull_elongation_factor

__all__ = ["CalibrationResult", "detect_knee", "calibrate_joint_limit"]


@dataclass(frozen=True)
class CalibrationResult:
    """Outcome of a joint-limit calibration of one tendon.

    K [-], M_e [m/N], knee_index (sample), knee_x_in [m], knee_T_in [N], residual_rms [m] (of the
    post-knee line x_in = M_e T_in + c), n_samples (used after the knee), model (SheathModel), tension_noise [N]
    (the noise sigma of the pull's T_in, :func:`estimator.data.noise_level`: the live estimator's noise band).
    """

    K: float
    M_e: float
    knee_index: int
    knee_x_in: float
    knee_T_in: float
    residual_rms: float
    n_samples: int
    model: SheathModel
    tension_noise: float = 0.0

    def as_dict(self) -> dict:
        return {"K": self.K, "M_e_m_per_N": self.M_e, "knee_index": self.knee_index, "knee_x_in_m": self.knee_x_in,
                "knee_T_in_N": self.knee_T_in, "residual_rms_m": self.residual_rms, "n_samples": self.n_samples,
                "compliance_m_per_N": self.model.compliance, "tension_noise_N": self.tension_noise}


def detect_knee(x_in: np.ndarray, T_in: np.ndarray, max_candidates: int = 400) -> int:
    """Index of the knee of T_in(x_in): the best continuous two-line (hinge) least-squares fit.

    Parameters
    ----------
    x_in, T_in : ndarray, shape (n,) [m], [N], with x_in increasing overall (a pull).

    Raises
    ------
    CalibrationError
        Fewer than 20 samples, or no knee where the slope at least doubles.
    """
    x = np.asarray(x_in, dtype=float)
    T = np.asarray(T_in, dtype=float)
    n = x.size
    if n < 20:
        raise CalibrationError(f"calibration pull has {n} samples; at least 20 are needed")
    lo, hi = int(0.05 * n), int(0.95 * n)
    cand = np.unique(np.linspace(lo, hi, min(max_candidates, hi - lo)).astype(int))
    best, best_sse, best_slopes = -1, math.inf, (0.0, 0.0)
    ones = np.ones(n)
    for k in cand:
        hinge = np.maximum(0.0, x - x[k])
        A = np.column_stack((ones, x, hinge))
        coef, res, *_ = np.linalg.lstsq(A, T, rcond=None)
        sse = float(res[0]) if res.size else float(np.sum((A @ coef - T) ** 2))
        if sse < best_sse:
            best, best_sse, best_slopes = int(k), sse, (coef[1], coef[1] + coef[2])
    before, after = best_slopes
    if not (after > 0 and after > 2.0 * max(before, 0.0)):
        raise CalibrationError(
            f"no joint-limit knee in the calibration pull: tension slope {before:.3g} N/m before and "
            f"{after:.3g} N/m after the best break; pull further into the limit")
    return best


def calibrate_joint_limit(x_in: np.ndarray, T_in: np.ndarray, L: float, EA: float,
                          wrap_shape: np.ndarray | None = None) -> CalibrationResult:
    """Calibrate one tendon from a proximal recording of a pull to the joint limit.

    Parameters
    ----------
    x_in : ndarray, shape (n,)
        Proximal displacement (encoder) [m], during a monotone pull.
    T_in : ndarray, shape (n,)
        Proximal tension (load cell) [N].
    L : float
        Sheath length [m], > 0.
    EA : float
        Tendon axial stiffness [N], > 0.
    wrap_shape : ndarray, optional
        Normalised cumulative wrap angle along the sheath (see :class:`SheathModel`); ``None`` assumes
        constant curvature as the paper does.

    Returns
    -------
    CalibrationResult

    Raises
    ------
    CalibrationError (a ValueError)
        No knee, too few samples beyond it, or M_e EA / L outside (0, 1) (eq. (13) has no solution;
        the message says which physical reading that implies).
    """
    x = np.asarray(x_in, dtype=float)
    T = np.asarray(T_in, dtype=float)
    if x.shape != T.shape or x.ndim != 1:
        raise CalibrationError(f"x_in and T_in must be 1-D of equal length, got {x.shape} and {T.shape}")
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(T))):
        raise CalibrationError("calibration recording has NaN or inf samples")
    if not (L > 0 and EA > 0):
        raise CalibrationError(f"sheath length L and stiffness EA must be > 0, got L={L!r} m, EA={EA!r} N")
    k = detect_knee(x, T)
    # skip a short settling stretch after the knee (the hinge is only a first estimate)
    start = k + max(3, (x.size - k) // 10)
    xs, Ts = x[start:], T[start:]
    if xs.size < 10 or np.ptp(Ts) <= 0:
        raise CalibrationError(f"only {xs.size} samples beyond the joint-limit knee; pull further")
    # x_in = M_e T_in + c beyond the knee
    A = np.column_stack((Ts, np.ones_like(Ts)))
    (M_e, c), *_ = np.linalg.lstsq(A, xs, rcond=None)
    resid = xs - (M_e * Ts + c)
    ratio = M_e * EA / L
    try:
        if wrap_shape is None:
            K = K_from_M_e(M_e, L, EA)
        else:
            if not (0.0 < ratio < 1.0):
                K_from_M_e(M_e, L, EA)  # raises with the physical explanation
            from scipy.optimize import newton  # lazy: the slave loads this module at start-up, rarely solves here

            w = np.asarray(wrap_shape, dtype=float)
            dfac = lambda K: -float(np.mean(0.5 * ((w * np.exp(-K * w))[1:] + (w * np.exp(-K * w))[:-1])))  # noqa: E731
            # convex decreasing in K, so Newton from K = 0 converges monotonically
            K = float(newton(lambda K: pull_elongation_factor(K, w) - ratio, 0.0, fprime=dfac, tol=1e-12, maxiter=200))
    except (ValueError, RuntimeError) as exc:
        raise CalibrationError(f"calibration: {exc}") from None
    model = SheathModel(K=K, compliance=L / EA, wrap_shape=wrap_shape)
    return CalibrationResult(K=K, M_e=float(M_e), knee_index=k, knee_x_in=float(x[k]), knee_T_in=float(T[k]),
                             residual_rms=float(np.sqrt(np.mean(resid ** 2))), n_samples=int(xs.size), model=model,
                             tension_noise=noise_level(T))
