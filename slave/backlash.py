"""Backlash compensation of a pulled tendon: the release band paid out as its command turns back.

After a pull to ``T_in0`` the distal end holds until the proximal tension has crossed the release band,
``T_in0 -> T_in0 e^-2K`` (Phee et al. 2009, Sec. III), while the proximal end travels ``c_rev T_in0``
(:attr:`estimator.sheath.SheathModel.reversal_compliance`): the dead zone. :func:`band_payout` is the travel
[m] the puller pays out so that the distal end follows the command's reversal instead, spread over a play of
half-width ``w`` on the command ``c`` (``s`` = +1 when pulling raises ``c``, -1 when it lowers it)::

    y   <- clip(y, c - w, c + w)                  (play on the command; y = c - s w when the pull starts)
    u    = s (c - y) / w                          in [-1, 1]: +1 while pulling, -1 once turned back by 2 w
    T0   = T_eq = T_in while u = 1                (the tension the reversal starts from)
    T_eq <- T_eq + (1 - e^(-dt/tau)) (min(T0, T_in e^2K) - T_eq)      otherwise (tau = BAND_TIME)
    payout = c_rev T_eq (1 - u) / 2

Past the band the distal tension follows ``T_out = T_in e^K``, so ``T_in e^2K`` is the pull-branch tension of
the present distal tension and the payout, the band at that tension, falls to 0 with it: the released tendon
is never left slack. Inside the band ``T_in e^2K >= T0`` and nothing feeds back; past it the payout is a
negative feedback of loop gain ``e^K - 1`` (a stiff load) that the filter keeps smooth. A pull after a
release takes the travel back over the same play, so jitter never ratchets. The payout is >= 0 and at most
``c_rev T_in0``: the compensation only ever pays tendon out relative to the uncompensated command.
:mod:`slave.pair_control` applies it to the puller of an antagonistic pair.
"""
from __future__ import annotations

import math

__all__ = ["BAND_TIME", "band_payout"]

#: Time constant tau [s] of the compensation's tension filter.
BAND_TIME = 0.01


def band_payout(c: float, s: float, T: float, dt: float, y: float, T0: float, T_eq: float, c_rev: float,
                K: float, w: float) -> tuple[float, float, float, float]:
    """One step of the compensation (module docstring).

    Parameters
    ----------
    c : float
        Command (a joint angle [rad] or a proximal position [m]; ``w`` in the same unit).
    s : float
        +1 when pulling raises ``c``, -1 when it lowers it.
    T : float
        The puller's proximal tension [N] (its load cell).
    dt : float
        Control period [s], > 0.
    y, T0, T_eq : float
        The state: the play's output, the reversal's tension [N] and the filtered pull-branch tension [N].
    c_rev : float
        Reversal compliance [m/N], >= 0.
    K : float
        Friction exponent [-], >= 0.
    w : float
        Half-width of the play, > 0.

    Returns
    -------
    (payout [m] >= 0, y, T0, T_eq) : the travel to pay out and the new state.
    """
    y = min(max(y, c - w), c + w)
    u = min(1.0, s * (c - y) / w)
    if u > 1.0 - 1e-9:                           # pulling (rounding of c - (c - w) aside)
        return 0.0, y, T, T
    target = min(T0, T * math.exp(2.0 * K))
    T_eq += -math.expm1(-dt / BAND_TIME) * (target - T_eq)
    return c_rev * max(T_eq, 0.0) * 0.5 * (1.0 - u), y, T0, T_eq
