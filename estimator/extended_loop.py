"""The sample loop of the extended profile-memory model, on a state passed in: one compiled loop for the batch
model and its per-cycle form.

:func:`run_span` runs the samples [i0, i1) of a proximal series on a state that :func:`start_extended` fills and
every call updates in place: the offline study's batch kernel (``estimator.offline.effects.kernels.run_extended``)
runs it once over a recording, the per-cycle estimator (:class:`estimator.online.extended.ExtendedEstimator`) once
per sample on the same state, so the two give the same numbers to the last bit on the same inputs. The equations
(the memory rule, the whole-tendon slide, static friction and its breakaway, drift, viscous friction, the
tension-independent friction a, pretension, the stiffening strain phi, the friction step) are those of the batch
kernel's docstring (docs/concepts/effects.md, E3-E6, E8, E9).

State layout (m1 nodes, proximal to distal):

* ``par``  float64 (:data:`N_PAR`,): the parameters at the ``P_*`` indices (read only);
* ``Y``    float64 (m1,): the profile Y_i = T_i + a [N];
* ``st``   float64 (:data:`N_ST`,): the scalars at the ``S_*`` indices (elongation sums, slide direction,
  breakaway time, previous proximal tension and time, the time origin of the drift, samples run);
* ``tab``  float64 (3, m1): the kinetic and static bounds e^{-K u_i}, e^{+K u_i}, e^{-K (1 + r_s) u_i} (read only);
* ``dY``, ``G`` float64 (m1,): scratch of the Stribeck form.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["V_STOP", "NODE_ROUNDING", "BREAK_MARGIN", "stiffening_strain", "friction_bounds", "start_extended",
           "run_span", "N_PAR", "N_ST", "P_K", "P_A", "P_T0", "P_K_RATE", "P_C_V", "P_R_S", "P_T_SLIP", "P_T_MIN",
           "P_SIGMA", "P_BETA", "P_TC", "P_V_ST", "P_BAND", "P_K_STEP", "P_T_STEP",
           "S_E", "S_E0", "S_SLIDING", "S_T_B", "S_YP_PREV", "S_T_ORIGIN", "S_T_PREV", "S_COUNT", "S_K_PROFILE"]

V_STOP = 2e-4        # proximal speed below which a slide ends (the tendon sticks) [m/s]
#: [-] a node of a stuck tendon whose bound it would move to lies within this share of its tension does not move.
#: A node latched on its bound sits there to rounding, and the bound computed again (e^{-K u} tabulated, or from a
#: drifting K) may fall an ulp either side of it: without the margin an ulp decides whether the slip reaches the distal
#: end and the whole tendon slides, so the model jumps between K_rate = 0 and any K_rate near it (the drift's fit,
#: started at 0, then sees no gradient)
NODE_ROUNDING = 1e-12
BREAK_MARGIN = 0.35  # share of the kinetic-static gap within which a turn of T_in counts as breakaway [-]

#: indices of ``par``: K [-], a [N], T0 [N], K_rate [1/s], c_v [s/m], r_s [-], t_slip [s], T_min [N], sigma [N],
#: beta [-], Tc [N], v_st [m/s], band [N], the friction step dK [-] and its instant t_s [s] from the first sample run
(P_K, P_A, P_T0, P_K_RATE, P_C_V, P_R_S, P_T_SLIP, P_T_MIN, P_SIGMA, P_BETA, P_TC, P_V_ST, P_BAND, P_K_STEP,
 P_T_STEP) = range(15)
N_PAR = 15
#: indices of ``st``: the running sum E [N] and its start E0 [N], the slide direction (-1, 0, +1), the breakaway
#: time t_b [s] (-inf: none), the previous proximal Y_p [N] and time [s], the drift's time origin [s], samples run,
#: and the steepest friction exponent the profile was written with since it last held everywhere at a lower one [-]
S_E, S_E0, S_SLIDING, S_T_B, S_YP_PREV, S_T_ORIGIN, S_T_PREV, S_COUNT, S_K_PROFILE = range(9)
N_ST = 9


@njit(cache=True, nogil=True)
def stiffening_strain(T, beta, Tc):  # pragma: no cover - compiled
    """phi(T) [N]: tension-equivalent strain of a stiffening tendon, T + beta T_c (1 - e^{-T/T_c})
    (T when beta = 0); elongation = (L/EA) int phi(T) ds. Used by the estimator and the simulated rig."""
    if beta == 0.0:
        return T
    return T - beta * Tc * math.expm1(-T / Tc)


@njit(cache=True, nogil=True)
def friction_bounds(u, K, r_s, tab):  # pragma: no cover - compiled
    """Fill ``tab`` (3, m1) with the kinetic and static bounds of the friction exponent ``K`` [-] at the nodes'
    normalised wrap angle ``u`` (m1,): e^{-K u_i}, e^{+K u_i}, e^{-K (1 + r_s) u_i} (module docstring)."""
    g_kin = np.exp(-K * u)          # the batch kernel's own array expressions: the same bits
    tab[0, :] = g_kin
    tab[1, :] = 1.0 / g_kin
    tab[2, :] = np.exp(-K * (1.0 + r_s) * u)


@njit(cache=True, nogil=True)
def start_extended(u, w, par, T0_out, Y, st, tab):  # pragma: no cover - compiled
    """Fill the state (module docstring) at rest: the profile uniform at T0 [N], or, given the distal rest reading
    ``T0_out`` [N] >= 0 with T0 > 0, capped by the friction band above it, min(T0, T0_out e^{K (1 - u_i)}) (< 0:
    uniform); no slide, no breakaway, nothing run. ``u``, ``w`` (m1,): the nodes' normalised wrap angle and
    trapezoid weights."""
    m1 = u.shape[0]
    K, a, T0, beta, Tc, r_s = par[P_K], par[P_A], par[P_T0], par[P_BETA], par[P_TC], par[P_R_S]
    for i in range(m1):
        Y[i] = T0 + a
    E0 = stiffening_strain(T0, beta, Tc)
    st[S_K_PROFILE] = 0.0           # uniform: it holds at any friction
    if T0 > 0.0 and T0_out >= 0.0:
        st[S_K_PROFILE] = K
        E0 = 0.0
        for i in range(m1):
            y = min(T0, T0_out * math.exp(K * (1.0 - u[i])))
            Y[i] = y + a
            E0 += w[i] * stiffening_strain(y, beta, Tc)
    friction_bounds(u, K, r_s, tab)
    st[S_E] = E0
    st[S_E0] = E0
    st[S_SLIDING] = 0.0
    st[S_T_B] = -math.inf
    st[S_YP_PREV] = Y[0]
    st[S_T_ORIGIN] = 0.0
    st[S_T_PREV] = 0.0
    st[S_COUNT] = 0.0


@njit(cache=True, nogil=True)
def _write_slide(Y, Yp, g, a):  # pragma: no cover - compiled
    """The profile of a whole-tendon slide at the tabulated bound ``g`` (m1,): Y_i = max(Y_p g_i, a)."""
    for i in range(Y.shape[0]):
        y = Yp * g[i]
        Y[i] = y if y >= a else a


#: [count] rows of the bound tables of a friction that steps (:func:`_bound_row`): each K level's kinetic bound both
#: ways and its static bound
N_ROWS = 8


@njit(cache=True, nogil=True)
def _bound_row(c, u, keys, rows):  # pragma: no cover - compiled
    """The row of ``rows`` (N_ROWS, m1) that holds e^{c u_i} for the exponent coefficient ``c`` [-], computed as the
    untabulated bound is (the same bits): the bounds of a friction that steps, whose K takes two values. A new ``c``
    replaces the oldest row. ``keys`` (N_ROWS + 1,): each row's c (NaN: none), then the next row to replace."""
    n = rows.shape[0]
    for j in range(n):
        if keys[j] == c:
            return j
    j = int(keys[n])
    keys[n] = float((j + 1) % n)
    keys[j] = c
    for i in range(rows.shape[1]):
        rows[j, i] = math.exp(c * u[i])
    return j


