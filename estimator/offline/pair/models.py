"""The pair models and the pair-level effect catalogue of the KAIST diagnosis.

A model is a structure plus a list of effects, written ``"capstan+joint_backlash"``:

* structure ``seed`` - the seed pair model (:mod:`estimator.offline.pair.fit`): each tendon's elongation from
  its profile memory driven by its *measured* proximal tension, the angle following the tendon
  kinematics at every sample. Parameters G [-], K_a, K_b [-], lam_a, lam_b [rad/N], theta0 [rad].
* structure ``capstan`` - the capstan-joint pair model (:mod:`estimator.pair_kernels`): the same
  two profile memories and the joint as one mechanism driven by the motor command, the joint held
  by its stiffness and moved only when a slip front reaches a tip. Parameters G [-], lam [rad/N],
  K_a, K_b [-], k [N/rad], theta0 [rad]; the proximal tensions are predicted, not used.

Effects (the numbers of docs/concepts/effects.md; each adds the parameters listed, with bounds):

========================= ============ ================================================ ==================
id                        literature   extension                                        structures
========================= ============ ================================================ ==================
``capstan_joint``         E1, E11, E13 seed -> capstan structure (no extra parameter)    seed
``joint_backlash``        E12          play of half-width b [rad] between pulley and link both
``sensor_delay``          E14          tracker angle delayed by tau [s]: theta(t - tau)  both
``friction_offset``       E8           capstan law on T + a [N]                          both
``pretension_profile``    E5           initial profile P e^{-shape mu theta(s)}          capstan
``joint_friction``        E11, E12     Coulomb torque tau_c [N] (per r) in the joint     capstan
``series_compliance``     E10          frictionless compliance lam_s [rad/N] ahead of    capstan
                                       the sheath (drive, load cell, sheath compression)
``joint_stiffening``      E11          joint stiffness k + k2 [N/rad] beyond |theta| >    capstan
                                       theta_c [rad] (bending section stiffens)
``tendon_toe``            E9           tendon compliance lam (1 + toe e^{-T/toe_tension}) capstan
                                       (softer at low tension: strands bedding in)
``bending_friction``      E7, E13      the tendons' wrap in the bending section is the  shared models
                                       joint angle: capstan factor e^{-+mu_b |theta|}    only (not offered
                                       on each distal tension                           per configuration)
========================= ============ ================================================ ==================

Inputs of every model: a recording with ``time`` [s], ``command`` [rad] (motor side), ``T_a``,
``T_b`` [N] (proximal tensions; the capstan structure uses only their first values, the measured
pretension) and ``angle`` [rad] (the target), all of shape (n,) (e.g.
:class:`recorded.kaist.KaistRecording`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from estimator.offline.pair.fit import PairParams, mean_tension, play
from estimator.pair_kernels import simulate_pair

__all__ = ["Param", "PairEffect", "STRUCTURES", "PAIR_EFFECTS", "CAUSE_OF_SEED", "model_id", "parse_model",
           "model_params", "applicable", "predict_model", "head"]


@dataclass(frozen=True)
class Param:
    """One fitted parameter: name, unit, bounds [lo, hi], start values (each tried when the parameter
    is new to a model) and a scale (its typical size, for the optimiser)."""

    name: str
    unit: str
    lo: float
    hi: float
    starts: tuple[float, ...]
    scale: float


@dataclass(frozen=True)
class PairEffect:
    """One pair-level effect: id, literature number(s), physical cause, signature in the angle data,
    the model extension, its parameters and the structures it applies to."""

    id: str
    literature: str
    cause: str
    signature: str
    extension: str
    parameters: tuple[Param, ...]
    structures: tuple[str, ...]


STRUCTURES: dict[str, tuple[Param, ...]] = {
    "seed": (Param("G", "-", 0.0, 20.0, (1.3,), 0.1), Param("K_a", "-", 0.0, 5.0, (0.1,), 0.1),
             Param("K_b", "-", 0.0, 5.0, (0.1,), 0.1), Param("lam_a", "rad/N", 0.0, 10.0, (0.1,), 0.01),
             Param("lam_b", "rad/N", 0.0, 10.0, (0.1,), 0.01), Param("theta0", "rad", -1.0, 1.0, (0.0,), 0.01)),
    "capstan": (Param("G", "-", 0.0, 20.0, (1.4,), 0.1), Param("lam", "rad/N", 1e-4, 10.0, (0.4,), 0.05),
                Param("K_a", "-", 0.0, 4.0, (0.8,), 0.1), Param("K_b", "-", 0.0, 4.0, (0.4,), 0.1),
                Param("k", "N/rad", 1e-3, 1e3, (4.0,), 0.5), Param("theta0", "rad", -1.0, 1.0, (0.0,), 0.01)),
}

#: The capstan structure replaces the seed: the cause the seed model misses.
CAUSE_OF_SEED = "capstan_joint"

PAIR_EFFECTS: dict[str, PairEffect] = {e.id: e for e in (
    PairEffect("capstan_joint", "E1, E11, E13",
               "sheath friction holds both distal tensions after a reversal (capstan stick band) and the "
               "joint, an elastic load on both tendons, turns only when a slip front reaches a tip",
               "flat angle after every reversal while the proximal tensions cross a band that grows with "
               "the tube bend; the seed model curls there and leaves the plateau too early",
               "two profile memories and the joint driven by the motor as one mechanism", (), ("seed",)),
    PairEffect("joint_backlash", "E12", "play between the joint pulley and the link (or the tracker mount)",
               "a dead zone of fixed width in angle after every reversal, independent of tension",
               "theta_link = play(theta, b)", (Param("b", "rad", 0.0, 0.6, (0.05, 0.25), 0.01),), ("seed", "capstan")),
    PairEffect("sensor_delay", "E14", "time skew between the tracker and the command (filter, bus)",
               "the loop widens like an ellipse; residual proportional to the angle rate",
               "theta(t - tau)", (Param("tau", "s", -0.2, 0.2, (0.02, -0.02), 0.01),), ("seed", "capstan")),
    PairEffect("friction_offset", "E8", "tension-independent friction (wire bending stiffness, clearance)",
               "a wider band at low tension: the released tendon's band, read as a ratio, grows as it slackens",
               "capstan law on T + a", (Param("a", "N", 0.0, 10.0, (0.3, 2.0), 0.1),), ("seed", "capstan")),
    PairEffect("pretension_profile", "E5", "the pretension was applied from the motor: the initial profile "
               "decays along the sheath", "the first pull from rest differs from later pulls",
               "initial profile P e^{-shape mu theta(s)}", (Param("shape", "-", 0.0, 1.0, (0.5,), 0.1),),
               ("capstan",)),
    PairEffect("joint_friction", "E11, E12", "Coulomb friction in the joint (bending section, bearings)",
               "a torque dead band: the joint stays put for small torque changes at any tension",
               "joint moves only when |torque imbalance| > tau_c",
               (Param("tau_c", "N", 0.0, 5.0, (0.2,), 0.05),), ("capstan",)),
    PairEffect("series_compliance", "E10", "compliance outside the sheath friction: drive, load cell, sheath "
               "axial compression", "proximal travel larger than the tendon stretch; softer tension loops",
               "frictionless series spring lam_s ahead of the sheath",
               (Param("lam_s", "rad/N", 0.0, 5.0, (0.1,), 0.05),), ("capstan",)),
    PairEffect("joint_stiffening", "E11", "the bending section stiffens towards its range (links closing up, "
               "compressed backbone)", "the angle saturates at the end of a stroke while the pulled tendon's "
               "tension keeps rising steeply", "joint stiffness k + k2 beyond |theta| > theta_c",
               (Param("k2", "N/rad", 0.0, 200.0, (3.0,), 0.5), Param("theta_c", "rad", 0.02, 1.0, (0.15,), 0.02)),
               ("capstan",)),
    PairEffect("tendon_toe", "E9", "a tendon softer at low tension (strands bedding in, a stiffening "
               "stress-strain law)", "the released tendon's proximal tension falls fast and then creeps toward "
               "zero; the joint leaves the plateau after a reversal from low tension later than a linear tendon "
               "allows", "node compliance lam (1 + toe e^{-T / toe_tension})",
               (Param("toe", "-", 0.0, 200.0, (4.0,), 0.5), Param("toe_tension", "N", 0.1, 10.0, (1.0,), 0.1)),
               ("capstan",)),
    # no structure: a candidate of the shared models (estimator.offline.pair.shared) only; per configuration it
    # priced out at every bend (docs/results/kaist.md), so the diagnosis does not offer it
    PairEffect("bending_friction", "E7, E13", "the tendons rub in the bending section, whose wrap angle is the "
               "joint angle itself", "the joint stalls at large angles while the pulled tendon's tension keeps "
               "rising; strongest where the angle range is largest (the straightest tube)",
               "joint balance T_d,a e^{-+mu_b |theta|} - T_d,b e^{+-mu_b |theta|} = k theta + tau_0",
               (Param("mu_b", "1/rad", 0.0, 5.0, (0.1,), 0.02),), ()),
    # an observer, not a property of the mechanism: it reads the measured proximal tensions at every sample
    # (the test block's too: proximal sensors, what the product's estimator has); not offered by default
    PairEffect("drive_observer", "E10 (drive side)", "a frictionless compliance between the motor and the sheath "
               "entry (drive, coupling, load-cell mount) whose stretch is the proximal tension it carries",
               "the measured proximal tensions rise gently after a reversal and steepest at the end of the stroke, "
               "where the command-only model's rise linearly", "sheath entry at G (c - c_0) - lam_d (T_meas - "
               "T_meas(0)), T_meas the measured proximal tension of each tendon",
               (Param("lam_d", "rad/N", 0.0, 5.0, (0.05, 0.2), 0.02),), ()),
)}


def model_id(structure: str, effects: tuple[str, ...] | list[str] = ()) -> str:
    """``"capstan+joint_backlash"``: the structure and its effects joined by '+'."""
    return "+".join([structure, *effects])


def parse_model(mid: str) -> tuple[str, tuple[str, ...]]:
    """Inverse of :func:`model_id`. Raises ValueError for an unknown structure or effect."""
    structure, *effects = mid.split("+")
    if structure not in STRUCTURES:
        raise ValueError(f"unknown pair structure {structure!r}; known: {', '.join(STRUCTURES)}")
    for e in effects:
        if e not in PAIR_EFFECTS or structure not in PAIR_EFFECTS[e].structures or e == CAUSE_OF_SEED:
            raise ValueError(f"effect {e!r} does not apply to the {structure} structure")
    return structure, tuple(effects)


def model_params(structure: str, effects: tuple[str, ...] = ()) -> tuple[Param, ...]:
    """The parameters of a model, structure first, in a fixed order."""
    return STRUCTURES[structure] + tuple(p for e in effects for p in PAIR_EFFECTS[e].parameters)


def applicable(structure: str, effects: tuple[str, ...]) -> list[str]:
    """Effect ids that can be added to the model (structure, effects), in catalogue order."""
    return [e.id for e in PAIR_EFFECTS.values()
            if structure in e.structures and e.id not in effects and e.id != CAUSE_OF_SEED]


def predict_model(structure: str, effects: tuple[str, ...], values: dict[str, float], rec,
                  n_nodes: int = 24) -> tuple[np.ndarray, np.ndarray | None]:
    """Distal angle [rad], shape (n,), of a model over a recording, and (capstan structure) the
    predicted proximal tensions [N], shape (n, 2), else None.

    ``values`` maps every name of :func:`model_params` to its value (SI units).

    Raises
    ------
    ValueError
        A parameter outside the range the kernels accept (from :func:`simulate_pair`).
    """
    v = values
    a = v.get("a", 0.0)
    T_in = None
    if structure == "seed":
        Ta = np.asarray(rec.T_a, dtype=float) + a
        Tb = np.asarray(rec.T_b, dtype=float) + a
        p = PairParams(v["G"], v["K_a"], v["K_b"], v["lam_a"], v["lam_b"], v["theta0"])
        theta = (p.G * np.asarray(rec.command, dtype=float) - p.lam_a * mean_tension(Ta, p.K_a, 50)
                 + p.lam_b * mean_tension(Tb, p.K_b, 50) + p.theta0)
    else:
        th, T_in = simulate_pair(rec.command, (float(rec.T_a[0]), float(rec.T_b[0])), v["G"], (v["lam"], v["lam"]),
                                 (v["K_a"], v["K_b"]), v["k"], lam_s=v.get("lam_s", 0.0), tau_c=v.get("tau_c", 0.0),
                                 shape=v.get("shape", 0.0), offset=a, k2=v.get("k2", 0.0),
                                 theta_c=v.get("theta_c", 0.0), toe=v.get("toe", 0.0),
                                 toe_tension=v.get("toe_tension", 1.0), mu_b=v.get("mu_b", 0.0), n_nodes=n_nodes,
                                 observed=(rec.T_a, rec.T_b) if "drive_observer" in effects else None,
                                 lam_d=v.get("lam_d", 0.0))
        theta = th + v["theta0"]
    if "joint_backlash" in effects:
        theta = play(theta, v["b"], float(theta[0]))
    if "sensor_delay" in effects:
        t = np.asarray(rec.time, dtype=float)
        theta = np.interp(t - v["tau"], t, theta)
    if not np.all(np.isfinite(theta)):
        raise ValueError(f"non-finite angle from {model_id(structure, effects)} at {values}")
    return theta, T_in


#: Look-ahead kept beyond the last fitted sample by :func:`head` [s]: more than the largest sensor
#: delay the catalogue allows (``sensor_delay``: |tau| <= 0.2 s), whose interpolation reads ahead.
LOOKAHEAD_S = 0.25


class _Head:
    """The first ``n`` samples of a recording (time, command, T_a, T_b, angle)."""

    def __init__(self, rec, n: int):
        self.time = np.asarray(rec.time)[:n]
        self.command = np.asarray(rec.command)[:n]
        self.T_a = np.asarray(rec.T_a)[:n]
        self.T_b = np.asarray(rec.T_b)[:n]
        self.angle = np.asarray(rec.angle)[:n]


def head(rec, used):
    """The part of a recording a fit on the samples ``used`` (slice or index array) needs.

    Every model here is causal (the prediction of sample i reads the inputs up to sample i, the sensor
    delay up to :data:`LOOKAHEAD_S` later), so a fit on the first cycle need not run the model over
    the later cycles: the predictions at the ``used`` samples are the same, bit for bit. Returns
    ``rec`` itself when nothing can be cut.
    """
    t = np.asarray(rec.time, dtype=float)
    n = t.size
    if isinstance(used, slice):
        last = max(range(*used.indices(n)), default=n - 1)
    else:
        last = int(np.max(used)) if np.size(used) else n - 1
    stop = int(np.searchsorted(t, t[last] + LOOKAHEAD_S, side="right")) + 1
    return rec if stop >= n else _Head(rec, stop)


def _check() -> None:
    """The catalogue is consistent (run at import, so that a typo fails loudly)."""
    for p in [p for e in PAIR_EFFECTS.values() for p in e.parameters] + [p for ps in STRUCTURES.values() for p in ps]:
        if not (math.isfinite(p.lo + p.hi) and p.scale > 0 and p.starts and all(p.lo <= x <= p.hi for x in p.starts)):
            raise RuntimeError(f"inconsistent pair parameter {p}")


_check()
