"""Friction exponent K and the tension-profile memory of a sheath (its route: :mod:`estimator.geometry`).

The sheath is a chain of straight runs and circular arcs, listed from the proximal (actuator) end to
the distal (instrument) end. Along the tendon the Coulomb-capstan friction bounds the tension
gradient (Phee et al. 2009, eq. (1) in differential form; Agrawal et al. 2010):

    |dT/ds| <= mu * kappa(s) * T(s)      <=>      |d ln T / d theta| <= mu

so the log-tension is mu-Lipschitz in the cumulative wrap angle theta(s) = int_0^s kappa. For a new
proximal tension T_in, every node i of the profile is updated by the envelope rule

    T_i <- min( max(T_i, T_in * exp(-mu theta_i)), T_in * exp(+mu theta_i) )        (profile update)

Nodes that change are slipping; the others stick and keep their memory. The distal node is T_out,
and the elongation is int T / EA ds. This is exact for a rigid sheath, Coulomb friction and a distal
end that does not move while the profile is stuck, for any history of reversals and minor loops.
The paper's four phases (pull, release and the two transitions) are special cases of this rule.

The banded form of the rule, for noisy readings, is :mod:`estimator.band`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from estimator.geometry import SheathGeometry

__all__ = [
    "SheathModel", "envelope_clip", "profile_update", "profile_batch", "pull_elongation_factor",
]


@dataclass(frozen=True)
class SheathModel:
    """What the estimator needs to know of one tendon-sheath transmission.

    Parameters
    ----------
    K : float
        Friction exponent mu * sum(theta) [-], >= 0 (Phee et al. 2009, eq. (2)).
    compliance : float
        Tendon compliance L / EA [m/N], > 0.
    wrap_shape : ndarray, shape (n_shape,), optional
        Normalised cumulative wrap angle theta(s) / theta_total at ``n_shape`` equally spaced points
        from the proximal (0) to the distal end (1); monotone from 0 to 1. ``None`` means constant
        curvature, the paper's assumption.
    """

    K: float
    compliance: float
    wrap_shape: np.ndarray | None = None

    def __post_init__(self) -> None:
        if not (math.isfinite(self.K) and self.K >= 0):
            raise ValueError(f"friction exponent K must be a finite number >= 0, got {self.K!r}")
        if not (math.isfinite(self.compliance) and self.compliance > 0):
            raise ValueError(f"tendon compliance L/EA must be > 0 m/N, got {self.compliance!r}")
        if self.wrap_shape is not None:
            w = np.asarray(self.wrap_shape, dtype=float)
            if w.ndim != 1 or w.size < 2 or np.any(np.diff(w) < -1e-12) or abs(w[0]) > 1e-9 or abs(w[-1] - 1) > 1e-9:
                raise ValueError("wrap_shape must be a monotone 1-D array from 0 to 1 with at least 2 points")

    @classmethod
    def from_geometry(cls, geometry: SheathGeometry, mu: float, EA: float) -> SheathModel:
        """Model of a known route with friction coefficient ``mu`` [-] and axial stiffness ``EA`` [N]."""
        if not (mu >= 0 and math.isfinite(mu)):
            raise ValueError(f"friction coefficient mu must be >= 0, got {mu!r}")
        if not (EA > 0 and math.isfinite(EA)):
            raise ValueError(f"tendon axial stiffness EA must be > 0 N, got {EA!r}")
        shape = None
        if geometry.total_angle > 0:
            s = np.linspace(0.0, geometry.length, 257)
            shape = geometry.wrap_angle(s) / geometry.total_angle
        return cls(K=mu * geometry.total_angle, compliance=geometry.length / EA, wrap_shape=shape)

    def with_K(self, K: float) -> SheathModel:
        """The same route and compliance with another friction exponent."""
        return SheathModel(K=K, compliance=self.compliance, wrap_shape=self.wrap_shape)

    def nodes(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """Discretise the sheath into ``n`` elements (``n + 1`` nodes, equally spaced in arc length).

        Returns
        -------
        log_gain : ndarray, shape (n + 1,)
            mu * theta(s_i) [-] at each node, 0 at the proximal end and K at the distal end.
        weight : ndarray, shape (n + 1,)
            Trapezoid weights [m/N] so that elongation = weight @ T.
        """
        if n < 1:
            raise ValueError(f"the profile needs at least 1 element, got n = {n}")
        u = np.linspace(0.0, 1.0, n + 1)
        if self.wrap_shape is None:
            shape = u
        else:
            shape = np.interp(u, np.linspace(0.0, 1.0, len(self.wrap_shape)), self.wrap_shape)
        weight = np.full(n + 1, self.compliance / n)
        weight[0] *= 0.5
        weight[-1] *= 0.5
        return self.K * shape, weight

    @property
    def M_e(self) -> float:
        """Elongation per proximal tension while pulling [m/N]: M_e = (1/EA) int_0^L exp(-mu theta(s)) ds.

        For constant curvature this is L (1 - e^-K) / (EA K), Phee et al. 2009, eq. (12).
        """
        return self.compliance * pull_elongation_factor(self.K, self.wrap_shape)

    @property
    def reversal_compliance(self) -> float:
        """Proximal travel per newton of reversal tension that crosses the release band [m/N].

        After a pull to ``T_in0`` the distal tension holds until ``T_in`` has fallen to ``T_in0 e^-2K``
        (Phee et al. 2009, Sec. III); meanwhile the distal end stands still and the proximal end moves
        by the change of elongation between the two profiles, ``T_in0 e^-K(s)`` and
        ``T_in0 e^-2K e^+K(s)``::

            dx = T_in0 (1/EA) int_0^L (e^-mu theta(s) - e^-2K e^+mu theta(s)) ds = c_rev T_in0

        so the joint's dead zone after a reversal is ``c_rev T_in0``; for constant curvature
        ``c_rev = M_e (1 - e^-K) = L (1 - e^-K)^2 / (EA K)`` (0 at K = 0: no friction, no band).
        """
        return self.compliance * (pull_elongation_factor(self.K, self.wrap_shape)
                                  - math.exp(-2.0 * self.K) * pull_elongation_factor(-self.K, self.wrap_shape))


def pull_elongation_factor(K: float, wrap_shape: np.ndarray | None = None) -> float:
    """(1/L) int_0^L exp(-K * shape(s)) ds [-]; (1 - e^-K)/K for constant curvature (1 at K = 0; a
    negative K gives the release profile's factor, (e^|K| - 1)/|K|)."""
    if wrap_shape is None:
        return 1.0 if abs(K) < 1e-12 else -math.expm1(-K) / K
    w = np.asarray(wrap_shape, dtype=float)
    f = np.exp(-K * w)
    return float(np.sum(0.5 * (f[1:] + f[:-1])) / (len(w) - 1))


@njit(cache=True, nogil=True, inline="always")
def envelope_clip(t, lo, hi):  # pragma: no cover - compiled
    """A node tension ``t`` [N] kept within its envelope [``lo``, ``hi``] [N] (Phee et al. 2009,
    eq. (1) at one node: it changes only where the new end tension forces it); NaN stays NaN."""
    if t < lo:
        t = lo
    elif t > hi:
        t = hi
    return t


@njit(cache=True, nogil=True)
def profile_update(T, log_gain, T_in):  # pragma: no cover - compiled
    """In-place envelope update of a tension profile; returns the distal tension T[-1] [N].

    T : float64[n + 1] node tensions [N], modified in place.
    log_gain : float64[n + 1] mu * theta at each node.
    T_in : proximal tension [N]; negative values are treated as 0 (a tendon cannot push).
    """
    if T_in < 0.0:
        T_in = 0.0
    for i in range(T.shape[0]):
        g = math.exp(log_gain[i])
        T[i] = envelope_clip(T[i], T_in / g, T_in * g)
    return T[T.shape[0] - 1]


@njit(cache=True, nogil=True)
def _profile_batch(T, lo_gain, hi_gain, weight, T_in, T_out, elong):  # pragma: no cover - compiled
    n = T.shape[0]
    for k in range(T_in.shape[0]):
        t_in = T_in[k]
        if t_in < 0.0:
            t_in = 0.0
        e = 0.0
        for i in range(n):
            t = envelope_clip(T[i], t_in * lo_gain[i], t_in * hi_gain[i])
            T[i] = t
            e += weight[i] * t
        T_out[k] = T[n - 1]
        elong[k] = e


def profile_batch(T0: np.ndarray, log_gain: np.ndarray, weight: np.ndarray, T_in: np.ndarray):
    """Run the profile update over a recorded proximal tension series.

    Parameters
    ----------
    T0 : ndarray, shape (n_nodes,)
        Initial profile [N]; not modified.
    log_gain, weight : ndarray, shape (n_nodes,)
        From :meth:`SheathModel.nodes`.
    T_in : ndarray, shape (n_samples,)
        Proximal tension [N].

    Returns
    -------
    T_out : ndarray, shape (n_samples,)
        Distal tension [N].
    elongation : ndarray, shape (n_samples,)
        Tendon elongation int T/EA ds [m].
    T_final : ndarray, shape (n_nodes,)
        Profile after the last sample [N].
    """
    T = np.array(T0, dtype=np.float64, copy=True)
    T_in = np.ascontiguousarray(T_in, dtype=np.float64)
    T_out = np.empty_like(T_in)
    elong = np.empty_like(T_in)
    g = np.exp(np.asarray(log_gain, dtype=np.float64))
    _profile_batch(T, 1.0 / g, g, np.ascontiguousarray(weight, dtype=np.float64), T_in, T_out, elong)
    return T_out, elong, T
