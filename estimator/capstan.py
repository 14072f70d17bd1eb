"""Closed forms of the seed paper for a sheath of constant curvature, vectorised over numpy arrays.

Phee, Low, Valdastri, Menciassi, Dario, "Tendon sheath analysis for estimation of distal end force
and elongation", IEEE/ASME AIM 2009. Symbols (defined in docs/concepts/model.md):

    K    = mu * sum((x_i - x_{i-1}) / R_i)      friction exponent [-]                      eq. (2)
    T_in, T_out                                  proximal, distal tension [N]
    L, EA                                        sheath length [m], tendon axial stiffness [N]
    M_e  = L (1 - e^-K) / (EA K)                 elongation per proximal tension [m/N]      eq. (12)

The four phases and their laws (full slip after a reversal from full slip):

    pull            T_out = T_in e^-K                          e = M_e T_in                     eqs. (1), (5)-(12)
    pull->release   T_out = T_in0 e^-K  while T_in > T_in0 e^-2K                                eqs. (14)-(21)
                    e = L/(EA K) (2 sqrt(T_in T_in0) - T_in - T_in0 e^-K)
    release         T_out = T_in e^+K                          e = L (e^K - 1)/(EA K) T_in       eq. (22)
    release->pull   T_out = T_in0 e^+K  while T_in < T_in0 e^+2K                                eqs. (24)-(25)
                    e = L/(EA K) (T_in - 2 sqrt(T_in T_in0) + T_in0 e^K)

The transition elongations follow from the profile min(T_in0 e^{-ks}, T_in e^{+ks}) (and its mirror)
with k = K/L. These formulas are exact for one reversal from full slip; :class:`PhaseFormulaEstimator`
chains them with the paper's "tension at the last reversal" state, which is wrong after minor loops
(docs/concepts/model.md, the tension-profile memory) - the profile-memory estimator in :mod:`estimator.online.distal` is
not.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from estimator.phase import Phase

__all__ = [
    "t_out_pull", "t_out_release", "elongation_factor", "M_e", "elongation_pull", "elongation_release",
    "elongation_pull_to_release", "elongation_release_to_pull", "K_from_M_e", "PhaseFormulaEstimator",
    "phase_formula_batch",
]


def _check_K(K: float) -> None:
    if not (K >= 0 and math.isfinite(K)):
        raise ValueError(f"friction exponent K must be a finite number >= 0, got {K!r}")


def t_out_pull(T_in, K: float):
    """Distal tension while pulling in full slip [N], T_out = T_in e^-K (eq. (1)). ``T_in`` any shape [N]."""
    _check_K(K)
    return np.asarray(T_in, dtype=float) * math.exp(-K)


def t_out_release(T_in, K: float):
    """Distal tension while releasing in full slip [N], T_out = T_in e^+K (eq. (22)). ``T_in`` any shape [N]."""
    _check_K(K)
    return np.asarray(T_in, dtype=float) * math.exp(K)


def elongation_factor(K: float) -> float:
    """(1 - e^-K) / K [-], the fraction of L that a pulled tendon stretches as if loaded by T_in (1 at K = 0)."""
    _check_K(K)
    return 1.0 if K < 1e-12 else -math.expm1(-K) / K


def M_e(K: float, L: float, EA: float) -> float:
    """Elongation per proximal tension while pulling [m/N], M_e = L (1 - e^-K) / (EA K) (eq. (12))."""
    if not (L > 0 and EA > 0):
        raise ValueError(f"sheath length L and stiffness EA must be > 0, got L={L!r} m, EA={EA!r} N")
    return L / EA * elongation_factor(K)


def _coef(K: float, compliance: float) -> float:
    """L/(EA K) with its K -> 0 limit handled by the callers' formulas."""
    return compliance / max(K, 1e-12)


def elongation_pull(T_in, K: float, compliance: float):
    """Elongation while pulling in full slip [m], e = M_e T_in (eqs. (5)-(12)). ``compliance`` = L/EA [m/N]."""
    return np.asarray(T_in, dtype=float) * compliance * elongation_factor(K)


def elongation_release(T_in, K: float, compliance: float):
    """Elongation while releasing in full slip [m], e = L (e^K - 1)/(EA K) T_in (release branch of eq. (22))."""
    _check_K(K)
    f = 1.0 if K < 1e-12 else math.expm1(K) / K
    return np.asarray(T_in, dtype=float) * compliance * f


