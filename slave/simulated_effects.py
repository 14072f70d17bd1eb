"""The effect switches of the simulated rig (``rig.simulated.effects``): compiled step kernels and the rig's share.

The switches, their settings and ranges are the effect catalogue's (estimator/offline/effects/catalogue.py,
``Effect.switch``; :data:`EFFECT_IDS` is derived from it); what each one does in this rig is the
code below (:data:`IMPLEMENTED` lists the switches this simulator has a kernel for).

:class:`EffectSwitches` is mixed into :class:`slave.simulated.SimulatedRig`; it owns the effect state
and the step with effects on, the kernels below solve it. The physics and the sliding rule are
described in the SimulatedRig docstring; estimator/offline/effects/kernels.py runs the same rules driven by
T_in instead of x_in.
"""
from __future__ import annotations

import math
from collections import deque
from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from estimator.extended_loop import stiffening_strain as strain  # one phi(T), shared with the estimator
from estimator.kernels import load_inverse
from estimator.offline.effects.catalogue import rig_switches
from teleop.config.effects import EffectsConfig, in_range
from teleop.errors import ConfigError

__all__ = [
    "EFFECT_IDS", "IMPLEMENTED", "EffectSwitches", "elongation_general", "full_slip", "advance_general",
    "validate_effects",
]

#: The switch keys of ``rig.simulated.effects``, from the catalogue (estimator/offline/effects/catalogue.py).
EFFECT_IDS = tuple(rig_switches())
#: The switches this simulator has a kernel for (a catalogue switch missing here fails a test).
IMPLEMENTED = frozenset({"velocity_friction", "pretension", "curvature_drift", "friction_step", "tendon_stiffening",
                         "stiction", "friction_offset", "presliding", "distal_backlash", "sensor_offset",
                         "sensor_gain", "sensor_delay", "sensor_drift", "encoder_offset"})
_V_STOP = 2e-4   # motor speed below which a whole-tendon slide ends [m/s] (estimator.extended_loop.V_STOP)


# ---- general step for the effect switches (friction offset, stiffening, varying bounds) -----------
#
# With a tension offset a (friction that does not scale with tension, dT/dtheta = -mu (T + a)) the
# envelope rule holds for Y = T + a instead of T, with T >= 0 (Y >= a) where the tendon goes slack.
# With a stiffening tendon the strain of an element is phi(T) / EA,
#     phi(T) = T + beta T_c (1 - exp(-T / T_c))       (tangent compliance (1 + beta e^{-T/T_c}) / EA)
# so the elongation sum(w phi(T_i)) is no longer linear in the proximal tension and each step is
# solved by a bracketed root search instead of the breakpoint scan. G is lo (pull, s = +1) or hi
# (release, s = -1): node i slips to Y_p G_i once Y_p passes the running max (min) of Y_j / G_j.
# When the bounds narrowed since a stuck part was laid down (speed or K dropped), that part is
# steeper than the new envelope and the slip front crosses it at one proximal tension: the step
# then ends with the front inside it (its nodes blended between old and new so that the
# elongation matches x_in - x_out exactly).


@njit(cache=True, nogil=True)
def elongation_general(T, w, beta, Tc):  # pragma: no cover - compiled
    """sum(w * phi(T)) [m]."""
    e = 0.0
    for i in range(T.shape[0]):
        e += w[i] * strain(T[i], beta, Tc)
    return e


@njit(cache=True, nogil=True)
def _prefix(T, S, G, w, a, beta, Tc, Yp, s, out):  # pragma: no cover - compiled
    """Elongation change [m] if the proximal end goes to Y_p with slip spreading from it.

    S = phi(T) of the old profile. Writes the new node tensions into ``out`` (its first k entries)
    and returns (dE, k), k = number of slipping nodes."""
    n1 = T.shape[0]
    dE = 0.0
    run = -math.inf if s > 0 else math.inf
    for i in range(n1):
        b = (T[i] + a) / G[i]
        if s > 0:
            if b > run:
                run = b
            if Yp < run:
                return dE, i
        else:
            if b < run:
                run = b
            if Yp > run:
                return dE, i
        t = Yp * G[i] - a
        if t < 0.0:
            t = 0.0
        out[i] = t
        dE += w[i] * (strain(t, beta, Tc) - S[i])
    return dE, n1


