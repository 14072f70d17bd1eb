"""The pair models of the offline study, one sample at a time: what the diagnosis fits, run in the live loop.

:class:`PairModelEstimator` runs a pair model (a structure plus effects, with the parameters the study fits,
:mod:`estimator.offline.pair.models`) causally: each :meth:`~PairModelEstimator.step` takes the present command
and proximal tensions and returns the distal angle, keeping the tension profiles, the joint angle and the
play and delay state between calls. Over a recording it gives the batch prediction
(``estimator.offline.pair.models.predict_model``) sample by sample:

* structure ``capstan`` (the capstan-joint pair model, (P1)-(P4) of :mod:`estimator.pair_kernels`): the same
  compiled sample loop as the batch model (:func:`estimator.pair_loops.run_pair`), run over one sample per
  call on the state the previous call left, so the numbers are the batch's bit for bit. The proximal tensions
  are predicted; the measured ones are read only by the drive-side observer (``drive_observer``);
* structure ``seed`` (the seed pair model): each tendon's profile memory driven by its measured proximal tension
  (:func:`estimator.sheath.profile_batch` over one sample, :data:`SEED_NODES` elements, the study's
  ``mean_tension``), theta = G c - lam_a (E_a - E_a(0)) + lam_b (E_b - E_b(0)) + theta_0;
* ``joint_backlash`` (E12): the play y_k = min(max(y_{k-1}, u_k - b), u_k + b), from y = u at the first sample;
* ``sensor_delay`` (E14) with tau >= 0: a delay line on the time stamps, the angle at t - tau interpolated
  linearly in the angles already computed (``np.interp`` of the past, as the batch model); tau < 0 would read
  the future and is refused.

:data:`PER_CYCLE` says for every pair effect how it runs per cycle (or why it does not).
"""
from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping
from typing import NamedTuple

import numpy as np

from estimator.pair_kernels import (
    EFFECT_PARAMS,
    EFFECT_STRUCTURES,
    STRUCTURE_PARAMS,
    PairKernel,
    PairState,
    pair_kernel,
)
from estimator.sheath import SheathModel, profile_batch

__all__ = ["PER_CYCLE", "SEED_NODES", "PairModelSample", "PairModelEstimator"]

#: Profile elements of the seed structure's tendons (those of the study's seed model, ``mean_tension``).
SEED_NODES = 50

#: For every pair effect (the ids of the offline catalogue): (has a per-cycle form, how it runs per cycle or
#: why it does not).
PER_CYCLE: dict[str, tuple[bool, str]] = {
    "capstan_joint": (True, "the capstan structure: the compiled sample loop of the batch model, one sample per "
                            "step on the kept profiles and joint angle"),
    "joint_backlash": (True, "a play operator on the angle, its output kept between steps"),
    "sensor_delay": (True, "tau >= 0 only: a delay line on the time stamps (the angle at t - tau interpolated in "
                           "the past); tau < 0 reads the future, so it has no causal form and is refused"),
    "friction_offset": (True, "the capstan law on T + a inside the profile memory (both structures)"),
    "pretension_profile": (True, "the initial profile, set at the first step"),
    "joint_friction": (True, "the joint's dead band inside the compiled substep"),
    "series_compliance": (True, "extra frictionless nodes of the tendon arrays"),
    "joint_stiffening": (True, "the joint stiffness inside the compiled substep"),
    "tendon_toe": (True, "the tangent-then-secant node weights inside the compiled substep"),
    "bending_friction": (True, "the bending section's balance inside the compiled substep"),
    "drive_observer": (True, "reads the measured proximal tensions of the present step (causal)"),
}


class PairModelSample(NamedTuple):
    """One step's output: the distal angle [rad] and, for the capstan structure, the predicted proximal
    tensions T_a, T_b [N] (NaN for the seed structure, which reads the measured ones)."""

    angle: float
    T_a: float
    T_b: float


