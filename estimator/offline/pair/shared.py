"""One set of physical parameters across tube configurations, with K growing with the bend (E6).

The per-configuration diagnosis (:mod:`estimator.offline.pair.diagnosis`) fits every configuration on its
own. Here one model holds for all of them: the capstan-joint pair model
(:mod:`estimator.pair_kernels`) with the transmission G, the tendon compliance lam and the joint
stiffness k shared, and the friction exponent of each tendon growing with the configuration's
accumulated bend angle N [rad] (docs/concepts/effects.md E6; Phee et al. 2009, eq. (2): K = mu sum(theta)):

    K_j(N) = K0_j + mu N,   j = a, b                                                          (S1)

K0_j is the rest of each tendon's route (its own base wrap), mu the friction coefficient of the
added bend. The angle starts at the measured first sample (no offset is fitted per configuration),
so a configuration is predicted from its command, its measured pretension and N alone.

Shared models are fitted the same way (training samples of every configuration together,
``scipy.optimize.least_squares``), so that the configuration dependence is tested, not assumed:

* ``capstan``             (S1) with mu free: G, lam, k, K0_a, K0_b, mu (6 parameters);
* ``capstan, mu = 0``     the same without E6 (5 parameters);
* ``seed+joint_backlash`` the seed model with a play of one width b (E12; 6 parameters: G, K_a,
  K_b, lam_a, lam_b, b), the other way to get a dead zone, which has no reason to grow with N;
* ``capstan, X per configuration`` for X = G, lam, k: (S1) with X fitted once per configuration,
  to see whether a second quantity drifts with the configuration besides K;
* ``capstan, G falls with N``: (S1) and G = G + G_N N (7 parameters), the drift the previous
  variants point at, as one shared slope;
* ``capstan+T`` and its variants (:data:`CHOICE`): the measured proximal tensions enter the fit too
  (weight :data:`TENSION_WEIGHT`), s = G / lam [N/rad] is fitted in place of lam and G is held at
  :data:`G_FIXED` (the data pin s, not G); ``G falls with N`` and ``lam grows with N`` add one slope;
* other ``capstan+T`` variants, not in the choice by default (each went to its neutral value or lost on
  the training cycles, docs/results/kaist.md): ``one K0`` (the same base friction for both
  tendons), ``mu per tendon``, ``pretension profile`` (E5), ``friction offset`` (E8), ``joint
  friction`` (E11/E12), ``bending-section friction`` (the tendons' wrap in the bending
  section is the joint angle, mu_b) and ``series compliance`` (E10, frictionless, ahead of the sheath),
  ``tendon toe`` (E9: toe, toe_tension; a tendon property, the same in every shape), ``k grows with N``
  (k = k + k_N N: the bent tube loads the bending section),
  ``capstan+T, drive observer`` and ``capstan, drive observer`` (the sheath entries moved by a
  drive compliance lam_d times the *measured* proximal tensions at every sample, :mod:`estimator.pair_kernels`;
  inputs: command and measured proximal tensions; lost on the training cycles).

The structure is chosen by leave-one-configuration-out on the training cycles
(:func:`estimator.offline.pair.general.choose_shared`). Leave-one-configuration-out for the report: the chosen
model is refitted on all samples up to the end of the test block of the other configurations and
predicts the left-out one.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from estimator.offline.pair.diagnosis_fit import FIT_TOL, MAX_NFEV, TENSION_FIT_WEIGHT
from estimator.offline.pair.models import Param, head, model_params, predict_model

__all__ = ["SharedModel", "SHARED_MODELS", "CHOICE", "COMPARED", "TENSION_WEIGHT", "LEAVE_ONE_OUT", "fit_shared",
           "predict_config", "leave_one_out", "shared_params", "config_values", "score"]

_MU = Param("mu", "1/rad", -1.0, 3.0, (0.15,), 0.02)
_MU_A = Param("mu_a", "1/rad", -1.0, 3.0, (0.15,), 0.02)
_MU_B = Param("mu_b", "1/rad", -1.0, 3.0, (0.15,), 0.02)
_S = Param("s", "N/rad", 0.05, 100.0, (3.0,), 0.2)
#: Weight of the proximal-tension residual [rad/N] in the "+T" shared fits: 1 N of tension error
#: costs as much as 0.57 deg of angle error (tension range ~10 N, angle range 20-70 deg). One value with the
#: per-configuration ``/T`` refits (:data:`estimator.offline.pair.diagnosis.TENSION_FIT_WEIGHT`).
TENSION_WEIGHT = TENSION_FIT_WEIGHT
#: Transmission G held in the "+T" models: with the tensions in the fit the data pin s = G / lam but
#: not G itself (bootstrap 95 % interval 3-15 when free; the held-out angle changes by < 0.3 deg for G
#: in 3-20, docs/results/kaist.md), so G is fixed and s carries the tendon compliance.
G_FIXED = 5.0
_G_N = Param("G_N", "1/rad", -5.0, 5.0, (0.0,), 0.02)
_LAM_N = Param("lam_N", "rad/N/rad", -2.0, 5.0, (0.05,), 0.02)
_K_N = Param("k_N", "N/rad/rad", -5.0, 20.0, (0.5,), 0.1)
_BAD = 10.0


@dataclass(frozen=True)
class SharedModel:
    """A model shared across configurations: name, structure, effects, whether K grows with N (S1),
    starting points (name -> value; missing names take their parameter's first start), the
    parameters fitted once per configuration instead (``per_config``, named ``G[i]`` etc.) and
    whether the transmission also changes linearly with N (``g_slope``: G = G + G_N N);
    ``tension_weight`` [rad/N] > 0 adds the measured proximal tensions to the fit (residual
    w (T_in,model - T_in,measured) beside the angle's), which pins the ratio of motor travel to
    tendon compliance; ``stiffness_ratio`` fits s = G / lam [N/rad] (proximal tension per radian of
    command with the tip held) in place of lam, the combination the data determine;
    ``fixed`` (name, value) pairs are held, not fitted; ``lam_slope``: the compliance grows with N,
    lam = lam + lam_N N (sheath axial compliance of the bent tube, E10); ``k_slope``: the joint stiffness grows
    with N, k = k + k_N N (the bent insertion tube loads the bending section, E11)."""

    name: str
    structure: str
    effects: tuple[str, ...]
    grows: bool
    starts: tuple[dict, ...]
    per_config: tuple[str, ...] = ()
    g_slope: bool = False
    tension_weight: float = 0.0
    stiffness_ratio: bool = False
    fixed: tuple[tuple[str, float], ...] = ()
    lam_slope: bool = False
    same_K0: bool = False
    mu_per_tendon: bool = False
    k_slope: bool = False


SHARED_MODELS = {m.name: m for m in (
    SharedModel("capstan", "capstan", (), True,
                ({"G": 1.4, "lam": 0.5, "k": 3.0, "K0_a": 0.6, "K0_b": 0.2, "mu": 0.13},
                 {"G": 2.5, "lam": 0.9, "k": 4.0, "K0_a": 0.6, "K0_b": 0.2, "mu": 0.13})),
    SharedModel("capstan, mu = 0", "capstan", (), False,
                ({"G": 1.4, "lam": 0.5, "k": 3.0, "K_a": 0.9, "K_b": 0.4},
                 {"G": 2.5, "lam": 0.9, "k": 4.0, "K_a": 1.2, "K_b": 0.6})),
    SharedModel("seed+joint_backlash", "seed", ("joint_backlash",), False,
                ({"G": 1.2, "K_a": 0.1, "K_b": 0.1, "lam_a": 0.1, "lam_b": 0.1, "b": 0.2},
                 {"G": 1.5, "K_a": 0.8, "K_b": 0.5, "lam_a": 0.2, "lam_b": 0.2, "b": 0.3})),
    SharedModel("capstan, G falls with N", "capstan", (), True,
                ({"G": 1.9, "G_N": -0.13, "lam": 0.3, "k": 8.0, "K0_a": 1.4, "K0_b": 0.8, "mu": 0.2},
                 {"G": 2.5, "G_N": 0.0, "lam": 1.0, "k": 3.6, "K0_a": 0.55, "K0_b": 0.15, "mu": 0.12}), (), True),
    *(SharedModel(f"capstan, {q} per configuration", "capstan", (), True,
                  ({"G": 1.6, "lam": 0.5, "k": 5.0, "K0_a": 0.8, "K0_b": 0.3, "mu": 0.15},), (q,))
      for q in ("G", "lam", "k")),
    SharedModel("capstan+T", "capstan", (), True,
                ({"s": 3.5, "k": 3.0, "K0_a": 0.6, "K0_b": 0.2, "mu": 0.13},
                 {"s": 2.5, "k": 5.0, "K0_a": 0.55, "K0_b": 0.25, "mu": 0.13}),
                tension_weight=TENSION_WEIGHT, stiffness_ratio=True, fixed=(("G", G_FIXED),)),
    SharedModel("capstan+T, G falls with N", "capstan", (), True,
                ({"G_N": -0.29, "s": 3.1, "k": 5.8, "K0_a": 0.66, "K0_b": 0.34, "mu": 0.07},
                 {"G_N": -0.12, "s": 6.9, "k": 7.9, "K0_a": 1.5, "K0_b": 0.87, "mu": 0.24}), (), True,
                tension_weight=TENSION_WEIGHT, stiffness_ratio=True, fixed=(("G", G_FIXED),)),
    SharedModel("capstan+T, lam grows with N", "capstan", (), True,
                ({"lam_N": 0.095, "s": 3.16, "k": 5.86, "K0_a": 0.67, "K0_b": 0.31, "mu": 0.10},
                 {"lam_N": 0.03, "s": 2.6, "k": 4.7, "K0_a": 0.55, "K0_b": 0.22, "mu": 0.12}),
                tension_weight=TENSION_WEIGHT, stiffness_ratio=True, fixed=(("G", G_FIXED),), lam_slope=True),
    SharedModel("capstan+T, k grows with N", "capstan", (), True,
                ({"k_N": 0.5, "s": 2.6, "k": 5.0, "K0_a": 0.57, "K0_b": 0.2, "mu": 0.14},
                 {"k_N": 2.0, "s": 2.6, "k": 3.0, "K0_a": 0.57, "K0_b": 0.2, "mu": 0.14}),
                tension_weight=TENSION_WEIGHT, stiffness_ratio=True, fixed=(("G", G_FIXED),), k_slope=True),
    SharedModel("capstan+T, one K0", "capstan", (), True,
                ({"s": 2.6, "k": 5.0, "K0": 0.4, "mu": 0.14}, {"s": 3.0, "k": 4.0, "K0": 0.3, "mu": 0.12}),
                tension_weight=TENSION_WEIGHT, stiffness_ratio=True, fixed=(("G", G_FIXED),), same_K0=True),
    SharedModel("capstan+T, mu per tendon", "capstan", (), True,
                ({"s": 2.6, "k": 5.0, "K0_a": 0.57, "K0_b": 0.2, "mu_a": 0.12, "mu_b": 0.16},
                 {"s": 2.6, "k": 5.0, "K0_a": 0.6, "K0_b": 0.1, "mu_a": 0.08, "mu_b": 0.25}),
                tension_weight=TENSION_WEIGHT, stiffness_ratio=True, fixed=(("G", G_FIXED),), mu_per_tendon=True),
    SharedModel("capstan+T, pretension profile", "capstan", ("pretension_profile",), True,
                ({"s": 2.6, "k": 5.0, "K0_a": 0.57, "K0_b": 0.2, "mu": 0.14, "shape": 0.5},
                 {"s": 2.6, "k": 5.0, "K0_a": 0.57, "K0_b": 0.2, "mu": 0.14, "shape": 0.9}),
                tension_weight=TENSION_WEIGHT, stiffness_ratio=True, fixed=(("G", G_FIXED),)),
    SharedModel("capstan+T, friction offset", "capstan", ("friction_offset",), True,
                ({"s": 2.6, "k": 5.0, "K0_a": 0.57, "K0_b": 0.2, "mu": 0.14, "a": 0.3},
                 {"s": 2.6, "k": 5.0, "K0_a": 0.4, "K0_b": 0.1, "mu": 0.1, "a": 1.5}),
                tension_weight=TENSION_WEIGHT, stiffness_ratio=True, fixed=(("G", G_FIXED),)),
    SharedModel("capstan+T, joint friction", "capstan", ("joint_friction",), True,
                ({"s": 2.6, "k": 5.0, "K0_a": 0.57, "K0_b": 0.2, "mu": 0.14, "tau_c": 0.2},
                 {"s": 2.6, "k": 5.0, "K0_a": 0.5, "K0_b": 0.2, "mu": 0.1, "tau_c": 0.8}),
                tension_weight=TENSION_WEIGHT, stiffness_ratio=True, fixed=(("G", G_FIXED),)),
    SharedModel("capstan+T, tendon toe", "capstan", ("tendon_toe",), True,
                # one start: a second one (toe 8, T_c 0.5 N) ended higher on the KAIST training cycles
                ({"s": 2.6, "k": 5.0, "K0_a": 0.57, "K0_b": 0.2, "mu": 0.14, "toe": 2.0, "toe_tension": 1.0},),
                tension_weight=TENSION_WEIGHT, stiffness_ratio=True, fixed=(("G", G_FIXED),)),
    SharedModel("capstan+T, bending-section friction", "capstan", ("bending_friction",), True,
                ({"s": 2.6, "k": 5.0, "K0_a": 0.57, "K0_b": 0.2, "mu": 0.14, "mu_b": 0.2},
                 {"s": 2.6, "k": 5.0, "K0_a": 0.57, "K0_b": 0.2, "mu": 0.14, "mu_b": 0.8}),
                tension_weight=TENSION_WEIGHT, stiffness_ratio=True, fixed=(("G", G_FIXED),)),
    SharedModel("capstan+T, series compliance", "capstan", ("series_compliance",), True,
                ({"s": 2.6, "k": 5.0, "K0_a": 0.57, "K0_b": 0.2, "mu": 0.14, "lam_s": 0.5},
                 {"s": 2.6, "k": 5.0, "K0_a": 0.57, "K0_b": 0.2, "mu": 0.14, "lam_s": 2.0}),
                tension_weight=TENSION_WEIGHT, stiffness_ratio=True, fixed=(("G", G_FIXED),)),
    SharedModel("capstan+T, drive observer", "capstan", ("drive_observer",), True,
                ({"s": 2.6, "k": 5.0, "K0_a": 0.57, "K0_b": 0.2, "mu": 0.14, "lam_d": 0.1},
                 {"s": 2.6, "k": 5.0, "K0_a": 0.57, "K0_b": 0.2, "mu": 0.14, "lam_d": 0.5}),
                tension_weight=TENSION_WEIGHT, stiffness_ratio=True, fixed=(("G", G_FIXED),)),
    SharedModel("capstan, drive observer", "capstan", ("drive_observer",), True,
                ({"G": 1.4, "lam": 0.5, "k": 3.0, "K0_a": 0.6, "K0_b": 0.2, "mu": 0.13, "lam_d": 0.1},
                 {"G": 2.5, "lam": 0.9, "k": 4.0, "K0_a": 0.6, "K0_b": 0.2, "mu": 0.13, "lam_d": 0.3})),
)}
#: Candidates of the shared structure, in the order of the forward choice by leave-one-configuration-out
#: on the training cycles (:func:`estimator.offline.pair.general.choose_shared`). ``capstan+T, tendon toe``
#: (E9) is not among them: it does not pass on the training cycles (price 1.47) and its leave-one-out refits
#: would cost a fifth of the whole KAIST analysis, which computes the uncertainty of every reported figure
#: instead; it stays available by name.
CHOICE = ("capstan", "capstan+T", "capstan+T, G falls with N", "capstan+T, lam grows with N")
#: Shared models refitted leaving each configuration out besides the chosen one (none: each costs five refits).
LEAVE_ONE_OUT: tuple[str, ...] = ()
#: Shared models fitted for comparison by :func:`shared_analysis` (besides :data:`CHOICE`).
COMPARED = ("capstan, mu = 0", "seed+joint_backlash")


def shared_params(m: SharedModel, n_configs: int = 1) -> tuple[Param, ...]:
    """Parameters of a shared model over ``n_configs`` configurations: the structure's and effects'
    without theta0, K_j renamed K0_j and mu added when K grows with N, each ``per_config`` one
    repeated as ``name[i]``."""
    out = []
    held = dict(m.fixed)
    for p in model_params(m.structure, m.effects):
        if p.name == "theta0" or p.name in held:
            continue
        if m.grows and m.same_K0 and p.name == "K_b":
            continue
        if m.grows and p.name in ("K_a", "K_b"):
            p = Param("K0" if m.same_K0 else "K0" + p.name[1:], p.unit, p.lo, p.hi, p.starts, p.scale)
        if m.stiffness_ratio and p.name == "lam":
            p = _S
        if p.name in m.per_config:
            out += [Param(f"{p.name}[{i}]", p.unit, p.lo, p.hi, p.starts, p.scale) for i in range(n_configs)]
        else:
            out.append(p)
    mus = ((_MU_A, _MU_B) if m.mu_per_tendon else (_MU,)) if m.grows else ()
    return (tuple(out) + mus + ((_G_N,) if m.g_slope else ()) + ((_LAM_N,) if m.lam_slope else ())
            + ((_K_N,) if m.k_slope else ()))


def config_values(m: SharedModel, values: dict[str, float], rec, bend: float, i: int = 0) -> dict[str, float]:
    """The model values of configuration ``i`` in a shared fit: K_j = K0_j + mu N (clipped at 0),
    the per-configuration parameters of ``i``, theta0 from the first measured angle."""
    v = {**{k: x for k, x in values.items() if "[" not in k}, **dict(m.fixed)}
    v.update({q: values[f"{q}[{i}]"] for q in m.per_config})
    if m.grows and m.same_K0:
        v["K_a"] = v["K_b"] = max(v.pop("K0") + v["mu"] * bend, 0.0)
        v.pop("mu")
    elif m.grows and m.mu_per_tendon:
        for j in ("a", "b"):
            v[f"K_{j}"] = max(v.pop(f"K0_{j}") + v.pop(f"mu_{j}") * bend, 0.0)
    elif m.grows:
        for j in ("a", "b"):
            v[f"K_{j}"] = max(v.pop(f"K0_{j}") + v["mu"] * bend, 0.0)
        v.pop("mu")
    if m.g_slope:
        v["G"] = max(v["G"] + v.pop("G_N") * bend, 1e-6)
    if m.stiffness_ratio:
        v["lam"] = max(v["G"] / v.pop("s"), 1e-4)
    if m.lam_slope:
        v["lam"] = max(v["lam"] + v.pop("lam_N") * bend, 1e-4)
    if m.k_slope:
        v["k"] = max(v["k"] + v.pop("k_N") * bend, 1e-3)
    g = v["G"] * float(rec.command[0]) if m.structure == "seed" else 0.0
    v["theta0"] = float(rec.angle[0]) - g
    return v


def predict_config(m: SharedModel, values: dict, rec, bend: float, i: int = 0) -> np.ndarray:
    """Angle [rad], shape (n,), of configuration ``i`` (bend [rad]) under a shared fit."""
    return predict_model(m.structure, m.effects, config_values(m, values, rec, bend, i), rec)[0]


def fit_shared(m: SharedModel, recs: list, bends: list[float], fit_on: list, *,
               starts: list[dict] | None = None, max_nfev: int = MAX_NFEV, full: bool = False):
    """Fit one shared model on the ``fit_on`` samples of every recording together.

    Parameters
    ----------
    m : SharedModel
    recs : recordings (time, command, T_a, T_b, angle), one per configuration
    bends : accumulated bend angle N of each configuration [rad]
    fit_on : sample slice (or index array, repeats allowed: a bootstrap) of each recording used in
        the fit (the models run from sample 0)
    starts : starting values (default ``m.starts``)
    max_nfev : most residual evaluations per start
    full : also return the ``scipy.optimize.OptimizeResult`` of the best start (jac, fun)

    Returns
    -------
    dict name -> value (SI units) of :func:`shared_params` (and the result when ``full``).

    Raises
    ------
    ValueError
        ``recs``, ``bends`` and ``fit_on`` of different lengths or empty.
    """
    if not (len(recs) == len(bends) == len(fit_on) > 0):
        raise ValueError("recs, bends and fit_on must be non-empty and of equal length")
    if m.per_config and len(recs) < 2:
        raise ValueError(f"{m.name}: per-configuration parameters need at least 2 configurations")
    params = shared_params(m, len(recs))
    names = [p.name for p in params]
    lo, hi = np.array([p.lo for p in params]), np.array([p.hi for p in params])
    ys = [np.asarray(r.angle, dtype=float)[s] for r, s in zip(recs, fit_on, strict=False)]
    w = m.tension_weight
    Ts = [np.column_stack([r.T_a, r.T_b])[s] for r, s in zip(recs, fit_on, strict=False)] if w > 0 else []

    # causal models: run up to the fitted samples only
    parts = [head(r, s) for r, s in zip(recs, fit_on, strict=False)]

    def residual(x: np.ndarray) -> np.ndarray:
        v = dict(zip(names, map(float, x), strict=False))
        out = []
        for i, (r, b, s, y) in enumerate(zip(parts, bends, fit_on, ys, strict=False)):
            try:
                th, T = predict_model(m.structure, m.effects, config_values(m, v, r, b, i), r)
                out.append(th[s] - y)
                if w > 0 and T is not None:
                    out.append((w * (T[s] - Ts[i])).ravel())
            except ValueError:
                out.append(np.full(y.size * (3 if w > 0 else 1), _BAD))
        return np.concatenate(out)

    best = None
    for s in (starts or m.starts):
        x0 = np.clip([s.get(p.name, s.get(p.name.split("[")[0], p.starts[0])) for p in params], lo, hi)
        sol = least_squares(residual, x0, bounds=(lo, hi), x_scale=[p.scale for p in params], diff_step=1e-3,
                            max_nfev=max_nfev, ftol=FIT_TOL, xtol=FIT_TOL)
        if best is None or sol.cost < best.cost:
            best = sol
    assert best is not None                       # at least one start
    values = dict(zip(names, map(float, best.x), strict=False))
    return (values, best) if full else values


def score(m: SharedModel, values: dict, recs: list, bends: list[float], train: list[slice],
          test: list[slice]) -> list[dict]:
    """Per configuration: rmse on ``train`` and ``test`` [deg], the max |error| on test [deg], K_a and
    K_b [-] (shared models with K growing), and the prediction [rad] (key ``angle``, not JSON)."""
    out = []
    for i, (r, b, tr, te) in enumerate(zip(recs, bends, train, test, strict=False)):
        th = predict_config(m, values, r, b, i)
        err = th - np.asarray(r.angle, dtype=float)
        v = config_values(m, values, r, b, i)
        out.append({"rmse_train_deg": math.degrees(float(np.sqrt(np.mean(err[tr] ** 2)))),
                    "rmse_test_deg": math.degrees(float(np.sqrt(np.mean(err[te] ** 2)))),
                    "max_abs_test_deg": math.degrees(float(np.max(np.abs(err[te])))),
                    "K_a": v.get("K_a"), "K_b": v.get("K_b"), **{q: v[q] for q in m.per_config},
                    "angle": th})
    return out


def leave_one_out(m: SharedModel, recs: list, bends: list[float], fit_on: list[slice], test: list[slice],
                  start: dict, progress: Callable[[str], None] | None = None) -> list[dict]:
    """Refit the shared model without each configuration in turn and predict that one.

    ``fit_on`` [i] is the part of configuration i used when it is not left out (e.g. both cycles);
    ``start`` the full shared fit (the starting point). Returns per configuration:
    ``rmse_test_deg`` (the left-out configuration's test block), ``rmse_all_deg`` (all its samples),
    ``params`` (the refit), ``angle`` [rad] (not JSON).
    """
    out = []
    for i, (r, b, te) in enumerate(zip(recs, bends, test, strict=False)):
        keep = [j for j in range(len(recs)) if j != i]
        v = fit_shared(m, [recs[j] for j in keep], [bends[j] for j in keep], [fit_on[j] for j in keep],
                       starts=[start])
        th = predict_config(m, v, r, b)
        err = th - np.asarray(r.angle, dtype=float)
        out.append({"rmse_test_deg": math.degrees(float(np.sqrt(np.mean(err[te] ** 2)))),
                    "rmse_all_deg": math.degrees(float(np.sqrt(np.mean(err ** 2)))), "params": v, "angle": th})
        if progress:
            progress(f"leave out {i}")
    return out