@njit(cache=True, nogil=True)
def _full(G, w, a, beta, Tc, Td, out):  # pragma: no cover - compiled
    """Elongation [m] of the whole tendon sliding with distal tension T_d (Y_i = Y_d G_i / G_n)."""
    n1 = G.shape[0]
    Yd = (Td + a) / G[n1 - 1]
    e = 0.0
    for i in range(n1):
        t = Yd * G[i] - a
        if t < 0.0:
            t = 0.0
        out[i] = t
        e += w[i] * strain(t, beta, Tc)
    return e


@njit(cache=True, nogil=True)
def _root(lo, f_lo, hi, f_hi, T, S, G, w, a, beta, Tc, s, x_in, target, bx, bF, bs, out, mode):  # pragma: no cover
    """Bracketed root of a non-decreasing f with f(lo) < 0 <= f(hi) (Anderson-Bjorck regula falsi,
    bisection whenever the bracket does not halve). mode 0: f = E(Y_p) - target (prefix slip);
    mode 1: f = x_hi(T_d) + E_full(T_d) - x_in (whole tendon sliding). Returns the final bracket."""
    side = 0
    for it in range(200):
        width = hi - lo
        if width <= 1e-15 * max(1.0, abs(hi)):
            break
        x = hi - f_hi * width / (f_hi - f_lo) if f_hi > f_lo else 0.5 * (lo + hi)
        if it % 3 == 2 or not (lo < x < hi):
            x = 0.5 * (lo + hi)
        if mode == 0:
            fx = _prefix(T, S, G, w, a, beta, Tc, x, s, out)[0] - target
        else:
            fx = load_inverse(x, bx, bF, bs)[1] + _full(G, w, a, beta, Tc, x, out) - x_in
        if fx < 0.0:
            lo, f_lo = x, fx
            if side == -1:
                f_hi *= 0.5
            side = -1
        else:
            if fx == 0.0:
                return x, x
            hi, f_hi = x, fx
            if side == 1:
                f_lo *= 0.5
            side = 1
    return lo, hi


@njit(cache=True, nogil=True)
def full_slip(T, G, w, a, beta, Tc, x_in, bx, bF, bs):  # pragma: no cover - compiled
    """Whole tendon sliding (G = lo pulling, hi releasing): the smallest distal tension T_d with
    x_hi(T_d) + e(T_d) >= x_in; writes the profile into T and returns x_out [m]."""
    out = np.empty_like(T)
    lo = 0.0
    f_lo = load_inverse(0.0, bx, bF, bs)[1] + _full(G, w, a, beta, Tc, 0.0, out) - x_in
    if f_lo >= 0.0:
        hi = 0.0
    else:
        hi = max(1.0, 2.0 * T[T.shape[0] - 1])
        for _ in range(200):
            f_hi = load_inverse(hi, bx, bF, bs)[1] + _full(G, w, a, beta, Tc, hi, out) - x_in
            if f_hi >= 0.0:
                break
            lo, f_lo, hi = hi, f_hi, 2.0 * hi
        lo, hi = _root(lo, f_lo, hi, f_hi, T, T, G, w, a, beta, Tc, 0, x_in, 0.0, bx, bF, bs, out, 1)
    e = _full(G, w, a, beta, Tc, hi, T)
    xl, xh = load_inverse(hi, bx, bF, bs)
    x = x_in - e
    if x < xl:
        x = xl
    elif x > xh:
        x = xh
    return x