class PairModelEstimator:
    """A pair model (structure + effects + fitted values) run one sample per :meth:`step` (module docstring).

    Parameters
    ----------
    structure : ``"seed"`` or ``"capstan"``
    effects : effect ids (:data:`PER_CYCLE`; each applies to the structure, ``estimator.pair_kernels.
        EFFECT_STRUCTURES``), in any order
    values : every parameter of the model (``estimator.pair_kernels.STRUCTURE_PARAMS`` of the structure,
        ``EFFECT_PARAMS`` of each effect) in SI units, and no other: G [-], lam, lam_a, lam_b [rad/N], K_a, K_b [-],
        k [N/rad], theta0 [rad], b [rad], tau [s], a [N], shape [-], tau_c [N], lam_s [rad/N], k2 [N/rad],
        theta_c [rad], toe [-], toe_tension [N], mu_b [1/rad], lam_d [rad/N]
    pretension : (T_a, T_b) [N], the proximal tensions measured at the first sample (the batch model's
        ``rec.T_a[0]``, ``rec.T_b[0]``), >= 0
    n_nodes : elements per sheath of the capstan structure (the seed structure uses :data:`SEED_NODES`)
    substeps : steps per sample of the capstan structure, >= 1

    Raises
    ------
    ValueError
        An unknown structure or effect, an effect that does not apply to the structure, a missing or extra
        parameter, ``sensor_delay`` with tau < 0 (it reads the future), ``joint_backlash`` with b < 0, or a value
        the kernels refuse (:func:`estimator.pair_kernels.pair_kernel`; the seed's K outside what
        :class:`estimator.sheath.SheathModel` accepts).
    """

    def __init__(self, structure: str, effects: tuple[str, ...] | list[str], values: Mapping[str, float],
                 pretension: tuple[float, float], n_nodes: int = 24, substeps: int = 1):
        self.structure, self.effects = structure, tuple(effects)
        v = _checked_values(structure, self.effects, values)
        P = (float(pretension[0]), float(pretension[1]))
        if not all(math.isfinite(x) and x >= 0.0 for x in P):
            raise ValueError(f"pretension must be two finite tensions >= 0 [N], got {pretension!r}")
        self._v = v
        self._a = v.get("a", 0.0)
        self._b = v.get("b") if "joint_backlash" in self.effects else None
        if self._b is not None and not (math.isfinite(self._b) and self._b >= 0.0):
            raise ValueError(f"joint_backlash: b must be finite and >= 0 [rad], got {self._b!r}")
        self._tau = v.get("tau") if "sensor_delay" in self.effects else None
        if self._tau is not None and not (math.isfinite(self._tau) and self._tau >= 0.0):
            raise ValueError(f"sensor_delay: tau = {self._tau!r} s; a negative delay reads the angle of a later "
                             "sample (the future), which a per-cycle estimator cannot; only tau >= 0 runs live")
        self._observed = "drive_observer" in self.effects
        self._kernel: PairKernel | None = None
        if structure == "capstan":
            self._kernel = pair_kernel(P, v["G"], (v["lam"], v["lam"]), (v["K_a"], v["K_b"]), v["k"],
                                       lam_s=v.get("lam_s", 0.0), tau_c=v.get("tau_c", 0.0), shape=v.get("shape", 0.0),
                                       offset=self._a, k2=v.get("k2", 0.0), theta_c=v.get("theta_c", 0.0),
                                       toe=v.get("toe", 0.0), toe_tension=v.get("toe_tension", 1.0),
                                       mu_b=v.get("mu_b", 0.0), n_nodes=n_nodes, substeps=substeps,
                                       observed=self._observed, lam_d=v.get("lam_d", 0.0))
            self._c = np.empty(1)
            self._Tm = np.empty((1, 2)) if self._observed else np.zeros((0, 2))
            self._th = np.empty(1)
            self._T = np.empty((1, 2))
        else:
            self._seed_nodes = [SheathModel(K=v[K], compliance=1.0).nodes(SEED_NODES) for K in ("K_a", "K_b")]
            self._pretension = (P[0] + self._a, P[1] + self._a)
        self.reset()

    def reset(self) -> None:
        """Back to the state before the first sample (rest at the pretensions, theta = 0, play and delay empty)."""
        self._state: PairState | None = None
        self._steps = 0
        self._y = 0.0                                  # play output [rad]
        self._hist: deque[tuple[float, float]] = deque()   # (t [s], angle [rad]) of the delay line
        if self._kernel is None:
            self._prof = [np.full(lg.size, P0) for (lg, _), P0 in zip(self._seed_nodes, self._pretension, strict=True)]
            self._E0 = [float(w.sum() * P0) for (_, w), P0 in zip(self._seed_nodes, self._pretension, strict=True)]
            self._one = np.empty(1)

    @property
    def steps(self) -> int:
        """Samples stepped since construction or :meth:`reset`."""
        return self._steps

    def step(self, command: float, T_a: float, T_b: float, t: float) -> PairModelSample:
        """Advance the model by one sample and return its distal angle.

        Parameters
        ----------
        command : motor-side command c [rad] (P1)
        T_a, T_b : measured proximal tensions [N] (read by the seed structure and the drive-side observer)
        t : time stamp [s], strictly increasing from step to step (read by ``sensor_delay``)

        Returns
        -------
        PairModelSample: angle [rad] (theta + theta_0, through the play and the delay line when on), and the
        predicted proximal tensions T_a, T_b [N] of the capstan structure (NaN for the seed structure).

        Raises
        ------
        ValueError
            A non-finite command, tension or time stamp that the model reads, or (``sensor_delay``) a time stamp
            not after the previous one.
        """
        if not math.isfinite(command):
            raise ValueError(f"command must be a finite angle [rad], got {command!r}")
        if self._kernel is not None:
            theta, Ta_hat, Tb_hat = self._step_capstan(float(command), T_a, T_b)
        else:
            theta = self._step_seed(float(command), T_a, T_b)
            Ta_hat = Tb_hat = math.nan
        if self._b is not None:                        # play, E12 (estimator.offline.pair.fit.play)
            y = theta if self._steps == 0 else self._y
            if y < theta - self._b:
                y = theta - self._b
            elif y > theta + self._b:
                y = theta + self._b
            self._y = theta = y
        if self._tau is not None:                      # delay line, E14
            theta = self._delay(float(t), theta, self._tau)
        self._steps += 1
        return PairModelSample(theta, Ta_hat, Tb_hat)

    def _step_capstan(self, command: float, T_a: float, T_b: float) -> tuple[float, float, float]:
        """One sample of the compiled loop (P1)-(P4) on the kept state: (theta + theta_0 [rad], T_a, T_b [N])."""
        kern = self._kernel
        assert kern is not None
        if self._observed:
            if not (math.isfinite(T_a) and math.isfinite(T_b)):
                raise ValueError(f"the drive-side observer needs finite proximal tensions [N], got {T_a!r}, {T_b!r}")
            self._Tm[0, 0] = T_a
            self._Tm[0, 1] = T_b
        state = self._state
        if state is None:
            state = self._state = kern.start(command, T_a, T_b) if self._observed else kern.start(command)
        self._c[0] = command
        kern.run(state, self._c, self._Tm, 0, 1, self._th, self._T)
        return (float(self._th[0]) + self._v["theta0"], float(self._T[0, 0]) - kern.offset,
                float(self._T[0, 1]) - kern.offset)

    def _step_seed(self, command: float, T_a: float, T_b: float) -> float:
        """One sample of the seed model's two profile memories (estimator.offline.pair.fit.mean_tension): theta
        [rad]."""
        if not (math.isfinite(T_a) and math.isfinite(T_b)):
            raise ValueError(f"the seed structure needs finite proximal tensions [N], got {T_a!r}, {T_b!r}")
        dE = []
        for j, T in enumerate((T_a, T_b)):
            log_gain, weight = self._seed_nodes[j]
            self._one[0] = T + self._a
            _, E, self._prof[j] = profile_batch(self._prof[j], log_gain, weight, self._one)
            dE.append(float(E[0]) - self._E0[j])
        v = self._v
        return v["G"] * command - v["lam_a"] * dE[0] + v["lam_b"] * dE[1] + v["theta0"]

    def _delay(self, t: float, theta: float, tau: float) -> float:
        """The delay line: the angle at t - ``tau`` [rad] (``tau`` [s] >= 0), linear between the kept samples
        (np.interp, held at the first sample before it)."""
        h = self._hist
        if not math.isfinite(t) or (h and t <= h[-1][0]):
            raise ValueError(f"sensor_delay needs finite, strictly increasing time stamps [s], got {t!r} after "
                             f"{h[-1][0] if h else None!r}")
        h.append((t, theta))
        x = t - tau
        while len(h) >= 2 and h[1][0] <= x:            # keep one sample at or before t - tau
            h.popleft()
        if len(h) == 1:
            return float(np.interp(x, [h[0][0]], [h[0][1]]))
        ts, ys = zip(*h, strict=True)
        return float(np.interp(x, ts, ys))


