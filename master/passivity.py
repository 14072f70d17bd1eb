"""Time-domain passivity observer (PO) and controller (PC) on the force channel at the master port.

Hannaford & Ryu 2002 ("Time-domain passivity control of haptic interfaces", IEEE T-RA 18(1)); for
delayed teleoperation the same observer sits at the master port of the communication two-port
(Ryu, Kwon & Hannaford 2004; Ryu, Artigas & Preusche 2010). Everything behind the device (channel,
delay, packet loss, slave, environment, estimator) is one network seen through the device handle.

Sign convention. ``f`` is the force the device renders on the operator's hand along the device
axis [N], ``v`` the handle velocity along the same axis [m/s] (+ = pull, as in
:mod:`master.device`). The power flowing from the operator *into* the network is ``-f v``: pushing
against a resisting force feeds energy in. The observed energy is::

    E(k) = sum_{j<=k} -f'(j) v(j) dt(j)                            [J]          (PO)

with ``f'`` the force actually rendered. The network is passive while ``E(k) >= 0`` for all k. When
the unmodified command would make it negative (the network would have generated energy), a
variable damper takes out exactly that excess in the same step::

    E_cmd = E(k-1) - f v dt
    alpha = -E_cmd / (v^2 dt)        if E_cmd < 0 and v != 0, else 0       [N s/m]  (PC)
    f'    = f - alpha v

so ``E(k) = 0`` after an active step. With an energy *reserve* ``E_r`` > 0 (``master.mapping.passivity_reserve``)
the controller first eases the force off smoothly while the port gives energy back (``-f v < 0``)::

    f = f min(1, E(k-1) / E_r)         when f d > 0, d = the direction of the last clear motion   (reserve)

so the stored energy decays like ``dE/dt = -(E/E_r) |f v|`` instead of running into the hard
correction, which then only catches what the scaling misses. The direction ``d`` is the handle's
last clear motion (its velocity smoothed over 20 ms beyond v_d = 2 mm/s): a handle held by the device's friction (v = 0
between slips) or creeping at a few um/s carries almost no power, and deciding on the sign of such a v switched the
force between full and zero every other sample; so did a raw-velocity threshold, as one force step moves the hand by ~1
mm/s within a sample. The hard PC alone switches between full force and the damped force from one sample to the next; on
a hand of small inertia that is a limit cycle of its own (docs/concepts/haptic-loop.md). Scaling the force toward 0
never makes the port active
(``|f'| <= |f|``, same sign). (Hannaford & Ryu write ``f' = f + alpha v`` with ``f`` the force
the operator applies to the network; here ``f`` is the force applied to the operator, hence the
minus.) The command is clamped to ``[-limit, limit]`` first; the damped force then always lies
between 0 and the clamped command (``f' v = E(k-1)/dt >= 0`` with ``|f'| <= |f|``), so the clamp holds
with the PC active and the PC needs no force the device cannot render.

Release and fade. The reserve's gain ``g`` (the factor above, 1 when the port takes energy in) follows
its target first-order, rising with the time constant ``tau_r`` (:data:`RELEASE_TIME`, 50 ms) and
falling with ``tau_f`` (:data:`FADE_TIME`, 10 ms)::

    g(k) = g_t + (g(k-1) - g_t) exp(-dt / tau),   g_t = min(1, E/E_r) or 1,   tau = tau_r if g_t > g(k-1) else tau_f

Before, ``g`` jumped to its target: the whole held-back force came back in one sample when the hand
turned into the force (the direction ``d`` flips, ``g`` 0.47 -> 1: a 1 N step on the grasp of the
3-joint instrument, 0.86 -> 1.83 N, 0.12 N in the worst 100 ms window above 30 Hz), and at a hold with
a long delay the direction's flips made ``g`` a relay (0.95 -> 0.63 in a sample, 0.086 N). A change of
``H`` newtons shaped so puts ~0.007 H (rise) and ~0.033 H (fall) into that window. ``tau_f`` is short
so that the fade still protects the tank: while ``g`` falls the port can lose at most
``f v tau_f`` = 4 N x 0.1 m/s x 10 ms = 4 mJ < E_r, so the hard PC stays the rare backstop (with a 50 ms
fall it ran the tank dry and switched at fs 0.4: 0.33 N). ``g`` in [0, 1] scales ``f`` toward 0 with
the same sign, and the hard PC after it still keeps ``E(k) >= 0``: passivity is unchanged. The price
is TDPA's known position drift (Artigas et al. 2010): where the network is strongly active (a
delayed stiff wall) the force comes back over ~50 ms after each cut and the hand sinks slowly into
the wall instead of buzzing against it (docs/concepts/haptic-loop.md).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from teleop.errors import ConfigError

__all__ = ["PassivityStats", "PassivityController"]

#: Handle speed v_d [m/s] above which the smoothed motion sets the direction the reserve acts on,
#: and the smoothing time [s] (first order).
RESERVE_SPEED, RESERVE_TIME = 0.002, 0.02
#: Time constant tau_r [s] of the release: the reserve's gain returns to 1 no faster than
#: 1 - exp(-t / tau_r). Its corner 1 / (2 pi tau_r) = 3.2 Hz lies in the hand's own band (< 10 Hz): a
#: release of H newtons puts ~0.007 H into the worst 100 ms window above 30 Hz (a step: 0.12 H).
RELEASE_TIME = 0.05
#: Time constant tau_f [s] of the fade: the gain falls toward E / E_r with it (module docstring).
FADE_TIME = 0.01


@dataclass(frozen=True)
class PassivityStats:
    """Counters of a :class:`PassivityController`.

    Attributes
    ----------
    energy : float
        Observed energy ``E(k)`` [J] (>= 0 up to rounding while the PC is enabled).
    dissipated : float
        Energy removed by the variable damper since the start or the last reset [J], >= 0.
    energy_in, energy_out : float
        Energy that flowed into / out of the network at the port [J], both >= 0;
        ``energy = E_r + energy_in - energy_out`` up to rounding (E_r the reserve, 0 without one).
    alpha : float
        Damping of the last step [N s/m] (0: PC inactive).
    active_steps, steps : int
        Steps where the PC acted, and all steps.
    """

    energy: float
    dissipated: float
    energy_in: float
    energy_out: float
    alpha: float
    active_steps: int
    steps: int


class PassivityController:
    """Passivity observer + controller for one force axis (see the module docstring for the equations).

    Parameters
    ----------
    limit : float
        Force clamp [N], finite and > 0; the output is always in ``[-limit, limit]``.
    enabled : bool
        False: observe only (the output is the clamped command; ``energy`` may go negative).
    reserve : float
        Energy reserve E_r [J], >= 0: below it the outgoing force is scaled by E / E_r (module
        docstring); 0 = the hard controller only.

    Raises
    ------
    ConfigError
        ``limit`` not finite and positive.
    """

    def __init__(self, limit: float, enabled: bool = True, reserve: float = 0.0):
        if isinstance(limit, bool) or not (math.isfinite(limit) and limit > 0):
            raise ConfigError(f"passivity limit must be a finite force > 0 N, got {limit!r}")
        if isinstance(reserve, bool) or not (math.isfinite(reserve) and reserve >= 0):
            raise ConfigError(f"master.mapping.passivity_reserve must be a finite energy >= 0 J, got {reserve!r}")
        self.limit = float(limit)
        self.reserve = float(reserve)
        self.enabled = bool(enabled)
        self.reset()

    def reset(self) -> None:
        """Forget the energy history (e.g. on re-engage, when the force starts again from zero).

        The observer starts with the reserve, ``E(0) = E_r`` (0 without one): a (re-)engage may hand
        back at most E_r (5 mJ) before the force eases off. Starting empty after a safe event left the
        reserve near 0 J at the next hold, where the direction logic turned into a relay on the hand
        (a 14 Hz, 2 N cycle in one demo run under load)."""
        self.energy = self.reserve
        self.dissipated = 0.0
        self.energy_in = 0.0
        self.energy_out = 0.0
        self.alpha = 0.0
        self.active_steps = 0
        self.steps = 0
        self._direction = 0.0
        self._v_smooth = 0.0
        self.gain = 1.0          # reserve gain g [-] in [0, 1] (module docstring, release)

    def step(self, force_cmd: float, velocity: float, dt: float) -> float:
        """The force to render [N] for the commanded ``force_cmd`` [N] at handle ``velocity`` [m/s].

        ``dt`` [s] is the duration of this sample (the force is held for ``dt``). Non-finite
        ``force_cmd`` gives 0 N; non-finite ``velocity`` or ``dt <= 0`` gives 0 N without touching the
        energy (the safe direction: no force is passive).
        """
        self.steps += 1
        self.alpha = 0.0
        f = float(force_cmd) if math.isfinite(force_cmd) else 0.0
        f = min(max(f, -self.limit), self.limit)
        if not (math.isfinite(velocity) and math.isfinite(dt) and dt > 0):
            return 0.0
        v = float(velocity)
        f_in = f
        # the direction of the handle's last clear motion (|v| > v_d): a handle held by the device's
        # friction or jittering about zero keeps it, so the reserve does not switch on stick-slip
        # smoothed over RESERVE_TIME: one force step moves a hand of ~1.6 kg by ~1 mm/s in a sample,
        # which must not flip the direction (else the step itself switches the force back: a cycle)
        self._v_smooth += dt / (RESERVE_TIME + dt) * (v - self._v_smooth)
        if abs(self._v_smooth) > RESERVE_SPEED:
            self._direction = 1.0 if self._v_smooth > 0 else -1.0
        if self.enabled and self.reserve > 0.0:
            # reserve: f = f g, g = min(1, E(k-1) / E_r) while the port gives energy back, else 1;
            # release / fade: g follows its target first-order (tau_r rising, tau_f falling)
            g = min(1.0, max(self.energy, 0.0) / self.reserve) if f * self._direction > 0.0 else 1.0
            g += (self.gain - g) * math.exp(-dt / (RELEASE_TIME if g > self.gain else FADE_TIME))
            self.gain = g
            f *= g
        # E_cmd = E(k-1) - f v dt      (energy into the network if f is rendered unchanged)
        e_cmd = self.energy - f * v * dt
        if self.enabled and e_cmd < 0.0 and v != 0.0:
            # alpha = -E_cmd / (v^2 dt);  f' = f - alpha v = E(k-1) / (v dt)
            # (the last form has no cancellation when v is tiny and alpha huge; |f'| <= |f|;
            # a rounding-level negative E(k-1) counts as 0, so f' never points against f)
            f_out = max(self.energy, 0.0) / (v * dt)
            f_out = min(max(f_out, -self.limit), self.limit)
        else:
            f_out = f
        if f_out != f_in:                        # the hard PC or the reserve took energy out
            self.alpha = (f_in - f_out) / v if v != 0.0 else 0.0
            self.dissipated += (f_in - f_out) * v * dt
            self.active_steps += 1
        # E(k) = E(k-1) - f' v dt
        de = -f_out * v * dt
        self.energy += de
        if de >= 0:
            self.energy_in += de
        else:
            self.energy_out -= de
        return f_out

    @property
    def stats(self) -> PassivityStats:
        """A snapshot of the counters."""
        return PassivityStats(self.energy, self.dissipated, self.energy_in, self.energy_out, self.alpha,
                              self.active_steps, self.steps)