@njit(cache=True, nogil=True)
def advance_general(T, lo, hi, w, a, beta, Tc, x_in, x_out, bx, bF, bs):  # pragma: no cover - compiled
    """Move the proximal end to ``x_in`` [m] with tension offset ``a`` [N] and stiffening (beta, T_c).

    Same physics as :func:`advance_proximal` (slip spreading from the proximal end, the distal end
    stuck until the slip front reaches it, then the whole tendon slides on the load graph), solved
    by a bracketed root search on the proximal tension. Returns (x_out [m], s) with s = +1 (-1) when
    the whole tendon slid toward the actuator (tip) in this step, else 0.
    """
    n1 = T.shape[0]
    S = np.empty_like(T)
    for i in range(n1):
        S[i] = strain(T[i], beta, Tc)
    e_old = 0.0
    for i in range(n1):
        e_old += w[i] * S[i]
    target = x_in - x_out
    if abs(target - e_old) <= 4e-16 * (abs(x_in) + abs(x_out) + e_old):
        return x_out, 0
    s = 1 if target > e_old else -1
    G = lo if s > 0 else hi
    # proximal Y at which the slip front reaches the distal node
    Ystar = (T[0] + a) / G[0]
    for i in range(1, n1):
        b = (T[i] + a) / G[i]
        if (s > 0 and b > Ystar) or (s < 0 and b < Ystar):
            Ystar = b
    Y0 = T[0] + a
    dt = target - e_old
    new = np.empty_like(T)
    if s > 0:
        f_hi = _prefix(T, S, G, w, a, beta, Tc, Ystar, s, new)[0] - dt
        if f_hi < 0.0:
            return full_slip(T, G, w, a, beta, Tc, x_in, bx, bF, bs), 1
        y_lo, y_hi = _root(Y0, -dt, Ystar, f_hi, T, S, G, w, a, beta, Tc, s, x_in, dt, bx, bF, bs, new, 0)
        y_in, y_out = y_lo, y_hi
    else:
        floor = max(Ystar, a)
        f_lo = _prefix(T, S, G, w, a, beta, Tc, floor, s, new)[0] - dt
        if f_lo > 0.0:
            if Ystar >= a:
                return full_slip(T, G, w, a, beta, Tc, x_in, bx, bF, bs), -1
            k = _prefix(T, S, G, w, a, beta, Tc, a, s, new)[1]  # slack: the proximal end cannot push
            T[:k] = new[:k]
            return x_out, 0
        y_lo, y_hi = _root(floor, f_lo, Y0, -dt, T, S, G, w, a, beta, Tc, s, x_in, dt, bx, bF, bs, new, 0)
        y_in, y_out = y_hi, y_lo
    # y_in: elongation short of (pull) / above (release) the target; y_out: at or past it
    d_lo, k_lo = _prefix(T, S, G, w, a, beta, Tc, y_in, s, new)
    if (d_lo - dt) * s > 0.0:
        # past the target already at y_in: the front jumps right at the start (a steeper part next to
        # the proximal end), so blend from the old profile
        d_hi, k_hi, d_lo, k_lo = d_lo, k_lo, 0.0, 0
    else:
        T[:k_lo] = new[:k_lo]
        d_hi, k_hi = _prefix(T, S, G, w, a, beta, Tc, y_out, s, new)
    if k_hi > k_lo and d_hi != d_lo:
        # the front crossed a steep stuck part: leave it inside, blending the nodes it passed
        lam = min(1.0, max(0.0, (dt - d_lo) / (d_hi - d_lo)))
        for i in range(k_lo, k_hi):
            new[i] = T[i] + lam * (new[i] - T[i])
    T[:k_hi] = new[:k_hi]
    return x_out, 0