def elongation_pull_to_release(T_in, T_in0, K: float, compliance: float):
    """Elongation in the pull->release transition [m] (eqs. (14)-(21)).

    Valid for T_in0 e^-2K <= T_in <= T_in0, after a full pull to ``T_in0`` [N].
    """
    T_in = np.asarray(T_in, dtype=float)
    if K < 1e-12:
        return T_in * compliance
    return _coef(K, compliance) * (2.0 * np.sqrt(T_in * T_in0) - T_in - T_in0 * math.exp(-K))


def elongation_release_to_pull(T_in, T_in0, K: float, compliance: float):
    """Elongation in the release->pull transition [m] (eqs. (24)-(25)).

    Valid for T_in0 <= T_in <= T_in0 e^2K, after a full release to ``T_in0`` [N].
    """
    T_in = np.asarray(T_in, dtype=float)
    if K < 1e-12:
        return T_in * compliance
    return _coef(K, compliance) * (T_in - 2.0 * np.sqrt(T_in * T_in0) + T_in0 * math.exp(K))


def K_from_M_e(M_e_value: float, L: float, EA: float) -> float:
    """Solve eq. (13), M_e = L (1 - e^-K) / (EA K), for K by Newton's method.

    Raises
    ------
    ValueError
        When r = M_e EA / L is outside (0, 1): no K >= 0 gives it. r >= 1 means the measured
        compliance exceeds that of the bare tendon (sheath compression, slack, a wrong L or EA);
        r <= 0 means no stretch was measured.
    """
    if not (L > 0 and EA > 0):
        raise ValueError(f"sheath length L and stiffness EA must be > 0, got L={L!r} m, EA={EA!r} N")
    r = M_e_value * EA / L
    if not (0.0 < r < 1.0):
        why = ("more compliant than the bare tendon L/EA: sheath compression, slack or a wrong L or EA"
               if r >= 1.0 else "no positive stretch was measured")
        raise ValueError(f"M_e * EA / L = {r:.4g} is outside (0, 1): {why}; cannot solve eq. (13) for K")
    from scipy.optimize import newton  # lazy: every process that builds the command line imports this module

    f = lambda K: elongation_factor(K) - r  # noqa: E731
    fprime = lambda K: (math.exp(-K) * (K + 1.0) - 1.0) / (K * K) if K > 1e-6 else -0.5 + K / 3.0  # noqa: E731
    # (1 - e^-K)/K is convex and decreasing: Newton from K = 0 climbs monotonically to the root.
    return float(newton(f, 0.0, fprime=fprime, tol=1e-12, maxiter=200))


class PhaseFormulaEstimator:
    """The seed paper's estimator: phase detection plus the closed forms above.

    The state is the phase and T_in0, the proximal tension at the last reversal. A reversal is
    declared when T_in moves back by more than ``deadband`` [N] from its running extremum, so that
    sensor noise does not flip the phase. After a reversal T_out is held until T_in has crossed the
    band T_in0 e^-+2K (eqs. (14)-(21), (24)-(25)); a new reversal inside the band restarts the
    transition from the current T_in (the paper's rule - this is what fails on minor loops).

    Parameters
    ----------
    K : float, >= 0 ; compliance : float, L/EA [m/N] > 0 ; deadband : float [N] >= 0.
    """

    def __init__(self, K: float, compliance: float, deadband: float = 0.1, T0: float = 0.0):
        _check_K(K)
        self.K, self.compliance, self.deadband = float(K), float(compliance), float(deadband)
        self.eK = math.exp(self.K)
        self.phase = Phase.PULL
        self.T_in0 = T0            # tension at the last reversal [N]
        self.extremum = T0         # running max (pull branch) or min (release branch) [N]
        self.T_out = T0 * math.exp(-self.K)
        self.held = self.T_out

    def step(self, T_in: float) -> tuple[float, float, Phase]:
        """Advance one sample: proximal tension [N] -> (T_out [N], elongation [m], phase)."""
        T_in = max(float(T_in), 0.0)
        K, c, eK, ph = self.K, self.compliance, self.eK, self.phase
        rising = ph in (Phase.PULL, Phase.RELEASE_TO_PULL)
        if rising:
            if T_in >= self.extremum:
                self.extremum = T_in
            elif T_in < self.extremum - self.deadband:       # reversal: start pull->release
                self.T_in0, self.held, self.extremum = self.extremum, self.T_out, T_in
                ph = Phase.PULL_TO_RELEASE
        else:
            if T_in <= self.extremum:
                self.extremum = T_in
            elif T_in > self.extremum + self.deadband:       # reversal: start release->pull
                self.T_in0, self.held, self.extremum = self.extremum, self.T_out, T_in
                ph = Phase.RELEASE_TO_PULL
        if ph == Phase.PULL_TO_RELEASE and T_in < self.T_in0 / (eK * eK):
            ph = Phase.RELEASE
        elif ph == Phase.RELEASE_TO_PULL and T_in > self.T_in0 * eK * eK:
            ph = Phase.PULL
        self.phase = ph
        T0 = self.T_in0
        # on a branch, T_in inside the deadband behind the running extremum counts as the extremum
        if ph == Phase.PULL:
            T = self.extremum
            self.T_out, e = T / eK, float(elongation_pull(T, K, c))
        elif ph == Phase.RELEASE:
            T = self.extremum
            self.T_out, e = T * eK, float(elongation_release(T, K, c))
        elif ph == Phase.PULL_TO_RELEASE:
            self.T_out = self.held
            e = float(elongation_pull_to_release(min(T_in, T0), T0, K, c))
        else:
            self.T_out = self.held
            e = float(elongation_release_to_pull(max(T_in, T0), T0, K, c))
        return self.T_out, e, ph