@njit(cache=True, nogil=True)
def _stribeck_bound(Y, Yp, a, u, w, Kk, r_s, v_st, vp, dY, G, g_kin, varying):  # pragma: no cover - compiled
    """Cumulative friction exponent G_i of a stuck tendon whose nodes near the proximal end slip (Stribeck form);
    ``g_kin`` the tabulated kinetic bounds e^{-K u_i}, used where K does not vary (``varying`` False).

    A kinetic trial update gives the slip zone and each node's change of tension dY_i; a node's sliding
    speed is the proximal speed vp times the share of the slip zone's stretch change beyond it (the
    distal part of the zone feeds the node's travel; 0 at the slip front and beyond). Node i's bound is
    K (1 + r_s e^-(v_i/v_st)^2) per unit of wrap angle: static at rest, kinetic well above v_st."""
    m1 = u.shape[0]
    tot = 0.0
    nf = -1
    for i in range(m1):
        g = math.exp(-Kk * u[i]) if varying else g_kin[i]
        y = Y[i]
        lo = Yp * g
        hi = Yp / g
        if hi < a:
            hi = a
        if y < lo:
            d = lo - y
        elif y > hi:
            d = y - hi
        else:
            break
        dY[i] = w[i] * d
        tot += dY[i]
        nf = i
    beyond = 0.0
    still = Kk * (1.0 + r_s)            # the bound of a node at rest (e^-0 = 1)
    for i in range(m1 - 1, -1, -1):
        if i <= nf and tot > 0.0:       # in the slip zone; the proximal node moves with the proximal end
            vi = vp if i == 0 else vp * beyond / tot
            beyond += dY[i]
            G[i] = Kk * (1.0 + r_s * math.exp(-(vi / v_st) ** 2))     # the node's bound, per wrap angle
        else:
            G[i] = still
    acc = 0.0
    prev = G[0]
    for i in range(m1):
        if i > 0:
            acc += 0.5 * (G[i] + prev) * (u[i] - u[i - 1])
        prev = G[i]
        G[i] = acc if i > 0 else 0.0
    return nf


