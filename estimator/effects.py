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

from dataclasses import dataclass
from typing import Iterable, Sequence

import numpy as np

from estimator.effects_kernels import run_extended

__all__ = ["Parameter", "Effect", "VelocityFriction", "Pretension", "CurvatureDrift", "TendonStiffening", "Stiction",
           "FrictionOffset", "SensorOffset", "SensorDelay", "Series", "Prediction", "CATALOGUE", "EFFECT_IDS", "NONE", "UNKNOWN",
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


class Effect:
    """One model extension (subclasses below, one per physical effect; instances in CATALOGUE).

    Class attributes: ``id`` catalogue identifier; ``cause`` the physical cause; ``signature`` how
    it shows in data; ``extension`` the model change; ``literature`` the effect number in
    literature.md; ``parameters`` what it adds; ``primary`` the signal it changes persistently
    ("T_out", or "x_out" for effects that leave T_out alone after the first pull); ``knobs`` the
    kernel knob of each parameter (:mod:`estimator.effects_kernels`), empty for sensor corrections.
    The rig switch of the same name is ``rig.effects.<id>`` (slave/simulated.py).
    """

    id: str = ""
    cause: str = ""
    signature: str = ""
    extension: str = ""
    literature: str = ""
    parameters: tuple[Parameter, ...] = ()
    primary: str = "T_out"
    knobs: dict[str, str] = {}

    def correct_input(self, values: dict[str, float], time: np.ndarray, T_in: np.ndarray) -> np.ndarray | None:
        """The corrected proximal tension [N], shape (n,), from ``T_in`` [N] sampled at ``time`` [s];
        None when the effect is not a sensor one."""
        return None

    def predict(self, values: dict[str, float], s: Series, *, compliance: float | None = None) -> Prediction:
        """The base model's batch prediction extended by this effect (see :func:`predict`)."""
        return predict([self], values, s, compliance=compliance)

    def describe(self) -> dict:
        """JSON-ready summary: id, cause, signature, extension, literature, parameters with units and bounds."""
        return {"id": self.id, "cause": self.cause, "signature": self.signature, "extension": self.extension,
                "literature": self.literature, "primary_signal": self.primary,
                "parameters": [{"name": p.name, "unit": p.unit, "bounds": [p.lower, p.upper], "meaning": p.meaning}
                               for p in self.parameters]}

    def __repr__(self) -> str:
        return f"<effect {self.id}>"


class VelocityFriction(Effect):
    id = "velocity_friction"
    cause = "friction grows with sliding speed: viscous lubricant film or polymer liner (Stribeck regime)"
    signature = "slip ratio ln(T_in/T_out) grows with |v|; loop width grows with speed at equal amplitude"
    extension = "K(v) = K (1 + c_v |dx_in/dt|) in the profile bounds; a slide follows the speed"
    literature = "E3"
    parameters = (Parameter("c_v", "s/m", 0.0, 200.0, 0.0, (5.0, 30.0),
                            "mu(v) = mu (1 + c_v |v|), v proximal sliding speed"),)
    knobs = {"c_v": "c_v"}


class Pretension(Effect):
    id = "pretension"
    cause = "the tendon carries tension at rest (assembly preload, antagonist), encoders zeroed there"
    signature = "T_in and T_out non-zero at rest; first pull from rest differs; x_out offset of (L/EA) T0"
    extension = "initial profile uniform at T0 (not 0), elongation counted from its (L/EA) T0"
    literature = "E5"
    parameters = (Parameter("T0", "N", 0.0, 50.0, 0.0, (), "uniform tension along the tendon at the start"),)
    primary = "x_out"
    knobs = {"T0": "T0"}


class CurvatureDrift(Effect):
    id = "curvature_drift"
    cause = "K changes during the recording: insertion shape (total wrap angle), wear or temperature"
    signature = "branch slopes e^-+K and the band width drift with time; early and late loops differ"
    extension = "K(t) = K + K_rate (t - t_0), route shape kept"
    literature = "E6/E15/E16"
    parameters = (Parameter("K_rate", "1/s", -0.05, 0.05, 0.0, (0.0,), "K(t) = K + K_rate (t - t_0)"),)
    knobs = {"K_rate": "K_rate"}


class TendonStiffening(Effect):
    id = "tendon_stiffening"
    cause = "the tendon is soft at low tension (strands bedding in, polymer), stiff above a toe"
    signature = "x_in - x_out vs T_in convex at low tension, then linear; T_out unaffected"
    extension = "elongation (L/EA) int phi(T) ds with phi(T) = T + beta T_c (1 - e^-T/T_c), i.e. EA(T) in the integral"
    literature = "E9"
    parameters = (Parameter("beta", "-", 0.0, 20.0, 0.0, (1.0, 4.0),
                            "extra compliance at zero tension: dstrain/dT = (1 + beta e^-T/T_c) / EA"),
                  Parameter("T_c", "N", 0.05, 20.0, 1.0, (1.0, 3.0), "tension scale of the toe"))
    primary = "x_out"
    knobs = {"beta": "beta", "T_c": "Tc"}


class Stiction(Effect):
    id = "stiction"
    cause = "static friction above kinetic: breakaway after sticking (dry coil sheaths)"
    signature = "after holds and reversals T_in overshoots then drops; T_out and x_out jump at breakaway"
    extension = ("bound K (1 + r_s) while stuck; at breakaway the whole profile slides with "
                 "K (1 + r_s e^-(t - t_b)/t_slip)")
    literature = "E4"
    parameters = (Parameter("r_s", "-", 0.0, 2.0, 0.0, (0.1, 0.25, 0.5, 0.9), "mu_static / mu_kinetic - 1"),)
    knobs = {"r_s": "r_s"}


class FrictionOffset(Effect):
    id = "friction_offset"
    cause = "friction that does not scale with tension: wire bending stiffness, clearance, weight"
    signature = "T_out vs T_in has an intercept of opposite sign on pull and release; friction stays as T -> 0"
    extension = "capstan law on T + a: dT/dtheta = -mu (T + a) sgn(v), T >= 0"
    literature = "E8"
    parameters = (Parameter("a", "N", 0.0, 20.0, 0.0, (0.5, 2.0),
                            "dT/dtheta = -mu (T + a): F0 = a (1 - e^-K) at the tip"),)
    knobs = {"a": "a"}


class SensorOffset(Effect):
    id = "sensor_offset"
    cause = "zero offset of the proximal load cell (tare, drift of the bridge)"
    signature = "T_out != 0 at T_in = 0; residual of one sign on pull and release, ratio e^-2K"
    extension = "input correction T_in - b_T_in"
    literature = "E14"
    parameters = (Parameter("b_T_in", "N", -10.0, 10.0, 0.0, (-0.5, 0.5), "T_in,measured = T_in + b_T_in"),)

    def correct_input(self, values, time, T_in):
        # T_in,true = T_in,measured - b
        return T_in - values["b_T_in"]


class SensorDelay(Effect):
    id = "sensor_delay"
    cause = "the load-cell channel lags the others (filter, bus or sampling skew)"
    signature = "cross-correlation lag between T_in and T_out in slip; loop area grows with frequency"
    extension = "input correction T_in(t + tau) (linear interpolation)"
    literature = "E14"
    parameters = (Parameter("tau", "s", -0.2, 0.2, 0.0, (0.01, 0.04), "T_in,measured(t) = T_in(t - tau)"),)

    def correct_input(self, values, time, T_in):
        # T_in,true(t) = T_in,measured(t + tau): the load-cell channel lags by tau
        return np.interp(time + values["tau"], time, T_in)


_EFFECTS: tuple[Effect, ...] = (VelocityFriction(), Pretension(), CurvatureDrift(), TendonStiffening(), Stiction(),
                                FrictionOffset(), SensorOffset(), SensorDelay())

CATALOGUE: dict[str, Effect] = {e.id: e for e in _EFFECTS}
EFFECT_IDS: tuple[str, ...] = tuple(CATALOGUE)


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
        knobs.update({e.knobs[k]: v for k, v in own.items() if k in e.knobs})
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

