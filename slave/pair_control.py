"""Slave control of one antagonistic pair, as in the seed paper's rig (Phee et al. 2009, Sec. V).

The command is a joint angle theta_cmd [rad] (+: turn toward tendon a). One tendon pulls in position
control, the other - the antagonist - keeps its proximal tension at a set value T_set from its own
load cell (a minimal tension so that it never goes slack, or the pair's pretension when one is
configured). Modes:

======  ======================  ==================================  ================================
mode    when                    tendon a                            tendon b
======  ======================  ==================================  ================================
IDLE    |theta_cmd| <= band     tension control at T_set            tension control at T_set
PULL_A  theta_cmd > band        position: x_ref + r (c - c_ref)     tension control (+ feedforward)
PULL_B  theta_cmd < -band       tension control (+ feedforward)     position: x_ref - r (c - c_ref)
======  ======================  ==================================  ================================

A pulling mode is left when |theta_cmd| falls below band / 2 (hysteresis), so the sides switch when
the command changes sign. On entry the pulling side's reference (x_ref, c_ref) is its present motor
command and theta_cmd (bumpless transfer): the tendon does not jump when it takes over, and the
joint then turns by the commanded change (less the tendon's stretch, which the estimator reports).

Tension control of a tendon (integral action on the load cell, rate-limited to ``max_speed`` - the
slave passes ``slave.relax_speed``, so a SAFE relaxation from a high tension is gentle)::

    x_cmd <- x_cmd + clip(g (T_set - T_in) dt, -v_max dt, v_max dt)  [+ ff]

with the feedforward ff = -(change of the pulling side's estimated distal displacement x_out_hat =
x_in - e_hat, through a play of half-width ``play``) when ``feedforward`` is on: the antagonist
pays out what the joint turned toward the puller, and the loop corrects only its own stretch. The
feedforward follows the joint, not the command: against a joint limit or stiff tissue, or in the
dead zone after a reversal (the puller's distal end stuck), the joint stands still and so does the
antagonist, instead of going slack (or being pulled tight) by the commanded travel.
Without a command (None: watchdog, not engaged) the pair goes IDLE: both tendons relax to T_set and
the joint returns toward rest under its own spring. Every motor command is finally clipped to the
tendon's travel limits (``x_limits``), whatever the command or the loop asks.

Backlash compensation (``band_compliance``, off by default). When the command turns back, the puller's
distal end holds until its proximal tension has crossed the release band, ``T_in0 -> T_in0 e^-2K``
(Phee et al. 2009, Sec. III): a dead zone of ``c_rev T_in0`` of proximal travel
(:attr:`estimator.sheath.SheathModel.reversal_compliance`), during which the command moves and the joint
does not. With compensation the puller pays that travel out as the command turns back, spread over a
play of half-width ``w`` (``band_width``) on the command, and shrinking with the tension past the band
(:func:`slave.backlash.band_payout`, ``s`` = +1 for tendon a, -1 for b)::

    x_cmd,p = x_ref + s r (c - c_ref) - payout

so the joint follows the command's reversal instead of waiting in the band. The play restarts with each
pulling mode (``y = c - s w``, ``T0 = T_eq = T_in,p``); the travel clip and the slave's tension limit
still apply.
:class:`slave.pair_control_bank.PairControlBank` steps the controllers of every joint in one call.
"""
from __future__ import annotations

import math
from enum import IntEnum
from typing import Any

from slave.backlash import band_payout

__all__ = ["PairMode", "PairController"]


class PairMode(IntEnum):
    IDLE = 0
    PULL_A = 1
    PULL_B = 2


_PULLING = {PairMode.IDLE: -1, PairMode.PULL_A: 0, PairMode.PULL_B: 1}