class EffectSwitches:
    """The rig's effect state and its step with effects on (mixed into SimulatedRig)."""

    # the host rig's state this mixin reads and advances (set in SimulatedRig.__init__)
    log_gain: np.ndarray                             # node log-gains mu theta(s_i) [-], shape (n + 1,)
    _w: np.ndarray                                   # node elongation weights [m/N], shape (n + 1,)
    _T: np.ndarray                                   # node tensions [N], shape (n + 1,)
    _x_in: float                                     # proximal displacement [m]
    _x_out: float                                    # distal displacement [m]
    _graph: tuple[np.ndarray, np.ndarray, np.ndarray]  # distal load law segments (bx, bF, bs)
    _t: float                                        # rig time [s]

    if TYPE_CHECKING:
        @property
        def K(self) -> float:
            """Friction exponent [-] (SimulatedRig.K)."""

    @property
    def effects(self) -> tuple[str, ...]:
        """Identifiers of the effects switched on (estimator/offline/effects/catalogue.py names), in config order."""
        return self._effect_ids

    def _init_effects(self, fx: EffectsConfig, n: int) -> None:
        validate_effects(fx)
        on = {name: fx[name] for name in fx.enabled()}
        self._effect_ids = tuple(on)
        self._pretension = float(on["pretension"].tension) if "pretension" in on else 0.0
        self._a = float(on["friction_offset"].tension_offset) if "friction_offset" in on else 0.0
        st = on.get("tendon_stiffening")
        self._beta, self._Tc = (float(st.softening), float(st.toe_tension)) if st else (0.0, 1.0)
        self._viscous = float(on["velocity_friction"].viscous) if "velocity_friction" in on else 0.0
        self._K_rate = float(on["curvature_drift"].rate) if "curvature_drift" in on else 0.0
        step = on.get("friction_step")
        self._K_step, self._t_step = (float(step.change), float(step.time)) if step else (0.0, math.inf)
        sc = on.get("stiction")
        self._static = 1.0 + float(sc.static_ratio) if sc else 1.0
        self._slip_time = float(sc.slip_time) if sc else 1.0
        self._t_break, self._dir = -math.inf, 0
        self._offset = float(on["sensor_offset"].offset) if "sensor_offset" in on else 0.0
        self._delay = float(on["sensor_delay"].delay) if "sensor_delay" in on else 0.0
        self._gain = float(on["sensor_gain"].gain) if "sensor_gain" in on else 0.0
        self._drift = float(on["sensor_drift"].rate) if "sensor_drift" in on else 0.0
        self._encoder_offset = float(on["encoder_offset"].offset) if "encoder_offset" in on else 0.0
        self._x_p = float(on["presliding"].distance) if "presliding" in on else 0.0
        self._half_play = 0.5 * float(on["distal_backlash"].width) if "distal_backlash" in on else 0.0
        self._history: deque[tuple[float, float]] = deque()
        self._general = any(k in on for k in ("velocity_friction", "curvature_drift", "friction_step",
                                              "tendon_stiffening",
                                              "stiction", "friction_offset"))
        K = float(self.log_gain[-1])
        # node gain per unit K (the route shape); a straight sheath drifts as if uniformly curved
        self._shape = self.log_gain / K if K > 0 else np.linspace(0.0, 1.0, n + 1)
        self._gain_key = math.nan

    def _bounds(self, K_eff: float) -> tuple[np.ndarray, np.ndarray]:
        if K_eff != self._gain_key:
            self._gain_key = K_eff
            self._glo = np.exp(-K_eff * self._shape)
            self._ghi = 1.0 / self._glo
        return self._glo, self._ghi

    def _advance_effects(self, v: float, t: float) -> None:
        """One proximal step with the effect switches (class docstring); v [m/s], t [s] after the step."""
        K_now = self.K + self._K_rate * t + (self._K_step if t >= self._t_step else 0.0)   # drift, step (E6)
        K_kin = max(K_now, 0.0) * (1.0 + self._viscous * abs(v))
        args = (self._w, self._a, self._beta, self._Tc)
        if self._dir and v * self._dir <= _V_STOP:     # the motor stopped or turned: the tendon sticks
            self._dir, self._t_break = 0, -math.inf
        if self._dir:
            # the whole tendon slides: the profile follows at the present sliding friction, which
            # after a breakaway relaxes from static to kinetic
            f = K_kin
            if self._t_break > -math.inf:
                f *= 1.0 + (self._static - 1.0) * math.exp(-(t - self._t_break) / self._slip_time)
            lo, hi = self._bounds(f)
            self._x_out = full_slip(self._T, lo if self._dir > 0 else hi, *args, self._x_in, *self._graph)
        else:
            stuck = self._static > 1.0                 # not sliding: static friction holds it
            lo, hi = self._bounds(K_kin * (self._static if stuck else 1.0))
            self._x_out, slid = advance_general(self._T, lo, hi, *args, self._x_in, self._x_out, *self._graph)
            if slid:
                self._dir = slid
                if stuck:
                    self._t_break = t              # breakaway from static friction

    def _start_distal(self) -> None:
        """The distal state of the switches at rest (after the start profile is laid down): the pre-sliding friction
        at the memory model's, the measured distal position at the tendon end (the middle of the play)."""
        self._friction = self._lag = float(self._T[0] - self._T[-1])
        self._joint = self._x_out

    def _advance_distal(self, dx: float) -> None:
        """The distal state after a step of ``dx`` [m] of proximal travel (0: a load change at rest).

        Pre-sliding (E2, the catalogue's lumped form): the friction F = T_in - T_out the load cell sees lags the
        memory model's M = T_0 - T_n in proximal travel s, dF/ds = (M - F) / x_p, solved exactly over the step with M
        linear in s from its value before the step (M_0) to the one after (M_1), r = |dx| / x_p:
        F <- M_1 + (F - M_0) e^-r - (M_1 - M_0) (1 - e^-r) / r.
        Distal backlash (E12): the measured distal position stays until the tendon end is more than half the width
        from it, then follows at that distance."""
        if self._x_p > 0.0:
            m0, m1 = self._friction, float(self._T[0] - self._T[-1])
            r = abs(dx) / self._x_p
            if r > 0.0:
                self._lag = m1 + (self._lag - m0) * math.exp(-r) + (m1 - m0) * math.expm1(-r) / r
            self._friction = m1
        h = self._half_play
        if h > 0.0:
            if self._x_out - self._joint > h:
                self._joint = self._x_out - h
            elif self._joint - self._x_out > h:
                self._joint = self._x_out + h

    def _distal(self) -> tuple[float, float]:
        """The distal tension [N] and position [m] as the distal load cell and position sensor see them (before
        noise): the tendon end's, or with pre-sliding T_in - F (>= 0: the tendon cannot push), with the backlash the
        position behind the play."""
        T_out = max(float(self._T[0]) - self._lag, 0.0) if self._x_p > 0.0 else float(self._T[-1])
        return T_out, self._joint if self._half_play > 0.0 else self._x_out

    def _load_cell(self, T_true: float) -> float:
        """The load-cell signal before noise [N]: delayed, scaled, offset and drifting as the sensor effects say,
        (1 + gain) T(t - delay) + offset + rate t."""
        if self._delay > 0.0:
            h = self._history
            h.append((self._t, T_true))
            t_read = self._t - self._delay
            while len(h) > 2 and h[1][0] <= t_read:
                h.popleft()
            (t0, v0), (t1, v1) = h[0], h[-1] if len(h) == 1 else h[1]
            if t_read <= t0 or t1 <= t0:
                T_true = v0
            else:
                T_true = v0 + (v1 - v0) * min(1.0, (t_read - t0) / (t1 - t0))
        return (1.0 + self._gain) * T_true + self._offset + self._drift * self._t