# Compiled twin of PhaseFormulaEstimator.step (the same state machine; tests keep them equal).
@njit(cache=True)
def _phase_kernel(T_in, K, deadband, T0, T_out, e1, phase):  # pragma: no cover - compiled
    eK = math.exp(K)
    small = K < 1e-12
    f_pull = 1.0 if small else -math.expm1(-K) / K
    f_rel = 1.0 if small else math.expm1(K) / K
    coef = 1.0 / max(K, 1e-12)
    ph = 1                                     # PULL
    T_in0 = T0
    ext = T0
    tout = T0 * math.exp(-K)
    held = tout
    for k in range(T_in.shape[0]):
        t = max(T_in[k], 0.0)
        if ph == 1 or ph == 4:                 # rising branch
            if t >= ext:
                ext = t
            elif t < ext - deadband:           # reversal: pull -> release
                T_in0, held, ext, ph = ext, tout, t, 3
        else:
            if t <= ext:
                ext = t
            elif t > ext + deadband:           # reversal: release -> pull
                T_in0, held, ext, ph = ext, tout, t, 4
        if ph == 3 and t < T_in0 / (eK * eK):
            ph = 2
        elif ph == 4 and t > T_in0 * eK * eK:
            ph = 1
        # on a branch, T_in inside the deadband behind the running extremum counts as the extremum
        if ph == 1:                            # eqs. (1), (12)
            tout = ext / eK
            e = ext * f_pull
        elif ph == 2:                          # eq. (22)
            tout = ext * eK
            e = ext * f_rel
        elif ph == 3:                          # eqs. (14)-(21)
            tout = held
            tt = min(t, T_in0)
            e = tt if small else coef * (2.0 * math.sqrt(tt * T_in0) - tt - T_in0 * math.exp(-K))
        else:                                  # eqs. (24)-(25)
            tout = held
            tt = max(t, T_in0)
            e = tt if small else coef * (tt - 2.0 * math.sqrt(tt * T_in0) + T_in0 * eK)
        T_out[k] = tout
        e1[k] = e
        phase[k] = ph



def phase_formula_batch(T_in: np.ndarray, K: float, compliance: float, deadband: float = 0.1, T0: float = 0.0):
    """The paper's phase formulas over a recording: :class:`PhaseFormulaEstimator`, compiled.

    Parameters
    ----------
    T_in : ndarray, shape (n,)
        Proximal tension [N].
    K : float, >= 0 ; compliance : float, L/EA [m/N] ; deadband : float [N] ; T0 : float, initial tension [N]

    Returns
    -------
    T_out : ndarray, shape (n,) [N] ; elongation : ndarray, shape (n,) [m] ; phase : ndarray of int8, shape (n,)
    """
    _check_K(K)
    T_in = np.ascontiguousarray(T_in, dtype=np.float64)
    T_out, e1 = np.empty_like(T_in), np.empty_like(T_in)
    phase = np.empty(T_in.size, dtype=np.int8)
    _phase_kernel(T_in, float(K), float(deadband), float(T0), T_out, e1, phase)
    return T_out, e1 * compliance, phase
