"""Compiled kernel of per-node pre-sliding (E2): a tension-scaled Dahl element on every sheath segment.

The catalogue's first pre-sliding form (:func:`estimator.offline.effects.kernels.travel_lag`) lags the
total friction T_in - T_out in proximal travel. Where the friction sits in a real sheath, each piece
of it pre-slides over its *own* travel, and a piece near a stiff distal load moves only by the strain
of the tendon beyond it: the slip front advances more slowly, the tension change reaches further
along the stuck part, and the distal pieces may never reach their Coulomb bound. This kernel
follows that, quasi-statically (massless tendon), on the profile-memory node grid
(normalised wrap angle u_i, arc length s_i = i/m, i = 0..m):

    segment i (nodes i, i+1): friction F_i = T_i - T_{i+1}, bound |F_i| <= B_i = beta_i (T_i + T_{i+1}) / 2,
        beta_i = 2 tanh(K (u_{i+1} - u_i) / 2)     (the capstan ratio T_{i+1} = T_i e^{-+K du} at the bound)
    travel of node i toward the actuator, in tension units (physical travel / (L/EA)):
        d_i = d_{i+1} + (s_{i+1} - s_i) (T_i + T_{i+1}) / 2 increments,  d_m = rho dT_m (distal load)
    below the bound (Dahl/elasto-plastic, the friction reverses over the travel d_p):
        dF_i = (2 B_i / T_p) (d_i + d_{i+1}) / 2,    T_p = d_p EA / L  [N]
    at the bound while moving that way: F_i = +-B_i.

rho = (EA/L) / k_load is the distal load's compliance relative to the tendon's (0: a fixed end,
inf: a constant force); the kernel takes r = rho / (1 + rho) in [0, 1]. Every sample is one
linear shot from the distal end (all increments are affine in one unknown, fixed by T_in), with
the stick/slip status of each segment found by a few active-set passes. As T_p -> 0 it is the
Coulomb memory of the base model. Elongation per compliance E1 = sum_i w_i phi(T_i) - phi(T0).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from estimator.extended_loop import stiffening_strain
from estimator.offline.effects.kernels import run_extended

__all__ = ["run_node_presliding", "node_presliding", "T_P_MIN", "NODE_FORM"]

#: key of the pre-sliding form in a values dict of the catalogue: 0 the lag of the total friction, 1 per node
NODE_FORM = "presliding_form"
T_P_MIN = 1e-3   # smallest pre-sliding tension [N]; a segment stiffer than the grid resolves is rigid-plastic


# The steps of a sample borrow the kernel's arrays and allocate none: compiled without reference counting
# (_nrt=False), a call costs no atomic increment and decrement per array argument.
@njit(cache=True, nogil=True, _nrt=False)
def _capstan_ratios(bet, u, Kk, m):  # pragma: no cover - compiled
    """Bound ratio beta_i = 2 tanh(K (u_{i+1} - u_i) / 2) of every segment at the friction exponent Kk [-]."""
    for i in range(m):
        bet[i] = 2.0 * math.tanh(0.5 * Kk * (u[i + 1] - u[i]))


@njit(cache=True, nogil=True, _nrt=False)
def _segment_slopes(T, bet, T_p, ds, kk, cc, m):  # pragma: no cover - compiled
    """Coulomb bound cc = B_i [N] of every segment at the sample's start tensions and its pre-sliding slope
    kk = 2 B_i / T_p [N per tension unit of travel], capped at 2 / ds (a segment stiffer than the grid resolves
    is rigid-plastic and the shot's elastic step keeps 1 - k ds / 4 >= 1/2)."""
    for i in range(m):
        B = 0.5 * bet[i] * (T[i] + T[i + 1])
        ki = 2.0 * B / T_p
        if ki * ds > 2.0:
            ki = 2.0 / ds
        kk[i] = ki
        cc[i] = B


@njit(cache=True, nogil=True, _nrt=False)
def _distal_end(k, xd, use_xd, r, aT, bT, ad, bd, m):  # pragma: no cover - compiled
    """Increments (dT_m, d_m) = (aT_m + bT_m x, ad_m + bd_m x) of the distal node at sample k, affine in the one
    unknown x: the distal end travels as measured (xd) or its load yields by the compliance share r."""
    aT[m] = 0.0
    if use_xd:
        bT[m] = 1.0
        ad[m] = xd[k] - xd[k - 1] if k > 0 else 0.0
        bd[m] = 0.0
    else:
        bT[m] = 1.0 - r
        ad[m] = 0.0
        bd[m] = r


@njit(cache=True, nogil=True, _nrt=False)
def _shoot(top, st, kk, cc, bet, F, ds, aT, bT, ad, bd):  # pragma: no cover - compiled
    """Shoot from the distal end: the increments (dT_i, d_i) = (aT_i + bT_i x, ad_i + bd_i x) of the nodes through
    the segments ``top`` down to 0, elastic or at their bound; the nodes beyond ``top`` are as the last pass left
    them."""
    for i in range(top, -1, -1):
        if st[i] == 0:
            # dT_i - dT_{i+1} = k d_{i+1} + (k ds / 4)(dT_i + dT_{i+1})
            h = 0.25 * kk[i] * ds
            den = 1.0 / (1.0 - h)       # a reciprocal: the shot's chain of dependent steps holds no division
            aT[i] = ((1.0 + h) * aT[i + 1] + kk[i] * ad[i + 1]) * den
            bT[i] = ((1.0 + h) * bT[i + 1] + kk[i] * bd[i + 1]) * den
        else:
            # F_i + dF_i = s beta (Tbar + dTbar): dT_i (1 - s beta/2) = dT_{i+1} (1 + s beta/2) + c
            sb = 0.5 * st[i] * bet[i]
            c = st[i] * cc[i] - F[i]
            den = 1.0 / (1.0 - sb)
            aT[i] = ((1.0 + sb) * aT[i + 1] + c) * den
            bT[i] = (1.0 + sb) * bT[i + 1] * den
        ad[i] = ad[i + 1] + 0.5 * ds * (aT[i] + aT[i + 1])
        bd[i] = bd[i + 1] + 0.5 * ds * (bT[i] + bT[i + 1])


@njit(cache=True, nogil=True, _nrt=False)
def _segment_status(x, T, F, st, kk, bet, aT, bT, ad, bd, m):  # pragma: no cover - compiled
    """Move each segment between elastic and at its bound by its travel and trial friction under the shot's x: an
    elastic segment past its bound in the direction it moves reaches it, one at the bound that moves back sticks.
    Returns the most distal segment whose status changed (-1: none)."""
    top = -1
    for i in range(m):
        dTi = aT[i] + bT[i] * x
        dTn = aT[i + 1] + bT[i + 1] * x
        trav = 0.5 * (ad[i] + ad[i + 1] + (bd[i] + bd[i + 1]) * x)
        Bn = 0.5 * bet[i] * (T[i] + dTi + T[i + 1] + dTn)
        if st[i] == 0:
            Fn = F[i] + kk[i] * trav
            if Fn > Bn and trav > 0.0:
                st[i] = 1
                top = i
            elif Fn < -Bn and trav < 0.0:
                st[i] = -1
                top = i
        elif trav * st[i] < 0.0:
            st[i] = 0
            top = i
    return top


@njit(cache=True, nogil=True, _nrt=False)
def _apply_increments(x, T, F, aT, bT, bet, w, beta, Tc, m):  # pragma: no cover - compiled
    """Take the sample's increments: node tensions (a tendon cannot push), segment frictions clipped to their new
    bounds. Returns the weighted strain sum_i w_i phi(T_i) [N]."""
    E = 0.0
    for i in range(m + 1):
        Ti = T[i] + aT[i] + bT[i] * x
        if Ti < 0.0:
            Ti = 0.0
        T[i] = Ti
    for i in range(m):
        Bn = 0.5 * bet[i] * (T[i] + T[i + 1])
        f = T[i] - T[i + 1]
        if f > Bn:
            f = Bn
        elif f < -Bn:
            f = -Bn
        F[i] = f
    for i in range(m + 1):
        E += w[i] * stiffening_strain(T[i], beta, Tc)
    return E


@njit(cache=True, nogil=True)
def _node_kernel(T_in, t, u, w, K, K_rate, T_p, r, T0, beta, Tc, xd, T_out, E1):  # pragma: no cover - compiled
    """Per-node pre-sliding over the samples of ``T_in`` (module docstring): T_out [N] and E1 [N] of each sample."""
    m1 = u.shape[0]
    m = m1 - 1
    T = np.full(m1, T0)
    F = np.zeros(m)
    st = np.zeros(m, np.int64)          # 0 elastic, +1 / -1 at the bound moving toward / away from the actuator
    ds = 1.0 / m
    aT = np.empty(m1)
    bT = np.empty(m1)
    ad = np.empty(m1)
    bd = np.empty(m1)
    bet = np.empty(m)
    kk = np.empty(m)
    cc = np.empty(m)
    E0 = stiffening_strain(T0, beta, Tc)
    use_xd = xd.shape[0] == T_in.shape[0]
    for k in range(T_in.shape[0]):
        if k == 0 or K_rate != 0.0:         # the segments' capstan ratios change only with a drifting K
            Kk = K + K_rate * (t[k] - t[0])
            if Kk < 0.0:
                Kk = 0.0
            _capstan_ratios(bet, u, Kk, m)
        Tp = T_in[k]
        if Tp < 0.0:
            Tp = 0.0
        _segment_slopes(T, bet, T_p, ds, kk, cc, m)
        dT0 = Tp - T[0]
        top = m - 1                     # the most distal segment whose status changed: the shot starts there
        _distal_end(k, xd, use_xd, r, aT, bT, ad, bd, m)      # the shot's start: the passes leave node m as it is
        for _ in range(8):
            _shoot(top, st, kk, cc, bet, F, ds, aT, bT, ad, bd)
            x = (dT0 - aT[0]) / bT[0] if bT[0] != 0.0 else 0.0
            top = _segment_status(x, T, F, st, kk, bet, aT, bT, ad, bd, m)
            if top < 0:
                break
        E = _apply_increments(x, T, F, aT, bT, bet, w, beta, Tc, m)
        T_out[k] = T[m]
        E1[k] = E - E0


def run_node_presliding(T_in: np.ndarray, time: np.ndarray, u: np.ndarray, w: np.ndarray, *, K: float,
                        T_p: float, r: float = 0.0, distal: np.ndarray | None = None, K_rate: float = 0.0,
                        T0: float = 0.0, beta: float = 0.0, Tc: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Run the per-node pre-sliding model over a recording (module docstring for the equations).

    Parameters
    ----------
    T_in : ndarray, shape (n,)
        Proximal tension [N] (after any sensor correction); negative values count as 0.
    time : ndarray, shape (n,)
        Sample times [s].
    u, w : ndarray, shape (m + 1,)
        Normalised wrap angle of the nodes (0 to 1, equally spaced in arc length) and trapezoid weights.
    K : float
        Friction exponent [-] >= 0; K_rate its drift [1/s] (E6).
    T_p : float
        Pre-sliding tension d_p EA / L [N], >= :data:`T_P_MIN`.
    r : float in [0, 1]
        Distal load compliance share rho / (1 + rho), rho = (EA/L) / k_load (0 fixed end, 1 constant force).
    T0, beta, Tc : float
        Initial uniform tension [N] (E5) and tendon stiffening (E9, see ``stiffening_strain``).

    Returns
    -------
    (T_out [N], E1 [N]), shape (n,) each; elongation = (L/EA) E1, zero in the initial state.

    Raises
    ------
    ValueError
        T_p below T_P_MIN or r outside [0, 1].
    """
    if not T_p >= T_P_MIN:
        raise ValueError(f"T_p must be >= {T_P_MIN} N, got {T_p!r}")
    if not 0.0 <= r <= 1.0:
        raise ValueError(f"r must be in [0, 1], got {r!r}")
    T_in = np.ascontiguousarray(T_in, dtype=np.float64)
    T_out = np.empty_like(T_in)
    E1 = np.empty_like(T_in)
    _node_kernel(T_in, np.ascontiguousarray(time, dtype=np.float64), np.ascontiguousarray(u, dtype=np.float64),
                 np.ascontiguousarray(w, dtype=np.float64), float(K), float(K_rate), float(T_p), float(r),
                 float(T0), float(beta), float(Tc),
                 np.empty(0) if distal is None else np.ascontiguousarray(distal, dtype=np.float64), T_out, E1)
    return T_out, E1


def node_presliding(T_in: np.ndarray, x_in: np.ndarray, x_out: np.ndarray | None, time: np.ndarray, u: np.ndarray,
                    w: np.ndarray, *, x_p: float, compliance: float | None, K: float, K_rate: float = 0.0,
                    T0: float = 0.0, beta: float = 0.0, Tc: float = 1.0,
                    stop: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Per-node pre-sliding over a recording with the pre-sliding travel ``x_p`` [m] as its parameter.

    T_p = x_p / (L/EA), and the distal end travels as the measured ``x_out`` [m] (the distal load's
    own law, whatever it is; None: a fixed end). Without a known ``compliance`` L/EA [m/N] it is
    estimated from the Coulomb memory (T_p -> 0) by linear least squares of x_in - x_out on E1 over the whole
    recording; it sets T_p and the distal travel of the pass that is returned (the caller refits L/EA on its E1).
    Arrays shape (n,); u, w the node grid. ``stop``: the returned pass runs over the first ``stop`` samples only
    (the same values there). Returns (T_out [N], E1 [N]), shape (stop,) (default (n,)).

    Raises
    ------
    ValueError
        No compliance and no x_out (L/EA cannot be estimated), or x_p <= 0.
    """
    if not x_p > 0.0:
        raise ValueError(f"x_p must be > 0 m, got {x_p!r}")
    if compliance is None and x_out is None:
        raise ValueError("node pre-sliding needs the compliance L/EA or a measured x_out")
    kw = {"K": K, "K_rate": K_rate, "T0": T0, "beta": beta, "Tc": Tc}
    n = T_in.shape[0] if stop is None else min(stop, T_in.shape[0])

    def run(c: float) -> tuple[np.ndarray, np.ndarray]:
        c = max(c, 1e-12)
        distal = None if x_out is None else (x_out[:n] - x_out[0]) / c
        return run_node_presliding(T_in[:n], time[:n], u, w, T_p=max(x_p / c, T_P_MIN), distal=distal, **kw)

    if compliance is not None:
        return run(compliance)
    assert x_out is not None
    return run(_coulomb_compliance(T_in, x_in, x_out, time, u, w, kw))


#: the last few Coulomb-memory compliances of :func:`node_presliding`: (inputs, L/EA [m/N])
_COULOMB: list[tuple[tuple, float]] = []


def _coulomb_compliance(T_in: np.ndarray, x_in: np.ndarray, x_out: np.ndarray, time: np.ndarray, u: np.ndarray,
                        w: np.ndarray, kw: dict) -> float:
    """L/EA [m/N] of the Coulomb memory (T_p -> 0, a fixed end) by linear least squares of x_in - x_out on its
    E1. The Coulomb memory is the base model's profile memory (:func:`estimator.offline.effects.kernels.run_extended`,
    exact inputs, no band), which the per-node kernel approaches as T_p -> 0 (their L/EA agree to 1e-3 at
    T_P_MIN) at a tenth of its cost. A fit varies x_p far more often than the memory's own parameters: the last few
    are kept, by the identity of the (read-only) input arrays and the values of the others."""
    arrays = (T_in, x_in, x_out, time, w)
    key = (u.tobytes(), tuple(sorted(kw.items())))
    for inputs, c in _COULOMB:
        if inputs[1] == key and all(a is b for a, b in zip(inputs[0], arrays, strict=True)):
            return c
    _, E = run_extended(T_in, np.gradient(x_in, time), time, u, w, **kw)
    den = float(E @ E)
    c = float(E @ (x_in - x_out)) / den if den > 0 else 0.0
    _COULOMB.insert(0, ((arrays, key), c))
    del _COULOMB[4:]
    return c