def _checked_values(structure: str, effects: tuple[str, ...], values: Mapping[str, float]) -> dict[str, float]:
    """The model's parameters from ``values`` as floats (class Raises: unknown names, missing or extra ones)."""
    if structure not in STRUCTURE_PARAMS:
        raise ValueError(f"unknown pair structure {structure!r}; known: {', '.join(STRUCTURE_PARAMS)}")
    for e in effects:
        if e not in EFFECT_PARAMS:
            raise ValueError(f"unknown pair effect {e!r}; known: {', '.join(EFFECT_PARAMS)}")
        if structure not in EFFECT_STRUCTURES[e] or e == "capstan_joint":
            raise ValueError(f"effect {e!r} does not apply to the {structure} structure")
    if len(set(effects)) != len(effects):
        raise ValueError(f"effects repeat: {effects!r}")
    names = STRUCTURE_PARAMS[structure] + tuple(p for e in effects for p in EFFECT_PARAMS[e])
    missing = [n for n in names if n not in values]
    extra = sorted(set(values) - set(names))
    if missing or extra:
        raise ValueError(f"values must hold exactly the parameters of {'+'.join((structure, *effects))} "
                         f"({', '.join(names)}); missing {missing}, not of the model {extra}")
    return {n: float(values[n]) for n in names}
