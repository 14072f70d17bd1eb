"""Compiled step of the dynamic lumped-mass tendon-sheath simulator (:mod:`study.lumped.simulator` explains it).

One substep of length ``dt`` is backward (implicit) Euler on the node velocities with the element
stiffness, the load slope and the friction linearised at the start of the substep; the linear
system is tridiagonal (a chain) and is solved by the Thomas algorithm, O(n) per substep. Arrays,
0-based, proximal to distal:

    u[i], v[i]   node displacement [m] (+ toward the actuator) and velocity [m/s], i = 0..n-1
    e[i], T[i]   stretch [m] and tension [N] of element i (element 0 joins the proximal tendon
                 point xp to node 0, element i joins node i-1 to node i)
    z[i]         friction force [N] of node i against the sheath (bristle state); st[i] its
                 status (0 stick, +1 / -1 sliding toward / away from the actuator)
    m[i]         node mass [kg] (the distal load mass is added to node n-1)
    dth[i]       wrap angle [rad] carried by node i; qds[i] tension-independent normal load [N]
    s = [x_motor, xp, x_joint, t, T_out]  scalar state

Nothing here is shared with the quasi-static rig or the estimator's kernels on purpose: it is an
independent second formulation, so that a diagnosis checked on both does not fit one simulator's numerics.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["simulate", "load_force"]


@njit(cache=True, nogil=True)
def load_force(x, lx, lF, ls):  # pragma: no cover - compiled
    """Distal load force [N] (pulls the tendon end distally) and its slope [N/m] at x [m].

    Piecewise linear through (lx[j], lF[j]); ls[0] is the slope left of lx[0], ls[j] the slope
    right of lx[j-1] (so ls has len(lx) + 1 entries).
    """
    return _load_piece(x, _load_segment(x, lx), lx, lF, ls)


@njit(cache=True, nogil=True, inline="always")
def _tension(e, T, k_lin, beta, Tc):  # pragma: no cover - compiled
    """Element tension [N] from stretch e [m]: phi(T) = k_lin e with phi(T) = T + beta Tc (1 - e^-T/Tc);
    a tendon cannot push (0 for e <= 0). Newton from the previous tension T (phi is concave)."""
    if e <= 0.0:
        return 0.0
    y = k_lin * e
    if beta == 0.0:
        return y
    t = T if T > 0.0 else y / (1.0 + beta)
    for _ in range(30):
        ex = math.exp(-t / Tc)
        f = t + beta * Tc * (1.0 - ex) - y
        dt_ = f / (1.0 + beta * ex)
        t -= dt_
        if t < 0.0:
            t = 0.0
        if abs(dt_) <= 1e-13 * (1.0 + y):
            break
    return t


@njit(cache=True, nogil=True)
def _load_segment(x, lx):  # pragma: no cover - compiled
    """Index j of the piece of the load law that holds x [m] (0 left of lx[0], j right of lx[j-1])."""
    m = lx.shape[0]
    for j in range(m):
        if x <= lx[j]:
            return j
    return m


@njit(cache=True, nogil=True)
def _load_piece(x, j, lx, lF, ls):  # pragma: no cover - compiled
    """Force [N] of piece j of the load law (extended as an affine law) at x [m], and its slope."""
    if j == 0:
        return lF[0] + ls[0] * (x - lx[0]), ls[0]
    return lF[j - 1] + ls[j] * (x - lx[j - 1]), ls[j]


@njit(cache=True, nogil=True)
def _thomas(a, b, c, d, n):  # pragma: no cover - compiled
    """Solve the tridiagonal system in place; the solution is left in d."""
    for i in range(1, n):
        w = a[i] / b[i - 1]
        b[i] -= w * c[i - 1]
        d[i] -= w * d[i - 1]
    d[n - 1] = d[n - 1] / b[n - 1]
    for i in range(n - 2, -1, -1):
        d[i] = (d[i] - c[i] * d[i + 1]) / b[i]


# The phases of a substep borrow the caller's arrays and allocate none: compiled without reference counting
# (_nrt=False), a call costs no atomic increment and decrement per array argument (with them the loop takes a
# quarter longer).
@njit(cache=True, nogil=True, _nrt=False)
def _motor_step(s, target, bw_alpha, vmax, dt):  # pragma: no cover - compiled
    """Move the motor s[0] [m] one substep toward ``target`` [m] (a first-order position loop, speed-limited to
    vmax [m/s]) and advance the time s[3] [s]."""
    step = bw_alpha * (target - s[0])
    lim = vmax * dt
    if step > lim:
        step = lim
    elif step < -lim:
        step = -lim
    s[0] += step
    s[3] += dt


@njit(cache=True, nogil=True, _nrt=False)
def _element_bases(e, T, k_lin, beta, Tc, ktt, Tt, tk, ktan, Tb, n):  # pragma: no cover - compiled
    """Tangent stiffness ktt [N/m] and affine force base Tt [N] of every element if taut at the end of the substep
    (T' = Tb + ktan dt (v_prox' - v')), and its taut flag tk with ktan, Tb from the stretch at the start; a slack
    element (a tendon cannot push) has neither."""
    for i in range(n):
        if beta == 0.0:
            ktt[i] = k_lin
        else:
            ktt[i] = k_lin / (1.0 + beta * math.exp(-(T[i] if e[i] > 0.0 else 0.0) / Tc))
        Tt[i] = T[i] if e[i] > 0.0 else ktt[i] * e[i]
        tk[i] = 1 if e[i] >= 0.0 else 0
        ktan[i] = ktt[i] if tk[i] == 1 else 0.0
        Tb[i] = Tt[i] if tk[i] == 1 else 0.0


@njit(cache=True, nogil=True, _nrt=False)
def _friction_bounds(T, T_out, v, z, dth, qds, mu, cv, rs, vs, dt, inv_zss, Fcs, cs, cvs, w,
                     n):  # pragma: no cover - compiled
    """Coulomb bound Fcs [N] of every node, N_i mu times the Stribeck factor of the last substep's speed, with
    its bristle stick slope cs = Fc dt / zss [N s/m] and slip damping cvs = N_i mu cv [N s/m]; a bristle force
    above a dropped bound is clipped to it, and the node velocities w start at v."""
    for i in range(n):
        Tnext = T[i + 1] if i < n - 1 else T_out
        tb = 0.5 * (T[i] + Tnext)
        if tb < 0.0:
            tb = 0.0
        Nmu = (tb * dth[i] + qds[i]) * mu
        # speed-strengthening part implicit (slip: F' = s Fc + Nmu cv v'), Stribeck part lagged
        cvs[i] = Nmu * cv
        g = 1.0
        if rs != 0.0:
            g += rs * math.exp(-(v[i] / vs) ** 2)
        Fc = Nmu * g
        # a node whose bound dropped below its friction slips at once
        if z[i] > Fc:
            z[i] = Fc
        elif z[i] < -Fc:
            z[i] = -Fc
        Fcs[i] = Fc
        cs[i] = Fc * dt * inv_zss
        w[i] = v[i]


@njit(cache=True, nogil=True, _nrt=False)
def _assemble(v, z, st, m, visc, ktan, Tb, Fcs, cs, cvs, A, B, FL, kL, b_load, dt, a, b, c, d,
              n):  # pragma: no cover - compiled
    """Tridiagonal system (a, b, c | d) of the node velocities at the end of the substep for the current active
    set: a stuck bristle F' = F + c v', a slipping one F' = st Fc + cvs v', the proximal tendon point
    v_p' = A + B v_0' and the distal load's piece (force FL [N], slope kL [N/m]) on the last node."""
    for i in range(n):
        if st[i] == 0:
            D = cs[i]
            Fw = z[i]
        else:
            D = cvs[i]
            Fw = st[i] * Fcs[i]
        ci = ktan[i] * dt
        cn = ktan[i + 1] * dt if i < n - 1 else (kL * dt + b_load)
        Tn = Tb[i + 1] if i < n - 1 else FL
        b[i] = m[i] / dt + D + visc[i] + cn + (ci * (1.0 - B) if i == 0 else ci)
        d[i] = m[i] / dt * v[i] + Tb[i] - Tn - Fw
        if i == 0:
            d[i] += ci * A
            a[i] = 0.0
        else:
            a[i] = -ci
        c[i] = -cn if i < n - 1 else 0.0


@njit(cache=True, nogil=True, _nrt=False)
def _slip_status(d, z, st, cs, Fcs, w, n):  # pragma: no cover - compiled
    """Take the solved velocities d as the nodes' w and move each bristle between stick and slip by its trial
    force z + cs d against the bound; True if a status changed."""
    changed = False
    for i in range(n):
        w[i] = d[i]
        trial = z[i] + cs[i] * d[i]
        if st[i] == 0:
            if trial > Fcs[i] and Fcs[i] > 0.0:
                st[i] = 1
                changed = True
            elif trial < -Fcs[i] and Fcs[i] > 0.0:
                st[i] = -1
                changed = True
        elif st[i] * trial < Fcs[i]:
            st[i] = 0
            changed = True
    return changed


@njit(cache=True, nogil=True, _nrt=False)
def _taut_status(d, e, A, B, ktt, Tt, tk, ktan, Tb, dt, n):  # pragma: no cover - compiled
    """Mark each element taut or slack by its stretch at the end of the substep under the solved velocities d
    (ktan, Tb follow); True if one changed."""
    changed = False
    vp_try = A + B * d[0]
    for i in range(n):
        vprox = vp_try if i == 0 else d[i - 1]
        want = 1 if e[i] + dt * (vprox - d[i]) > 0.0 else 0
        if want != tk[i]:
            tk[i] = want
            ktan[i] = ktt[i] if want == 1 else 0.0
            Tb[i] = Tt[i] if want == 1 else 0.0
            changed = True
    return changed


@njit(cache=True, nogil=True, _nrt=False)
def _active_set(u, v, e, z, st, s, m, visc, ktt, Tt, tk, ktan, Tb, Fcs, cs, cvs, w, a, b, c, d, inv_ks, lx, lF,
                ls, b_load, dt, n_iter, n):  # pragma: no cover - compiled
    """Node velocities w [m/s] at the end of the substep, with the stick/slip status of every bristle, the
    taut/slack state of every element and the load law's piece that holds the distal node there, one
    tridiagonal solve per pass of at most ``n_iter``. Returns (A, B) of the proximal tendon point
    v_p' = A + B v_0' behind the sheath spring."""
    jL = _load_segment(u[n - 1], lx)
    A = 0.0
    B = 0.0
    for _it in range(n_iter):
        r = ktan[0] * inv_ks
        A = (s[0] - s[1] - Tb[0] * inv_ks) / (dt * (1.0 + r))
        B = r / (1.0 + r)
        FL, kL = _load_piece(u[n - 1], jL, lx, lF, ls)
        _assemble(v, z, st, m, visc, ktan, Tb, Fcs, cs, cvs, A, B, FL, kL, b_load, dt, a, b, c, d, n)
        _thomas(a, b, c, d, n)
        slip = _slip_status(d, z, st, cs, Fcs, w, n)
        taut = _taut_status(d, e, A, B, ktt, Tt, tk, ktan, Tb, dt, n)
        jn = _load_segment(u[n - 1] + dt * d[n - 1], lx)
        if not slip and not taut and jn == jL:
            break
        jL = jn
    return A, B


@njit(cache=True, nogil=True, _nrt=False)
def _advance(u, v, e, z, T, s, w, cs, Fcs, A, B, k_lin, beta, Tc, lx, lF, ls, b_load, m_load, half_play, dt,
             n):  # pragma: no cover - compiled
    """Integrate the substep with the node velocities w: the proximal tendon point s[1], stretches, bristle
    forces (clipped to their bound), displacements and tensions, the distal tension s[4] (load law, damping and
    the load mass's inertia) and the joint s[2] behind the distal backlash."""
    vp = A + B * w[0]
    s[1] += dt * vp
    acc_last = (w[n - 1] - v[n - 1]) / dt
    for i in range(n):
        vi = w[i]
        vprox = vp if i == 0 else w[i - 1]
        e[i] += dt * (vprox - vi)
        f = z[i] + cs[i] * vi
        if f > Fcs[i]:
            f = Fcs[i]
        elif f < -Fcs[i]:
            f = -Fcs[i]
        z[i] = f
        u[i] += dt * vi
        v[i] = vi
    for i in range(n):
        T[i] = _tension(e[i], T[i], k_lin, beta, Tc)
    FL, kL = load_force(u[n - 1], lx, lF, ls)
    s[4] = FL + b_load * v[n - 1] + m_load * acc_last
    # joint behind the distal backlash (play operator of total width 2 half_play)
    if s[2] < u[n - 1] - half_play:
        s[2] = u[n - 1] - half_play
    elif s[2] > u[n - 1] + half_play:
        s[2] = u[n - 1] + half_play


@njit(cache=True, nogil=True)
def simulate(xcmd, n_sub, dt, bw_alpha, vmax, u, v, e, T, z, st, s, m, dth, qds, visc, k_lin, beta, Tc,
             inv_ks, mu0, mu_rate, cv, rs, vs, inv_zss, lx, lF, ls, b_load, m_load, half_play, n_iter,
             out):  # pragma: no cover - compiled
    """Run the chain over the command samples ``xcmd`` [m], ``n_sub`` substeps of ``dt`` [s] each.

    Motor: x_m += clip(bw_alpha (x_target - x_m), +-vmax dt), x_target linear between samples.
    Friction of node i: an elasto-plastic bristle (a single-state LuGre-family model) with the
    normal-force-scaled bound Fc_i = N_i mu(t) (1 + rs exp(-(v/vs)^2)), N_i = max(Tbar_i, 0) dth_i
    + qds_i, mu(t) = mu0 + mu_rate t (v of the last substep in the Stribeck factor): stick
    F' = F + (Fc / zss) dt v' while |F'| <= Fc, else slip F' = s Fc + N_i mu cv v' (s = +-1, the
    speed-strengthening term implicit: taken explicitly it is an unstable damper for light nodes);
    plus visc_i v'. The stick/slip status of every node (``st``: 0, +1, -1, kept between
    substeps) is found by an active-set iteration (at most ``n_iter`` tridiagonal solves, usually
    one) together with the taut/slack state of every element at the end of the substep (taut:
    T' = Tb + ktan dt (v_prox' - v'), Tb the tension, or ktan e for an element slack at the start;
    slack: T' = 0) and the piece of the load law that holds the distal node at its end: contact
    and separation are implicit (taken at the start of the substep, an element going taut in a
    substep was stretched with no stiffness and the stiff rebound of the next pumped energy into
    a slack tendon until it overflowed - lumped seed 316100, joint load, T_in near 0). N_i, the
    Stribeck factor and the tangent stiffness are frozen over a substep; |F| is clipped to Fc when
    the bound drops.
    Writes per sample k: out[k] = (x_motor, T_in, u_distal, T_out, x_joint, xp).
    """
    n = u.shape[0]
    a = np.empty(n)
    b = np.empty(n)
    c = np.empty(n)
    d = np.empty(n)
    ktan = np.empty(n)
    Fcs = np.empty(n)
    cs = np.empty(n)
    cvs = np.empty(n)
    w = np.empty(n)
    ktt = np.empty(n)
    Tt = np.empty(n)
    Tb = np.empty(n)
    tk = np.empty(n, dtype=np.int64)
    xprev = s[0]
    for k in range(xcmd.shape[0]):
        x_goal = xcmd[k]
        for j in range(n_sub):
            _motor_step(s, xprev + (x_goal - xprev) * (j + 1) / n_sub, bw_alpha, vmax, dt)
            mu = mu0 + mu_rate * s[3]
            if mu < 0.0:
                mu = 0.0
            _element_bases(e, T, k_lin, beta, Tc, ktt, Tt, tk, ktan, Tb, n)
            _friction_bounds(T, s[4], v, z, dth, qds, mu, cv, rs, vs, dt, inv_zss, Fcs, cs, cvs, w, n)
            A, B = _active_set(u, v, e, z, st, s, m, visc, ktt, Tt, tk, ktan, Tb, Fcs, cs, cvs, w, a, b, c, d,
                               inv_ks, lx, lF, ls, b_load, dt, n_iter, n)
            _advance(u, v, e, z, T, s, w, cs, Fcs, A, B, k_lin, beta, Tc, lx, lF, ls, b_load, m_load, half_play,
                     dt, n)
        xprev = x_goal
        out[k, 0] = s[0]
        out[k, 1] = T[0]
        out[k, 2] = u[n - 1]
        out[k, 3] = s[4]
        out[k, 4] = s[2]
        out[k, 5] = s[1]
