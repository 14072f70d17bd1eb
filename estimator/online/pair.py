"""Distal joint torque and angle of an antagonistic tendon pair, from proximal signals only.

A joint of pulley radius r is turned by tendon a (pulling it gives + angles) and tendon b, each
through its own sheath (own K, L/EA, route). Per tendon j in {a, b}, sign s_a = +1, s_b = -1:

    T(s)_j          tension-profile memory driven by T_in,j (envelope rule, :mod:`estimator.sheath`),
                    from a uniform pretension P_j                                    docs/concepts/effects.md E1, E5
    T_out,j         = T_n,j,    e_j = (1/EA_j) int T_j ds                         Phee et al. 2009 (1), (5)
    x_out,j         = x_in,j - e_j                                                   distal displacement
    theta_j         = s_j (x_out,j - x_out,j(0)) / r                 kinematic angle seen by tendon j  (J1)

and for the joint

    torque_hat      = r (T_out,a - T_out,b)                         distal joint torque [N m]        (J2)
    angle_hat       = (theta_a + theta_b) / 2                                                         (J3)
                    = ((x_in,a - e_a) - (x_in,b - e_b) - (x_out,a(0) - x_out,b(0))) / (2 r)

(J3) follows from x_out,a = +r theta + c_a and x_out,b = -r theta + c_b (both taut on the pulley):
subtracting cancels the unknown offsets to the zero pose, taken at :meth:`PairEstimator.zero`
(power-up rest, theta = 0), and halves independent elongation errors of the two tendons. A slack
tendon's x_in - e is not where its tip is, so each term is weighted by w_j = min(1, T_in,j /
``taut_tension``) (T_in,j >= 0): angle_hat = (w_a theta_a + w_b theta_b) / (w_a + w_b), which is
(J3) whenever both tendons carry at least ``taut_tension`` (the plain mean if neither does).

Pair coupling (docs/concepts/effects.md E13). A single-tendon estimator assumes the distal end stays put while
the profile near it is stuck. In a pair the two distal ends are tied: the joint turns only when the
torque r (T_out,a - T_out,b) moves away from what its load holds at the present angle, and when it
turns it moves both distal ends. Two rules, applied after the proximal updates of each sample:

* Joint moving (J4). The driving tendon d - the one with the higher proximal tension (hysteresis
  0.2 N + 10 %), whose profile the proximal update keeps right - gives the motion: its kinematic
  angle (J1), through a play of half-width ``play / r`` that keeps sensor noise out. Each output
  step delta of the play moves the other tendon q's distal end by s_q r delta with its proximal
  tension held at the measured T_in,q (the envelope rule has already placed the proximal part), by
  the distal slip rule (:mod:`estimator.distal_slip`):

      e_q <- e_q - s_q r delta,   T_d from (D),   T_in,q e^{-K_q} <= T_d <= T_in,q e^{+K_q}

  The bounds are the whole tendon sliding with its proximal tension held, where an antagonist kept
  at a set tension by its own load cell ends up while the joint turns. The part of the motion that
  (J5) below has already given the tendon (the joint creeping inside the play) is not given twice.
* Joint still (J5). While the play does not move, the angle, hence the load torque, is unchanged:

      r (T_out,a - T_out,b) = tau_lock

  If the proximal update moved one tendon's distal tension (its slip front reached the tip), the
  other tendon absorbs the change from its distal end - rule (D) with T_d set to keep tau_lock,
  clipped to the same sliding bounds. Once it reaches a bound the torque can no longer be held; the
  joint turns, which the play sees a few micrometres later. tau_lock follows the estimate after every
  sample. The elongation change (J5) gives the absorbing tendon is the joint motion it implies; it
  is kept (signed) and subtracted from the next motion (J4) in the same direction. (J5) is exact for a load whose
  stiffness is small next to the antagonist's capstan band (a joint spring, tissue); against a hard stop it may move the
  other tendon's distal tension by up to its band, T_in (e^K - e^-K), which the torque estimate then carries.

Without these rules the antagonist's distal tension is unknown within its band, which at a 2 N
pretension is a quarter of the full scale of the paper's protocol; with them the pretension is
carried through (E5).

The same maths over recorded arrays (compiled) is :func:`estimator.online.pair_batch.estimate_pair_batch`;
the kernels (and every sample after the first in one compiled call) are in :mod:`estimator.online.pair_coupling`;
:class:`estimator.online.pair_bank.PairBank` steps the estimators of every joint of an instrument in one call.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from estimator.distal_slip import distal_gains
from estimator.online.distal import DistalEstimator
from estimator.online.pair_coupling import couple, step_pair, weighted_angle
from estimator.phase import Phase
from estimator.sheath import SheathModel

__all__ = ["PairSample", "PairBatch", "PairEstimator", "DEFAULT_PLAY", "KAIST_PLAY"]

#: Default play of the coupling: distal tendon displacement that counts as joint motion [m]
#: (several times the elongation noise a 0.02 N load cell leaves in the profile, plus encoder steps).
DEFAULT_PLAY = 2e-5
#: Coupling play for the KAIST recordings, in units of the pulley radius [rad] (joint_batch.predict_pair_angle).
KAIST_PLAY = 0.005


class PairSample(NamedTuple):
    """One estimate of a joint (a named tuple: cheap to build every cycle).

    torque [N m] (J2); angle [rad] (J3); T_out, elongation, x_out: per tendon (a, b) [N], [m], [m];
    angle_a, angle_b: the kinematic angle of each tendon (J1) [rad]; phase: per tendon (a, b).
    """

    torque: float
    angle: float
    T_out: tuple[float, float]
    elongation: tuple[float, float]
    x_out: tuple[float, float]
    angle_a: float
    angle_b: float
    phase: tuple[Phase, Phase]


@dataclass(frozen=True)
class PairBatch:
    """Estimates over a recording: torque [N m] and angle [rad] of shape (n,); T_out [N] and
    elongation [m] of shape (n, 2) (columns a, b)."""

    torque: np.ndarray
    angle: np.ndarray
    T_out: np.ndarray
    elongation: np.ndarray


class PairEstimator:
    """Online torque and angle estimator of one antagonistic joint (module docstring, (J1)-(J4)).

    Parameters
    ----------
    model_a, model_b : SheathModel
        K, L/EA and route shape of tendons a and b (e.g. from calibration).
    pulley_radius : float
        Distal pulley radius r [m], > 0.
    n_nodes : int
        Elements of each profile (n_nodes + 1 nodes), >= 1.
    pretension : float or (float, float)
        Uniform tension of each tendon at rest [N], >= 0.
    coupling : bool
        Apply the pair coupling (J4); False: two independent single-tendon estimators.
    play : float
        Coupling play as distal tendon displacement [m], >= 0.
    taut_tension : float
        Proximal tension from which a tendon's kinematic angle counts fully in (J3) [N], > 0.
    hold_rate, rate_time_constant : float
        Phase settings of :class:`~estimator.online.distal.DistalEstimator` [N/s], [s].
    tension_noise : float or (float, float)
        Noise sigma of each proximal load cell [N], >= 0: > 0 gives that tendon the noise band of
        :class:`~estimator.online.distal.DistalEstimator` with a slack release side (``released_slack``; a slide
        ends where the coupling moves the distal end), in the compiled pair step too. 0 (default): the envelope rule.

    Raises
    ------
    ValueError
        A non-finite or out-of-range argument (named in the message).
    """

    def __init__(self, model_a: SheathModel, model_b: SheathModel, pulley_radius: float, *, n_nodes: int = 100,
                 pretension: float | tuple[float, float] = 0.0, coupling: bool = True,
                 play: float = DEFAULT_PLAY, taut_tension: float = 0.1, hold_rate: float = 0.5,
                 rate_time_constant: float = 0.02, tension_noise: float | tuple[float, float] = 0.0):
        if not (math.isfinite(pulley_radius) and pulley_radius > 0):
            raise ValueError(f"pulley_radius must be > 0 m, got {pulley_radius!r}")
        if not (math.isfinite(play) and play >= 0):
            raise ValueError(f"play must be a distal displacement >= 0 m, got {play!r}")
        if not (math.isfinite(taut_tension) and taut_tension > 0):
            raise ValueError(f"taut_tension must be > 0 N, got {taut_tension!r}")
        self.taut = float(taut_tension)
        P = (pretension, pretension) if isinstance(pretension, (int, float, np.number)) else tuple(pretension)
        if len(P) != 2:
            raise ValueError(f"pretension must be one tension or one per tendon (a, b), got {pretension!r}")
        self.r = float(pulley_radius)
        self.coupling = bool(coupling)
        self.half_width = float(play) / self.r
        self.pretension = (float(P[0]), float(P[1]))
        S = ((tension_noise, tension_noise) if isinstance(tension_noise, (int, float, np.number))
             else tuple(tension_noise))
        if len(S) != 2:
            raise ValueError(f"tension_noise must be one sigma or one per tendon (a, b), got {tension_noise!r}")
        self.tendons = tuple(DistalEstimator(m, n_nodes=n_nodes, pretension=p, hold_rate=hold_rate,
                                             rate_time_constant=rate_time_constant, tension_noise=float(s),
                                             released_slack=True)
                             for m, p, s in zip((model_a, model_b), self.pretension, S, strict=False))
        self._dgain = tuple(distal_gains(t.log_gain) for t in self.tendons)
        self._x0: tuple[float, float] | None = None
        self._state = np.array([-1.0, 0.0, 0.0, 0.0, 0.0])    # coupling (see couple())
        # constants of the compiled step (joint_kernels.step_pair); the tendons' estimators step only through here
        self._const = tuple(np.stack((t.log_gain, t.weight, *g, t._lo_gain, t._hi_gain))
                            for t, g in zip(self.tendons, self._dgain, strict=False))
        self._noise = np.zeros((2, 6))                        # the tendons' band state in the compiled step
        ta, tb = self.tendons
        self._prm = np.array([ta.model.K, tb.model.K, ta.phase_band, tb.phase_band, ta.hold_rate, tb.hold_rate,
                              ta.tau, tb.tau, 0.0, 0.0, self.r, self.half_width, self.taut, float(self.coupling),
                              0.0, 0.0, 0.0, 0.0, 0.0, 0.0], dtype=np.float64)
        self._out = np.zeros(14)
        self._compiled = ta.phase_band > 0 and tb.phase_band > 0
        self._bank: Any = None        # the estimator.online.pair_bank.PairBank stepping this joint, if any

    def reset(self) -> None:
        """Back to uniform profiles at the pretension, no angle zero (the next :meth:`step` sets it)."""
        if self._bank is not None:
            self._bank.release()
        for t, p in zip(self.tendons, self.pretension, strict=False):
            t.reset(p)
        self._x0 = None
        self._state[0] = -1.0

    def zero(self, x_in_a: float, x_in_b: float) -> None:
        """Take the present pose as theta = 0: x_out,j(0) = x_in,j - e_j [m]."""
        if self._bank is not None:
            self._bank.release()
        self._x0 = (float(x_in_a) - self.tendons[0].elongation, float(x_in_b) - self.tendons[1].elongation)
        self._prm[8], self._prm[9] = self._x0
        self._state[0] = -1.0

    def angles(self, x_in_a: float, x_in_b: float) -> tuple[float, float]:
        """Kinematic angles (J1) of tendons a and b [rad] for encoder readings ``x_in_a``, ``x_in_b`` [m]."""
        x0a, x0b = self._x0 if self._x0 is not None else (0.0, 0.0)
        ta, tb = self.tendons
        return (x_in_a - ta.elongation - x0a) / self.r, -(x_in_b - tb.elongation - x0b) / self.r

    def step(self, T_in_a: float, x_in_a: float, T_in_b: float, x_in_b: float, t: float | None = None) -> PairSample:
        """Update with one proximal sample of both tendons (load cells [N], encoders [m], time [s]).

        The first call without a prior :meth:`zero` takes the pose after the update as theta = 0.

        Raises
        ------
        ValueError
            A non-finite sample (from :meth:`DistalEstimator.step`, naming the value).
        """
        if self._bank is not None:    # stepped on its own: its state back from the bank first
            self._bank.release()
        ta, tb = self.tendons
        if (self._compiled and t is not None and self._x0 is not None and ta._t_prev is not None
                and tb._t_prev is not None):
            s = self._step_compiled(ta, tb, T_in_a, x_in_a, T_in_b, x_in_b, t)
            if s is not None:
                return s
        Ta_prev, Tb_prev = ta.T_out, tb.T_out
        sa = ta.step(T_in_a, x_in_a, t)
        sb = tb.step(T_in_b, x_in_b, t)
        if self._x0 is None:
            self.zero(x_in_a, x_in_b)
        if self.coupling:
            ua, ub = self.angles(x_in_a, x_in_b)
            (dloa, dhia), (dlob, dhib) = self._dgain
            couple(ta.profile, dloa, dhia, ta.weight, ta.model.K, tb.profile, dlob, dhib, tb.weight, tb.model.K,
                   Ta_prev, Tb_prev, ua, ub, self.r, self.half_width, self._state)
            for est in self.tendons:
                if est.tension_noise > 0.0 and float(est.profile[-1]) != est.T_out:
                    est.end_slide()          # the coupling moved the distal end: its slide is over
                est.T_out = float(est.profile[-1])
                est.elongation = float(est.weight @ est.profile)
        ang_a, ang_b = self.angles(x_in_a, x_in_b)
        return PairSample(torque=self.r * (ta.T_out - tb.T_out),
                           angle=weighted_angle(ang_a, ang_b, T_in_a, T_in_b, self.taut),
                           T_out=(ta.T_out, tb.T_out), elongation=(ta.elongation, tb.elongation),
                           x_out=(x_in_a - ta.elongation, x_in_b - tb.elongation), angle_a=ang_a, angle_b=ang_b,
                           phase=(sa.phase, sb.phase))


    def _step_compiled(self, ta: DistalEstimator, tb: DistalEstimator, T_in_a: float, x_in_a: float,
                       T_in_b: float, x_in_b: float, t: float) -> PairSample | None:
        """:meth:`step` after the first sample in one compiled call (:func:`joint_kernels.step_pair`): the
        same numbers as the tendons' own steps and :func:`couple`. None (nothing changed) if not finite."""
        prm = self._prm
        prm[14], prm[15], prm[16], prm[17], prm[18], prm[19] = (ta._T_prev, tb._T_prev, ta._t_prev, tb._t_prev,
                                                                ta._rate, tb._rate)
        (Ca, Cb), out, N = self._const, self._out, self._noise
        for k, e in enumerate((ta, tb)):      # the tendons' own state in, and back out below
            N[k, 0], N[k, 1], N[k, 3], N[k, 4], N[k, 5] = e.band, e.tension_noise, e.velocity, e._slide[0], e._slide[1]
            N[k, 2] = math.nan if e._x_prev is None else e._x_prev
        if not step_pair(ta.profile, Ca, ta._phase_state, tb.profile, Cb, tb._phase_state, prm, self._state, N,
                          T_in_a, x_in_a, T_in_b, x_in_b, t, out):
            return None
        for k, e in enumerate((ta, tb)):
            e._x_prev, e.velocity, e._slide[0], e._slide[1] = float(N[k, 2]), float(N[k, 3]), N[k, 4], N[k, 5]
        o = out.tolist()
        pa, pb = _PHASES[int(o[10])], _PHASES[int(o[11])]
        ta.T_out, tb.T_out, ta.elongation, tb.elongation, ta.phase, tb.phase = o[2], o[3], o[4], o[5], pa, pb
        ta._T_prev, tb._T_prev, ta._t_prev, tb._t_prev, ta._rate, tb._rate = T_in_a, T_in_b, t, t, o[12], o[13]
        return PairSample(o[0], o[1], (o[2], o[3]), (o[4], o[5]), (o[6], o[7]), o[8], o[9], (pa, pb))


_PHASES = tuple(Phase(k) for k in range(len(Phase)))