class PairController:
    """Motor commands of one joint's two tendons from a joint-angle command and the two load cells.

    Parameters
    ----------
    pulley_radius : float
        Distal pulley radius r [m], > 0 (tendon displacement per joint angle).
    set_tension : float
        T_set [N], > 0: the antagonist's tension (minimal tension or the pretension).
    gain : float
        Integral gain g of the tension loop [m/(N s)], > 0.
    band : float
        Idle band of the command [rad], >= 0.
    max_speed : float
        Rate limit of the tension loop [m/s], > 0 (the motor's speed limit).
    x_init : (float, float)
        Present motor positions of tendons a and b [m] (the first commands).
    feedforward : bool
        Feed the pulling side's estimated distal motion to the antagonist.
    play : float
        Half-width of the play on that motion [m], >= 0 (keeps estimate noise out).
    x_limits : ((float, float), (float, float)), optional
        Travel limits [m] of the motor commands of tendons a and b, (low, high) each.
    band_compliance : (float, float), optional
        Reversal compliance ``c_rev`` [m/N] of tendons a and b, each finite and >= 0: backlash
        compensation on (module docstring); None: off.
    band_width : float
        Half-width ``w`` [rad] > 0 of the play on the command over which the compensation is applied.
    friction_exponent : (float, float)
        ``K`` [-] of tendons a and b, finite and >= 0 (the compensation's ``e^2K``; module docstring).

    Raises
    ------
    ValueError
        A setting not finite or out of range (named).
    """

    def __init__(self, pulley_radius: float, set_tension: float, gain: float, band: float, max_speed: float,
                 x_init: tuple[float, float], feedforward: bool = True, play: float = 5e-6, x_limits=None,
                 band_compliance: tuple[float, float] | None = None, band_width: float = 0.005,
                 friction_exponent: tuple[float, float] = (0.0, 0.0)):
        comp = () if band_compliance is None else tuple(band_compliance)
        if band_compliance is not None and len(comp) != 2:
            raise ValueError(f"pair control: band_compliance must be (c_rev,a, c_rev,b) [m/N], got {band_compliance!r}")
        for name, v, lo_ok in (("pulley_radius", pulley_radius, False), ("set_tension", set_tension, False),
                               ("gain", gain, False), ("band", band, True), ("max_speed", max_speed, False),
                               ("play", play, True), ("band_width", band_width, False),
                               *((f"band_compliance[{k}]", c, True) for k, c in enumerate(comp)),
                               *((f"friction_exponent[{k}]", K, True) for k, K in enumerate(friction_exponent))):
            if not (isinstance(v, (int, float)) and math.isfinite(v) and (v >= 0 if lo_ok else v > 0)):
                raise ValueError(f"pair control: {name} must be a finite number {'>= 0' if lo_ok else '> 0'}, "
                                 f"got {v!r}")
        self.r = float(pulley_radius)
        self.T_set = float(set_tension)
        self.gain = float(gain)
        self.band = float(band)
        self.vmax = float(max_speed)
        self.feedforward = bool(feedforward)
        self.play = float(play)
        self.x_limits = None if x_limits is None else tuple((float(lo), float(hi)) for lo, hi in x_limits)
        if self.x_limits is not None and (len(self.x_limits) != 2 or any(not lo < hi for lo, hi in self.x_limits)):
            raise ValueError(f"pair control: x_limits must be ((low, high), (low, high)) [m], got {x_limits!r}")
        self._ff: float | None = None      # play output on the puller's distal displacement [m]
        self.x_cmd = [float(x_init[0]), float(x_init[1])]
        self.mode = PairMode.IDLE
        self.switches = 0
        self._x_ref = 0.0
        self._c_ref = 0.0
        self._bank: Any = None     # the slave.pair_control_bank.PairControlBank stepping this controller, if any
        self.band_compliance = None if band_compliance is None else (float(comp[0]), float(comp[1]))
        self.band_width = float(band_width)
        self._y = 0.0              # the compensation's play output on the command [rad]
        self.friction_exponent = (float(friction_exponent[0]), float(friction_exponent[1]))
        self._T0 = 0.0             # the tension its reversal starts from [N]
        self._T_eq = 0.0           # the pull-branch tension of the present distal tension [N] (filtered)

    @property
    def pulling(self) -> int:
        """Index of the tendon in position control (0 = a, 1 = b), -1 when idle."""
        return _PULLING[self.mode]

    def _mode_for(self, c: float) -> PairMode:
        if not math.isfinite(c):
            return PairMode.IDLE
        if self.mode == PairMode.PULL_A and c > 0.5 * self.band:
            return PairMode.PULL_A
        if self.mode == PairMode.PULL_B and c < -0.5 * self.band:
            return PairMode.PULL_B
        if c > self.band:
            return PairMode.PULL_A
        if c < -self.band:
            return PairMode.PULL_B
        return PairMode.IDLE

    def _tension_step(self, j: int, T_in: float, dt: float) -> None:
        lim = self.vmax * dt
        self.x_cmd[j] += max(-lim, min(lim, self.gain * (self.T_set - T_in) * dt))

    def step(self, theta_cmd: float | None, T_in: tuple[float, float], dt: float,
             x_out_hat: tuple[float, float] | None = None) -> tuple[float, float]:
        """Motor commands (x_cmd,a, x_cmd,b) [m] for this cycle.

        Parameters
        ----------
        theta_cmd : float or None
            Joint-angle command [rad]; None (or NaN) = no command: IDLE.
        T_in : (float, float)
            Load cells of tendons a and b [N] (the last readings).
        dt : float
            Control period [s], > 0.
        x_out_hat : (float, float), optional
            Estimated distal displacements of tendons a and b [m] (for the feedforward).
        """
        if self._bank is not None:      # stepped on its own: its state back from the bank first
            self._bank.release()
        c = math.nan if theta_cmd is None else float(theta_cmd)   # None or NaN: idle
        mode = self._mode_for(c)
        if mode != self.mode:
            self.mode = mode
            self.switches += 1
            self._ff = None
            if mode != PairMode.IDLE:
                self._x_ref = self.x_cmd[self.pulling]
                self._c_ref = c
                self._y = c - (1.0 if mode == PairMode.PULL_A else -1.0) * self.band_width
                self._T0 = self._T_eq = float(T_in[self.pulling])
        p = self.pulling
        if p < 0:
            self._tension_step(0, T_in[0], dt)
            self._tension_step(1, T_in[1], dt)
            return self._clip()
        s = 1.0 if p == 0 else -1.0
        # pulling side: x_cmd = x_ref + s r (c - c_ref)
        x_new = self._x_ref + s * self.r * (c - self._c_ref)
        if self.band_compliance is not None:
            x_new -= self._payout(p, s, c, float(T_in[p]), dt)
        self.x_cmd[p] = x_new
        q = 1 - p
        if self.feedforward and x_out_hat is not None and math.isfinite(x_out_hat[p]):
            u = float(x_out_hat[p])
            if self._ff is None:
                self._ff = u
            y = min(max(self._ff, u - self.play), u + self.play)
            # the antagonist's distal end moves by -(puller's distal motion): pay it out
            self.x_cmd[q] -= y - self._ff
            self._ff = y
        self._tension_step(q, T_in[q], dt)
        return self._clip()

    def _payout(self, p: int, s: float, c: float, T: float, dt: float) -> float:
        """The backlash compensation's payout [m] >= 0 of the puller ``p`` (:func:`slave.backlash.band_payout`)."""
        assert self.band_compliance is not None
        out, self._y, self._T0, self._T_eq = band_payout(c, s, T, dt, self._y, self._T0, self._T_eq,
                                                         self.band_compliance[p], self.friction_exponent[p],
                                                         self.band_width)
        return out

    def _clip(self) -> tuple[float, float]:
        x = self.x_cmd
        if self.x_limits is not None:
            (lo_a, hi_a), (lo_b, hi_b) = self.x_limits
            x[0] = min(max(x[0], lo_a), hi_a)
            x[1] = min(max(x[1], lo_b), hi_b)
        return x[0], x[1]
