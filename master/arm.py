"""The operator's arm holding a haptic device, as haptics models it: mass, damping, stiffness.

Along one device axis the hand (arm + grip) and the device handle move together (a firm grip), so
they are one mass driven by the arm's impedance about the position the operator *intends*, by the
force the device renders, and braked by the device's own friction::

    (m_a + m_d) dv/dt = k_a (p_i - p) + b_a (v_i - v) + F - b_d v - F_c sgn(v)            [N]
    dp/dt = v                                                                             [m/s]

with ``p_i, v_i`` the intended hand position [m] and velocity [m/s] (the script, or the surgeon's
motor plan), ``F`` the rendered device force [N] (+ = along + position), ``m_a, b_a, k_a`` the arm's
effective mass [kg], damping [N s/m] and stiffness [N/m] (Hogan 1985; Tsuji et al. 1995), ``m_d``,
``b_d``, ``F_c`` the device's moving mass [kg], viscous [N s/m] and Coulomb [N] friction.

Typical values (docs/concepts/haptic-loop.md, with sources): hand/arm mass 1-2 kg, damping 5-30 N s/m,
stiffness 100-800 N/m for a relaxed to a firm grip; a desktop haptic device 0.05-0.2 kg and
0.05-0.3 N of friction. The defaults (1.5 kg, 15 N s/m, 300 N/m; 0.1 kg, 0.5 N s/m, 0.2 N) sit
in the middle.

Integration: a step of ``dt`` is cut into sub-steps of at most ``max_substep`` (1 ms). Each
sub-step is implicit in the spring and the dampers (stable for any stiffness and damping) and
handles Coulomb friction as an impulse (Karnopp): if friction can stop the mass within the
sub-step it sticks (v = 0), else it takes ``F_c dt`` of momentum. The static arm of the first
scripted operators (``p = p_i + F / k_a``, no mass) is the limit m, b -> 0; a time-domain
passivity controller on such an arm is a discrete damper loop of gain ``alpha / (k_a dt)``, which
is what made the demo chatter (docs/concepts/haptic-loop.md).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from teleop.errors import ConfigError

__all__ = ["ArmParameters", "HumanArm"]


@dataclass(frozen=True)
class ArmParameters:
    """Arm and device parameters of :class:`HumanArm` (module docstring; SI units).

    mass [kg] > 0, damping [N s/m] >= 0, stiffness [N/m] > 0: the arm; device_mass [kg] >= 0,
    device_damping [N s/m] >= 0, device_friction [N] >= 0: the device handle.
    """

    mass: float = 1.5
    damping: float = 15.0
    stiffness: float = 300.0
    device_mass: float = 0.1
    device_damping: float = 0.5
    device_friction: float = 0.2

    def __post_init__(self):
        for name, low_ok in (("mass", False), ("damping", True), ("stiffness", False), ("device_mass", True),
                             ("device_damping", True), ("device_friction", True)):
            v = getattr(self, name)
            ok = isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) \
                and (v >= 0 if low_ok else v > 0)
            if not ok:
                raise ConfigError(f"master.device.arm.{name} must be a finite number {'>= 0' if low_ok else '> 0'}, "
                                  f"got {v!r}")

    @classmethod
    def from_config(cls, arm) -> ArmParameters:
        """From the ``master.device.arm`` section (any object with the same field names)."""
        return cls(**{k: float(getattr(arm, k)) for k in cls.__dataclass_fields__})

    @property
    def natural_frequency_hz(self) -> float:
        """Undamped natural frequency of the hand on the arm's spring, sqrt(k / m) / 2 pi [Hz]."""
        return math.sqrt(self.stiffness / (self.mass + self.device_mass)) / (2 * math.pi)

    @property
    def damping_ratio(self) -> float:
        """(b_a + b_d) / (2 sqrt(k_a (m_a + m_d))) [-]."""
        return (self.damping + self.device_damping) / (2 * math.sqrt(self.stiffness * (self.mass + self.device_mass)))


class HumanArm:
    """One axis of an arm holding a device handle (module docstring).

    Parameters
    ----------
    params : ArmParameters
    max_substep : float
        Longest integration sub-step [s], > 0.

    Attributes
    ----------
    p, v : float
        Handle position [m] and velocity [m/s].
    """

    def __init__(self, params: ArmParameters | None = None, max_substep: float = 1e-3):
        self.params = params or ArmParameters()
        if not (math.isfinite(max_substep) and max_substep > 0):
            raise ConfigError(f"HumanArm: max_substep must be > 0 s, got {max_substep!r}")
        self.max_substep = float(max_substep)
        self.p = 0.0
        self.v = 0.0

    def reset(self, p: float = 0.0) -> None:
        """Hand at rest at ``p`` [m]."""
        self.p, self.v = float(p), 0.0

    def step(self, dt: float, p_intended: float, v_intended: float, force: float) -> float:
        """Advance ``dt`` [s] with the intended position [m] and velocity [m/s] and the rendered force
        [N] held over the step; returns the handle position [m]. ``dt <= 0`` or non-finite: no motion."""
        if not (math.isfinite(dt) and dt > 0):
            return self.p
        f = float(force) if math.isfinite(force) else 0.0
        a = self.params
        m = a.mass + a.device_mass
        b = a.damping + a.device_damping
        n = max(1, math.ceil(dt / self.max_substep - 1e-9))
        h = dt / n
        p_i = p_intended - v_intended * dt           # the intention moves linearly over the step
        for i in range(1, n + 1):
            pi_k = p_i + v_intended * h * i
            # implicit in spring and dampers: m (v' - v) = h [k (p_i - p - h v') + b_a v_i - b v' + F]
            v_free = (m * self.v + h * (a.stiffness * (pi_k - self.p) + a.damping * v_intended + f)) \
                / (m + h * b + h * h * a.stiffness)
            # Coulomb friction of the device as an impulse: stick if it can stop the mass this sub-step
            dv_c = a.device_friction * h / (m + h * b + h * h * a.stiffness)
            if abs(v_free) <= dv_c:
                v_new = 0.0
            else:
                v_new = v_free - math.copysign(dv_c, v_free)
            self.v = v_new
            self.p += h * v_new
        return self.p
