"""The catalogue of model extensions: one small class per physical effect the base model misses.

Base model: the profile-memory estimator (exact Coulomb memory; :mod:`estimator.sheath`) with two
parameters, the friction exponent K [-] and the compliance L/EA [m/N], driven by the measured
proximal tension T_in from an unloaded tendon (initial profile 0, positions zeroed there). Each
extension adds a few parameters to it; all of them run through one compiled kernel
(:mod:`estimator.effects_kernels`) in which an extension that is off sits at its neutral value, so
extensions compose. Sensor effects act on the input (T_in corrected before the kernel); friction
and tendon effects change the kernel. Effect numbers E1-E16 refer to the project's literature
summary (literature.md); the causes and signatures are summarised in docs/diagnosis.md.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Iterable, Sequence

import numpy as np

from estimator.effects_kernels import run_extended

__all__ = ["Parameter", "Effect", "Series", "Prediction", "CATALOGUE", "EFFECT_IDS", "NONE", "UNKNOWN",
           "effect", "predict", "neutral_values", "K_MAX"]

NONE = "none"          # the base model explains the data within the noise
UNKNOWN = "unknown"    # structure left in the residual that no extension explains
K_MAX = 5.0            # upper bound of the friction exponent in fits [-]


@dataclass(frozen=True)
class Parameter:
    """One fitted parameter: name (paper symbol where there is one), SI unit, bounds, neutral value
    (the base model), typical starting values for the fit, and what it means."""

    name: str
    unit: str
    lower: float
    upper: float
    neutral: float
    starts: tuple[float, ...]
    meaning: str


@dataclass(frozen=True, eq=False)
class Series:
    """A recording prepared for fitting: arrays of shape (n,), the model's node grid and noise.

    time [s], x_in [m], T_in [N], velocity dx_in/dt [m/s], T_out [N] or None, x_out [m] or None,
    u (m + 1,) normalised wrap angle of the nodes, w (m + 1,) trapezoid weights (sum 1),
    T_min [N] the tension below which a breakaway is lost in the load-cell noise, sigma_T_in [N]
    the white-noise level of the prepared T_in.
    """

    time: np.ndarray
    x_in: np.ndarray
    T_in: np.ndarray
    velocity: np.ndarray
    T_out: np.ndarray | None
    x_out: np.ndarray | None
    u: np.ndarray
    w: np.ndarray
    T_min: float = 0.0
    sigma_T_in: float = 0.0

    def __len__(self) -> int:
        return int(self.time.shape[0])

    def slice(self, stop: int) -> "Series":
        """The first ``stop`` samples (the training block)."""
        cut = (lambda a: None if a is None else a[:stop])
        return Series(self.time[:stop], self.x_in[:stop], self.T_in[:stop], self.velocity[:stop],
                      cut(self.T_out), cut(self.x_out), self.u, self.w, self.T_min, self.sigma_T_in)


@dataclass(frozen=True)
class Prediction:
    """Model outputs over a series: T_out [N] and x_out [m], shape (n,), and the compliance L/EA
    [m/N] used (fitted by linear least squares on the given mask when x_out was measured)."""

    T_out: np.ndarray
    x_out: np.ndarray
    compliance: float


@dataclass(frozen=True)
class Effect:
    """One model extension.

    id : catalogue identifier; cause : the physical cause; signature : how it shows in data;
    literature : effect number in literature.md; parameters : what it adds; primary : the signal
    it changes persistently ("T_out", or "x_out" for effects that leave T_out alone after the first
    pull); knobs : the kernel knob each parameter sets (or "input" for a sensor correction).
    """

    id: str
    cause: str
    signature: str
    literature: str
    parameters: tuple[Parameter, ...]
    primary: str = "T_out"
    knobs: tuple[str, ...] = field(default=())

    def correct_input(self, values: dict[str, float], time: np.ndarray, T_in: np.ndarray) -> np.ndarray | None:
        """The corrected proximal tension [N], shape (n,), from ``T_in`` [N] sampled at ``time`` [s];
        None when the effect is not a sensor one."""
        return None

    def describe(self) -> dict:
        """JSON-ready summary: id, cause, signature, literature, parameters with units and bounds."""
        return {"id": self.id, "cause": self.cause, "signature": self.signature, "literature": self.literature,
                "primary_signal": self.primary,
                "parameters": [{"name": p.name, "unit": p.unit, "bounds": [p.lower, p.upper], "meaning": p.meaning}
                               for p in self.parameters]}


class _SensorOffset(Effect):
    def correct_input(self, values, time, T_in):
        # T_in,true = T_in,measured - b
        return T_in - values["b_T_in"]


class _SensorDelay(Effect):
    def correct_input(self, values, time, T_in):
        # T_in,true(t) = T_in,measured(t + tau): the load-cell channel lags by tau
        return np.interp(time + values["tau"], time, T_in)


_EFFECTS: tuple[Effect, ...] = (
    Effect("velocity_friction",
           "friction grows with sliding speed: viscous lubricant film or polymer liner (Stribeck regime)",
           "slip ratio ln(T_in/T_out) grows with |v|; loop width grows with speed at equal amplitude",
           "E3", (Parameter("c_v", "s/m", 0.0, 200.0, 0.0, (5.0, 30.0),
                            "mu(v) = mu (1 + c_v |v|), v proximal sliding speed"),), knobs=("c_v",)),
    Effect("pretension",
           "the tendon carries tension at rest (assembly preload, antagonist), encoders zeroed there",
           "T_in and T_out non-zero at rest; first pull from rest differs; x_out offset of (L/EA) T0",
           "E5", (Parameter("T0", "N", 0.0, 50.0, 0.0, (), "uniform tension along the tendon at the start"),),
           primary="x_out", knobs=("T0",)),
    Effect("curvature_drift",
           "K changes during the recording: insertion shape (total wrap angle), wear or temperature",
           "branch slopes e^-+K and the band width drift with time; early and late loops differ",
           "E6/E15/E16", (Parameter("K_rate", "1/s", -0.05, 0.05, 0.0, (0.0,), "K(t) = K + K_rate (t - t_0)"),),
           knobs=("K_rate",)),
    Effect("tendon_stiffening",
           "the tendon is soft at low tension (strands bedding in, polymer), stiff above a toe",
           "x_in - x_out vs T_in convex at low tension, then linear; T_out unaffected",
           "E9", (Parameter("beta", "-", 0.0, 20.0, 0.0, (1.0, 4.0),
                            "extra compliance at zero tension: strain' = (1 + beta e^-T/T_c) / EA"),
                  Parameter("T_c", "N", 0.05, 20.0, 1.0, (1.0, 3.0), "tension scale of the toe")),
           primary="x_out", knobs=("beta", "Tc")),
    Effect("stiction",
           "static friction above kinetic: breakaway after sticking (dry coil sheaths)",
           "after holds and reversals T_in overshoots then drops; T_out and x_out jump at breakaway",
           "E4", (Parameter("r_s", "-", 0.0, 2.0, 0.0, (0.1, 0.25, 0.5, 0.9), "mu_static / mu_kinetic - 1"),),
           knobs=("r_s",)),
    Effect("friction_offset",
           "friction that does not scale with tension: wire bending stiffness, clearance, weight",
           "T_out vs T_in has an intercept of opposite sign on pull and release; friction stays as T -> 0",
           "E8", (Parameter("a", "N", 0.0, 20.0, 0.0, (0.5, 2.0),
                            "dT/dtheta = -mu (T + a): F0 = a (1 - e^-K) at the tip"),), knobs=("a",)),
    _SensorOffset("sensor_offset",
                  "zero offset of the proximal load cell (tare, drift of the bridge)",
                  "T_out != 0 at T_in = 0; residual of one sign on pull and release, ratio e^-2K",
                  "E14", (Parameter("b_T_in", "N", -10.0, 10.0, 0.0, (-0.5, 0.5),
                                    "T_in,measured = T_in + b_T_in"),), knobs=("input",)),
    _SensorDelay("sensor_delay",
                 "the load-cell channel lags the others (filter, bus or sampling skew)",
                 "cross-correlation lag between T_in and T_out in slip; loop area grows with frequency",
                 "E14", (Parameter("tau", "s", -0.2, 0.2, 0.0, (0.01, 0.04),
                                   "T_in,measured(t) = T_in(t - tau)"),), knobs=("input",)),
)

CATALOGUE: dict[str, Effect] = {e.id: e for e in _EFFECTS}
EFFECT_IDS: tuple[str, ...] = tuple(CATALOGUE)
_KNOB = {"c_v": "c_v", "T0": "T0", "K_rate": "K_rate", "beta": "beta", "T_c": "Tc", "r_s": "r_s", "a": "a"}


def effect(name: str) -> Effect:
    """The catalogue entry ``name``.

    Raises
    ------
    KeyError
        Not a catalogue identifier (the message lists them).
    """
    try:
        return CATALOGUE[name]
    except KeyError:
        raise KeyError(f"no effect {name!r} in the catalogue; known: {', '.join(EFFECT_IDS)}") from None


def predict(effects: Iterable[Effect | str], values: dict[str, float], s: Series, *,
            compliance: float | None = None, fit_mask: slice | np.ndarray | None = None) -> Prediction:
    """Outputs of the base model extended by ``effects`` over a series.

    Parameters
    ----------
    effects : iterable of Effect or id
        The extensions switched on (none: the base model).
    values : dict
        ``K`` [-] and every parameter of the listed effects (names as in their Parameter lists);
        missing ones take their neutral value.
    s : Series
    compliance : float, optional
        L/EA [m/N]. Without it and with a measured x_out it is fitted by linear least squares on
        ``fit_mask`` (default all samples): x_in - x_out = (L/EA) E1.

    Returns
    -------
    Prediction

    Raises
    ------
    KeyError
        An unknown effect id.
    """
    fx: Sequence[Effect] = [e if isinstance(e, Effect) else effect(e) for e in effects]
    knobs = {"K": float(values["K"])}
    T_in = s.T_in
    for e in fx:
        own = {p.name: float(values.get(p.name, p.neutral)) for p in e.parameters}
        knobs.update({_KNOB[k]: v for k, v in own.items() if k in _KNOB})
        corrected = e.correct_input(own, s.time, T_in)
        if corrected is not None:
            T_in = corrected
    T_out, E1 = run_extended(T_in, s.velocity, s.time, s.u, s.w, T_min=s.T_min, sigma=s.sigma_T_in, **knobs)
    c = compliance
    if c is None:
        c = 0.0
        if s.x_out is not None:
            m = slice(None) if fit_mask is None else fit_mask
            a, b = E1[m], (s.x_in - s.x_out)[m]
            den = float(a @ a)
            c = max(float(a @ b) / den, 0.0) if den > 0 else 0.0
    return Prediction(T_out=T_out, x_out=s.x_in - c * E1, compliance=float(c))


def neutral_values(effects: Iterable[Effect]) -> dict[str, float]:
    """Neutral value of every parameter of ``effects`` (the base model)."""
    return {p.name: p.neutral for e in effects for p in e.parameters}