@njit(cache=True, nogil=True)
def run_span(T_in, v, spd, t, slide, i0, i1, u, w, par, Y, st, tab, dY, G, T_out, E1):  # pragma: no cover
    """Run the samples [i0, i1) on the state (module docstring), updated in place: proximal tension ``T_in`` [N],
    velocity ``v`` [m/s], sliding speed ``spd`` [m/s] >= 0 and time ``t`` [s], shape (n,); ``slide`` int8 (n,)
    the direction the measured distal end is seen moving (an empty array: not used). Writes the distal tension
    ``T_out[k]`` [N] and the elongation per compliance ``E1[k]`` [N] (zero in the initial state) of every sample."""
    m1 = u.shape[0]
    K, a, K_rate, c_v, r_s = par[P_K], par[P_A], par[P_K_RATE], par[P_C_V], par[P_R_S]
    t_slip, T_min, sigma, beta, Tc = par[P_T_SLIP], par[P_T_MIN], par[P_SIGMA], par[P_BETA], par[P_TC]
    v_st, band, K_step, t_step = par[P_V_ST], par[P_BAND], par[P_K_STEP], par[P_T_STEP]
    g_kin, g_kin_inv, g_sta = tab[0], tab[1], tab[2]
    E, E0 = st[S_E], st[S_E0]
    sliding = int(st[S_SLIDING])
    t_b, Yp_prev, t_prev = st[S_T_B], st[S_YP_PREV], st[S_T_PREV]
    count = int(st[S_COUNT])
    K_prof = st[S_K_PROFILE]
    if count == 0 and i1 > i0:
        st[S_T_ORIGIN] = t[i0]          # the drift counts from the first sample run
    t0 = st[S_T_ORIGIN]
    varying = K_rate != 0.0 or c_v != 0.0 or K_step != 0.0
    stiction = r_s > 0.0
    stribeck = stiction and v_st > 0.0    # the Stribeck form: static-kinetic by each node's own speed
    # a friction that only steps has two levels of K: its bounds are tabulated as they are first met (over a span of
    # more than a sample; the per-cycle form's one-sample spans compute them)
    tabled = varying and K_rate == 0.0 and c_v == 0.0 and i1 - i0 > 1
    none = np.empty(0)          # no table: the bound is computed
    keys = np.empty(N_ROWS + 1 if tabled else 0)
    rows = np.empty((N_ROWS if tabled else 0, m1))
    for j in range(keys.shape[0]):
        keys[j] = math.nan if j < N_ROWS else 0.0
    seen = slide.shape[0] > 0
    # a slide at the tabulated kinetic bound without stiffening: the profile is Y_p times the bound, so E is Y_p times
    # the bounds' weighted sum (no node loop; the sums taken at the span's first such slide, so that a span without
    # one, as most one-sample spans of the per-cycle form are, pays nothing); the profile itself is written when the
    # slide ends (``lazy``, pending)
    flat = not varying and not stribeck and beta == 0.0
    sw_pull, sw_release, w_sum = 0.0, 0.0, -1.0
    lazy = 0
    lazy_Yp = 0.0
    for k in range(i0, i1):
        tk = t[k]
        Kk = K
        if varying:
            Kk = K + K_rate * (tk - t0)
            if tk - t0 >= t_step:
                Kk += K_step        # the friction step: K before t_s, K + dK from t_s on
            if Kk < 0.0:
                Kk = 0.0
            Kk *= 1.0 + c_v * spd[k]
        Yp = T_in[k]
        if Yp < 0.0:
            Yp = 0.0
        Yp += a
        if sliding != 0 and v[k] * sliding <= V_STOP:
            sliding = 0             # the proximal end stopped or turned: the tendon sticks
            t_b = -math.inf
        forced = 0
        if seen and slide[k] != 0 and v[k] * slide[k] > V_STOP and (Yp - Yp_prev) * slide[k] >= -2.0 * sigma:
            forced = slide[k]       # both ends seen moving one way, T_in not turned back: the whole tendon slides
        stuck = stiction and sliding == 0
        if stuck and not stribeck and count > 0 and Yp_prev - a >= T_min and abs(v[k]) > V_STOP:
            # breakaway seen as a turn of T_in near the static threshold while the proximal end goes on
            dm = 1 if v[k] > 0.0 else -1
            yn = Y[m1 - 1]
            gk = math.exp(-Kk * u[m1 - 1] * dm)
            gs = math.exp(-Kk * (1.0 + r_s) * u[m1 - 1] * dm)
            near = yn / gk + (1.0 - BREAK_MARGIN) * (yn / gs - yn / gk)
            if (Yp_prev - near) * dm >= 0.0 and (Yp_prev - Yp) * dm > 2.0 * sigma:
                sliding = dm
                t_b = t_prev
        Yp_prev = Yp
        t_prev = tk
        count += 1
        entered = forced != 0 and sliding != forced
        if entered:
            if stuck and not stribeck and Yp - a >= T_min:
                t_b = tk            # breakaway from static friction
            sliding = forced
        if sliding != 0:
            f = Kk
            if stribeck:
                f *= 1.0 + r_s * math.exp(-(v[k] / v_st) ** 2)
            elif t_b > -math.inf:
                f *= 1.0 + r_s * math.exp(-(tk - t_b) / t_slip)
            g_n = math.exp(-f * sliding * u[m1 - 1])
            if not entered and tk - t_b > 5.0 * t_slip and (Yp * g_n - Y[m1 - 1]) * sliding < -2.0 * sigma * g_n:
                # a sliding distal end only moves on (T_out rises pulling, falls releasing): T_in
                # turned back beyond the noise, the tendon sticks (the averaged T_in turns before x_in)
                sliding = 0
                t_b = -math.inf
        if sliding != 0 and flat and t_b == -math.inf and (sliding < 0 or Yp * g_kin[m1 - 1] >= a):
            lazy, lazy_Yp = sliding, Yp     # no node below a: sum_i w_i (Y_p g_i - a) in closed form
            if w_sum < 0.0:
                w_sum = 0.0
                for i in range(m1):
                    sw_pull += w[i] * g_kin[i]
                    sw_release += w[i] * g_kin_inv[i]
                    w_sum += w[i]
            if sliding > 0:
                E = Yp * sw_pull - a * w_sum
                Y[m1 - 1] = Yp * g_kin[m1 - 1]
            else:
                E = Yp * sw_release - a * w_sum
                Y[m1 - 1] = Yp * g_kin_inv[m1 - 1]
            T_out[k] = Y[m1 - 1] - a
            E1[k] = E - E0
            continue
        if lazy != 0:
            _write_slide(Y, lazy_Yp, g_kin if lazy > 0 else g_kin_inv, a)
            lazy = 0
        if sliding != 0:
            E = 0.0
            c = -f * sliding
            if not varying and not stribeck and t_b == -math.inf:      # the kinetic bound: tabulated
                gt = g_kin if sliding > 0 else g_kin_inv
            elif tabled and f == Kk:
                gt = rows[_bound_row(c, u, keys, rows)]
            else:
                gt = none
            for i in range(m1):
                y = Yp * (gt[i] if gt.shape[0] > 0 else math.exp(c * u[i]))
                if y < a:
                    y = a
                Y[i] = y
                E += w[i] * stiffening_strain(y - a, beta, Tc)
            K_prof = f
        else:
            bound = Kk * (1.0 + r_s) if stuck else Kk
            # a friction that fell (the speed dropped, the drift or the step went down) below the steepest one the
            # profile was written with tightens the bounds of nodes beyond one that holds: every node is checked
            every = varying and (K_prof - bound) * Yp > band
            moved = False
            if stribeck:
                _stribeck_bound(Y, Yp, a, u, w, Kk, r_s, v_st, abs(v[k]), dY, G, g_kin, varying)
                gt = none
            elif varying:
                gt = rows[_bound_row(-bound, u, keys, rows)] if tabled else none
            else:
                gt = g_sta if stuck else g_kin
            for i in range(m1):
                if stribeck:
                    g = math.exp(-G[i])
                elif gt.shape[0] > 0:
                    g = gt[i]
                else:
                    g = math.exp(-bound * u[i])
                y = Y[i]
                lo = (Yp - band) * g
                hi = (Yp + band) / g
                if y < lo:
                    ny = lo
                    d = 1
                elif y > hi:
                    ny = hi if hi > a else a
                    d = -1
                elif every:
                    continue
                else:
                    break
                if abs(ny - y) <= NODE_ROUNDING * y:
                    if every:
                        continue
                    break           # on its bound to rounding (NODE_ROUNDING): the node does not move
                E += w[i] * (stiffening_strain(ny - a, beta, Tc) - stiffening_strain(y - a, beta, Tc))
                Y[i] = ny
                moved = True
                if i == m1 - 1:         # the slip reached the distal end: the whole tendon slides
                    sliding = d
                    if stuck and not stribeck and Yp - a >= T_min:
                        t_b = tk        # breakaway from static friction
            if every:
                K_prof = bound      # every node within the bounds of this friction
            elif moved and bound > K_prof:
                K_prof = bound
        T_out[k] = Y[m1 - 1] - a
        E1[k] = E - E0
    if lazy != 0:
        _write_slide(Y, lazy_Yp, g_kin if lazy > 0 else g_kin_inv, a)
    st[S_E] = E
    st[S_SLIDING] = float(sliding)
    st[S_T_B] = t_b
    st[S_YP_PREV] = Yp_prev
    st[S_T_PREV] = t_prev
    st[S_COUNT] = float(count)
    st[S_K_PROFILE] = K_prof