def validate_effects(fx: EffectsConfig) -> None:
    """Range checks of every switch's settings against its catalogue entry, and that this simulator
    has a kernel for each switch that is on; ConfigError names the key."""
    for name, e in rig_switches().items():
        sw = e.switch
        if sw is None:      # rig_switches keeps only catalogue entries with a switch
            raise RuntimeError(f"effect catalogue entry {name!r} has no rig switch")
        sub = fx[name]
        where = f"rig.simulated.effects.{name}"
        _check(isinstance(sub.enabled, (bool, np.bool_)), f"{where}.enabled", "true or false", sub.enabled)
        for st in sw.settings:
            v = getattr(sub, st.name)
            _check(_finite(v) and in_range(v, st.valid), f"{where}.{st.name}",
                   "a finite number" + ("" if st.valid == "any" else f" {st.valid}") + f" [{st.unit}]", v)
        if sub.enabled and name not in IMPLEMENTED:
            raise ConfigError(f"{where}: the simulated rig has no kernel for this effect (it simulates: "
                              f"{', '.join(sorted(IMPLEMENTED))})")


def _check(ok: bool, key: str, expected: str, value: object) -> None:
    if not ok:
        raise ConfigError(f"{key} must be {expected}, got {value!r}")


def _finite(v: object) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
