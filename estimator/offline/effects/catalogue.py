"""The catalogue of model extensions: one small class per physical effect the base model misses.

Over 400 lines: one class per catalogue entry with its texts, switches and per-cycle form, and the one prediction
over them; the entries are the catalogue and do not split.

Base model: the profile-memory estimator (exact Coulomb memory; :mod:`estimator.sheath`) with two
parameters, the friction exponent K [-] and the compliance L/EA [m/N], driven by the measured
proximal tension T_in from an unloaded tendon (initial profile 0, positions zeroed there). Each
extension adds a few parameters to it; all of them run through one compiled kernel
(:mod:`estimator.offline.effects.kernels`) in which an extension that is off sits at its neutral value, so
extensions compose. Sensor effects act on the input (T_in corrected before the kernel); friction
and tendon effects change the kernel. Effect numbers E1-E16 refer to the project's literature
summary (docs/concepts/effects.md); the causes and signatures are summarised there too.
"""
from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np

from estimator.offline.effects import switches as sw
from estimator.offline.effects.predict import run_model
from estimator.offline.effects.presliding_kernel import NODE_FORM
from estimator.offline.effects.switches import RigSwitch, ScenarioKnob, Setting
from estimator.offline.effects.types import (
    Parameter,
    Prediction,
    Series,
    route_shape,
    route_values,
)
from estimator.online.extended import PER_CYCLE

#: Held setting of velocity_friction: 1 = the sliding speed is the mean of |dx_in/dt| and |dx_out/dt|.
SPEED_FORM = "velocity_form"
#: Held setting of stiction: 1 = the Stribeck form, each node's friction K (1 + r_s e^-(v/v_st)^2) by its own speed.
STRIBECK_FORM = "stiction_form"
#: Stribeck speed of that form [m/s], held (docs/concepts/effects.md names the form, not a value; the lumped simulator
#: uses 0.5 mm/s)
STRIBECK_SPEED = 0.5e-3
#: Smallest pre-sliding travel x_p the fit may use [m] (its neutral, off, is 0): below a few um the rounding is under
#: the floor of x_out and the per-node form differs from the base only by running on the measured x_out. Half the
#: lower end of the realistic range (40-150 um, the scenario knob below).
PRESLIDING_MIN = 20e-6
#: Noise band of the memory rule in sigma of the prepared T_in (``run_extended``'s ``band``): the stuck profile moves
#: only for what T_in exceeds beyond it, so it does not latch the noise's own extremes (docs/concepts/diagnosis.md).
NOISE_BAND = 3.0

__all__ = [
    "Effect", "VelocityFriction", "Pretension", "CurvatureDrift", "FrictionStep", "TendonStiffening", "Stiction",
    "FrictionOffset", "Presliding", "DistalBacklash", "SensorEffect", "CATALOGUE", "EFFECT_IDS", "ALIASES",
    "EQUIVALENT", "effect", "predict", "neutral_values", "register", "unregister", "rig_switches", "NOISE_BAND",
    "SPEED_FORM", "STRIBECK_FORM", "STRIBECK_SPEED", "PRESLIDING_MIN", "below_resolution",
]

class Effect:
    """One model extension (subclasses below, one per physical effect; instances in CATALOGUE).

    Class attributes: ``id`` catalogue identifier; ``cause`` the physical cause; ``signature`` how
    it shows in data; ``extension`` the model change; ``literature`` the effect number
    (docs/concepts/effects.md); ``parameters`` what it adds; ``primary`` the signal it changes persistently
    ("T_out", or "x_out" for effects that leave T_out alone after the first pull); ``knobs`` the
    kernel knob of each parameter (:mod:`estimator.offline.effects.kernels`), empty for sensor corrections.
    ``switch`` the simulated rig's switch (``rig.simulated.effects.<key>``, None: the rig has none) and
    ``knob`` the scenario knob (None: no hidden-effect scenario): :mod:`estimator.offline.effects.switches`.
    ``initial_state`` True for an effect that acts through the state at the start only (a pretension whose profile a
    first full slide erases): the diagnosis then judges it on the fold that validates on the start when the other
    fold's base is already at its floor. ``from_start`` True for an effect that is zero at the start and grows with
    time (a sensor drifting away from its zero at the start): the diagnosis judges it on the fold that validates on
    the end when the other fold's base is at its floor.
    """

    id: str = ""
    cause: str = ""
    signature: str = ""
    extension: str = ""
    literature: str = ""
    parameters: tuple[Parameter, ...] = ()
    primary: str = "T_out"
    knobs: dict[str, str] = {}
    requires: tuple[str, ...] = ()      # distal signals the recording must have for the effect to show
    channel: str = ""                   # the sensor channel (sensor effects only)
    switch: RigSwitch | None = None     # the simulated rig's switch
    knob: ScenarioKnob | None = None    # how a scenario level sets it
    variants: tuple[dict[str, float], ...] = ()   # alternative forms (settings held, not fitted); best one kept
    # the effect acts through the state at the start (before the first full slide): only a validation block that
    # holds the start can show it (estimator.offline.diagnosis.fit.fit_model)
    initial_state: bool = False
    # the effect is zero at the start and grows with time (a load cell drifting from its zero at the start): a
    # validation block at the start shows the least of it (estimator.offline.diagnosis.fit.fit_model)
    from_start: bool = False

    def variant_ok(self, variant: dict[str, float], measured: list[str]) -> bool:
        """Whether ``variant`` (one of ``variants``) can differ from the first form on a recording with ``measured``."""
        return True

    def correct_input(self, values: dict[str, float], time: np.ndarray, T_in: np.ndarray) -> np.ndarray | None:
        """The corrected proximal tension [N], shape (n,), from ``T_in`` [N] sampled at ``time`` [s];
        None when the effect is not a sensor one."""
        return None

    def predict(self, values: dict[str, float], s: Series, *, compliance: float | None = None) -> Prediction:
        """The base model's batch prediction extended by this effect (see :func:`predict`)."""
        return predict([self], values, s, compliance=compliance)

    @property
    def per_cycle(self) -> tuple[bool, str]:
        """Whether the live loop runs this entry, and how it runs there or why it cannot
        (:data:`estimator.online.extended.PER_CYCLE`; an entry added by :func:`register` has none)."""
        return PER_CYCLE.get(self.id, (False, "an entry added to the catalogue has no per-cycle form"))

    def describe(self) -> dict:
        """JSON-ready summary: id, cause, signature, extension, literature, parameters with units and bounds,
        per_cycle (whether the live loop runs it, and how or why not)."""
        return {"id": self.id, "cause": self.cause, "signature": self.signature, "extension": self.extension,
                "literature": self.literature, "primary_signal": self.primary, "per_cycle": list(self.per_cycle),
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
    switch = RigSwitch("velocity_friction", "friction grows with sliding speed (viscous liner)", (Setting(
        "viscous", 15.0, "s/m", ">= 0", "mu(v) = mu (1 + viscous |v|), v = sliding speed"),))
    knob = ScenarioKnob((("viscous", 8.0, 30.0),))                   # +8..30 % friction at 10 mm/s
    # the speed in K(v): the proximal one, or (needs x_out) the mean of the proximal and distal speeds - where
    # friction acts per segment on each segment's own speed, which lies between the two (the distal end of a
    # tendon on a stiff load hardly moves while the proximal one runs on by the elongation rate)
    variants = ({SPEED_FORM: 0.0}, {SPEED_FORM: 1.0})

    def variant_ok(self, variant: dict[str, float], measured: list[str]) -> bool:
        return not variant.get(SPEED_FORM) or "x_out" in measured


class Pretension(Effect):
    id = "pretension"
    cause = "the tendon carries tension at rest (assembly preload, antagonist), encoders zeroed there"
    signature = "T_in and T_out non-zero at rest; first pull from rest differs; x_out offset of (L/EA) T0"
    extension = ("initial profile at T0 (not 0), capped at the distal end by the friction band above the rest "
                 "reading of T_out (a load that held less slid back); elongation counted from that profile")
    literature = "E5"
    parameters = (Parameter("T0", "N", 0.0, 50.0, 0.0, (), "uniform tension along the tendon at the start",
                            rest="replace"),)
    primary = "x_out"
    initial_state = True
    knobs = {"T0": "T0"}
    switch = RigSwitch("pretension", "the tendon carries tension at rest (assembly preload)", (Setting(
        "tension", 3.0, "N", ">= 0", "uniform tension at rest, added to sheath.pretension"),))
    knob = ScenarioKnob((("tension", 1.0, 5.0),))


class CurvatureDrift(Effect):
    id = "curvature_drift"
    cause = "K changes during the recording: insertion shape (total wrap angle), wear or temperature"
    signature = "branch slopes e^-+K and the band width drift with time; early and late loops differ"
    extension = "K(t) = K + K_rate (t - t_0), route shape kept"
    literature = "E6/E15/E16"
    parameters = (Parameter("K_rate", "1/s", -0.05, 0.05, 0.0, (0.0,), "K(t) = K + K_rate (t - t_0)"),)
    knobs = {"K_rate": "K_rate"}
    switch = RigSwitch("curvature_drift", "K changes during the recording (shape change, wear, temperature)",
                       (Setting("rate", 0.002, "1/s", "any", "dK/dt, K(t) = K + rate t"),))
    knob = ScenarioKnob((("relative_change", 0.10, 0.30),), ("relative_change",), sw.drift_rate, ("K_rate",))  # |dK|/K


class FrictionStep(Effect):
    id = "friction_step"
    cause = "the sheath reshaped at one instant (an endoscope moved, the insertion tube bent): K steps up or down"
    signature = ("the branch slopes e^-+K and the band width change at one instant and stay: the residual of a steady "
                 "K is a step in time, not a ramp")
    extension = ("K(t) = K before t_s, K + dK from t_s on, route shape kept; t_s fitted by a profile over candidate "
                 "instants, both levels by least squares")
    literature = "E6"
    parameters = (Parameter("t_s", "s", 0.0, 1e6, 0.0, (), "the instant K steps, from the first sample",
                            discrete=True),
                  Parameter("dK", "-", -2.0, 2.0, 0.0, (0.0,), "K steps to K + dK at t_s"))
    knobs = {"dK": "K_step", "t_s": "t_step"}
    switch = RigSwitch("friction_step", "friction steps at one instant (the sheath reshaped: an endoscope moved)", (
        Setting("change", 0.1, "-", "any", "dK: K becomes K + change at the instant"),
        Setting("time", 30.0, "s", ">= 0", "the instant, from the start of the run")))
    # a relative step of K (either sign) at an instant drawn apart from the size, within the training block
    knob = ScenarioKnob((("relative_step", 0.15, 0.40),), ("relative_step",), sw.step_at, ("t_s", "dK",
                                                                                          "relative_step"),
                        drawn=(("instant_share", 0.15, 0.5),))


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
    switch = RigSwitch("tendon_stiffening", "tendon soft at low tension (strand bedding, polymer)", (
        Setting("softening", 2.0, "-", ">= 0", "extra compliance at zero tension: "
                "dstrain/dT = (1 + softening e^(-T/toe_tension))/EA"),
        Setting("toe_tension", 2.0, "N", "> 0", "tension scale of the soft toe")))
    knob = ScenarioKnob((("softening", 1.0, 4.0), ("toe_tension", 1.0, 3.0)))


class Stiction(Effect):
    id = "stiction"
    cause = "static friction above kinetic: breakaway after sticking (dry coil sheaths)"
    signature = "after holds and reversals T_in overshoots then drops; T_out and x_out jump at breakaway"
    extension = ("bound K (1 + r_s) while stuck; at breakaway the whole profile slides with "
                 "K (1 + r_s e^-(t - t_b)/t_slip)")
    literature = "E4"
    parameters = (Parameter("r_s", "-", 0.0, 2.0, 0.0, (0.1, 0.25, 0.5, 0.9), "mu_static / mu_kinetic - 1"),)
    knobs = {"r_s": "r_s"}
    variants = ({STRIBECK_FORM: 0.0}, {STRIBECK_FORM: 1.0})   # breakaway at reversals; Stribeck per node
    switch = RigSwitch("stiction", "static friction above kinetic: breakaway after sticking, stick-slip when slow", (
        Setting("static_ratio", 0.3, "-", ">= 0", "mu_static / mu_kinetic - 1"),
        Setting("slip_time", 0.02, "s", "> 0", "after breakaway mu relaxes to kinetic with this time constant")))
    knob = ScenarioKnob((("static_ratio", 0.15, 0.6),))


class FrictionOffset(Effect):
    id = "friction_offset"
    cause = "friction that does not scale with tension: wire bending stiffness, clearance, weight"
    signature = "T_out vs T_in has an intercept of opposite sign on pull and release; friction stays as T -> 0"
    extension = "capstan law on T + a: dT/dtheta = -mu (T + a) sgn(v), T >= 0"
    literature = "E8"
    parameters = (Parameter("a", "N", 0.0, 20.0, 0.0, (0.5, 2.0),
                            "dT/dtheta = -mu (T + a): F0 = a (1 - e^-K) at the tip"),)
    knobs = {"a": "a"}
    switch = RigSwitch("friction_offset", "friction that does not scale with tension (bending stiffness, clearance)",
                       (Setting("tension_offset", 1.0, "N", ">= 0", "a in dT/dtheta = -mu (T + a)"),))
    knob = ScenarioKnob((("distal_offset", 0.2, 1.0),), (), sw.offset_at_tip)    # N: F0 = a (1 - e^-K) at the tip


class Presliding(Effect):
    id = "presliding"
    cause = "pre-sliding: friction builds up over a small travel after a reversal (liner/asperity compliance, Dahl)"
    signature = ("rounded loop corners: T_out bends gradually after a reversal instead of staying flat; relaxes in "
                 "dwells")
    extension = ("tension-scaled Dahl element, in one of two forms (the better fit is kept): the friction "
                 "T_in - T_out lags the memory model's in proximal travel, dF/dx = (F_memory - F) / x_p; or "
                 "per node: every segment pre-slides over its own travel x_p "
                 "(estimator.offline.effects.presliding_kernel)")
    literature = "E2"
    parameters = (Parameter("x_p", "m", PRESLIDING_MIN, 1e-3, 0.0, (40e-6, 120e-6),
                            "pre-sliding travel F_c / sigma (neutral 0: off, below the fitted range)"),)
    switch = RigSwitch("presliding", "friction builds up over a small travel after a reversal (the lumped form)", (
        Setting("distance", 80e-6, "m", "> 0", "x_p: T_in - T_out lags the memory model's friction over this "
                "proximal travel"),))
    knob = ScenarioKnob((("distance", 40e-6, 150e-6),))
    variants = ({NODE_FORM: 0.0}, {NODE_FORM: 1.0})     # lumped (travel lag), per node (needs x_out)

    def variant_ok(self, variant: dict[str, float], measured: list[str]) -> bool:
        return not variant.get(NODE_FORM) or "x_out" in measured


class DistalBacklash(Effect):
    id = "distal_backlash"
    cause = "play between the tendon's distal end and the distal joint/load (pulley, gear or clevis clearance)"
    signature = "x_out stands still while the tendon end crosses a gap after each reversal; x_out vs x_in dead zone"
    extension = "x_out = backlash operator of the tendon end, total width d_b (the joint stays until the gap closes)"
    literature = "E12"
    parameters = (Parameter("d_b", "m", 0.0, 2e-3, 0.0, (60e-6, 200e-6), "total dead-zone width"),)
    primary = "x_out"
    requires = ("x_out",)
    switch = RigSwitch("distal_backlash", "play between the tendon's distal end and the measured distal position", (
        Setting("width", 1e-4, "m", ">= 0", "total width d_b of the play behind which the distal position "
                "sits"),))
    knob = ScenarioKnob((("width", 50e-6, 300e-6),))


class SensorEffect(Effect):
    """A sensor effect on one channel (E14): ``id`` = "sensor_<kind>:<channel>", e.g. "sensor_lag:T_out".

    Proximal channels are corrected before the model runs (the model is driven by the true T_in and
    x_in); distal channels are applied to the model's output (what the distal sensor would read).
    """

    literature = "E14"

    def __init__(self, kind: str, channel: str):
        prefix, units, meaning = sw.SENSOR_TEXT[kind]
        unit, lo, hi, starts = units[channel[0]]
        self.kind, self.channel = kind, channel
        self.id = f"sensor_{kind}:{channel}"
        self.cause = sw.SENSOR_CAUSE[kind].format(what=sw.SENSOR_WHAT[channel])
        self.signature = sw.SENSOR_SIGNATURE[kind]
        self.extension = (f"{'input correction of' if channel.endswith('_in') else 'reading model of'} {channel}: "
                          f"{meaning}")
        self.pname = f"{prefix}_{channel}"
        # a slack tendon reads its offset at rest: the T_in offset also starts from that reading, and an
        # encoder offset from x_out - x_in there (diagnosis_fit.rest_start)
        self.parameters = (Parameter(self.pname, unit, lo, hi, 0.0, starts, f"{channel} {meaning}",
                                     rest="extend" if kind == "offset" and channel != "T_out" else ""),)
        self.primary = "x_out" if channel[0] == "x" else "T_out"
        self.requires = ("x_out",) if channel[0] == "x" else ("T_out",) if channel == "T_out" else ()
        self.switch, self.knob = sw.SENSOR_SWITCHES.get((kind, channel)), sw.SENSOR_KNOBS[(kind, channel[0])]
        # a drift is counted from the recording's start, where the channel was zeroed: rate x (t - t_0)
        self.from_start = kind == "drift"


# the friction step comes last: the benchmark's seeds follow the catalogue's order
_EFFECTS: tuple[Effect, ...] = (VelocityFriction(), Pretension(), CurvatureDrift(), TendonStiffening(), Stiction(),
                                FrictionOffset(), Presliding(), DistalBacklash(),
                                *(SensorEffect(k, c) for k, chans in (("offset", "TT"), ("gain", "TT"), ("lag", "TT"),
                                  ("drift", "TT"), ("offset", "xx"), ("lag", "xx"))
                                  for c in (f"{chans[0]}_in", f"{chans[0]}_out")), FrictionStep())

CATALOGUE: dict[str, Effect] = {e.id: e for e in _EFFECTS}
EFFECT_IDS: tuple[str, ...] = tuple(CATALOGUE)
ALIASES = {"sensor_offset": "sensor_offset:T_in", "sensor_delay": "sensor_lag:T_in"}   #: former ids
#: effects with identical outputs: a T_in scale is a T_out scale (the memory is homogeneous, L/EA absorbs
#: it in x_out); an x_in offset is an x_out offset of the other sign (only x_in - x_out enters)
EQUIVALENT = {"sensor_gain:T_in": ("sensor_gain:T_out",), "sensor_gain:T_out": ("sensor_gain:T_in",),
              "sensor_offset:x_in": ("sensor_offset:x_out",), "sensor_offset:x_out": ("sensor_offset:x_in",)}

def effect(name: str) -> Effect:
    """The catalogue entry ``name`` (former ids of :data:`ALIASES` accepted).

    Raises
    ------
    KeyError
        Not a catalogue identifier (the message lists them).
    """
    try:
        return CATALOGUE[ALIASES.get(name, name)]
    except KeyError:
        raise KeyError(f"no effect {name!r} in the catalogue; known: {', '.join(EFFECT_IDS)}") from None


def register(entry: Effect) -> Effect:
    """Add ``entry`` to :data:`CATALOGUE` (a new effect: its entry here plus its kernel); returns it.

    Raises
    ------
    ValueError
        Its id or its rig switch's key is taken already.
    """
    keys = {e.switch.key for e in CATALOGUE.values() if e.switch}
    if entry.id in CATALOGUE or entry.id in ALIASES or (entry.switch and entry.switch.key in keys):
        raise ValueError(f"effect {entry.id!r}: its id or rig switch key is in the catalogue already")
    CATALOGUE[entry.id] = entry
    return entry


def unregister(eid: str) -> None:
    """Remove an entry added by :func:`register` (KeyError when absent)."""
    del CATALOGUE[eid]


def rig_switches() -> dict[str, Effect]:
    """Rig switch key -> catalogue entry, catalogue order (the ``rig.simulated.effects`` block)."""
    return {e.switch.key: e for e in CATALOGUE.values() if e.switch is not None}


def _knobs(fx: Sequence[Effect], values: dict[str, float]) -> tuple[dict, dict, float, float, bool]:
    """The kernel's knobs, the sensor effects' values by id, the pre-sliding travel x_p [m], the backlash width
    d_b [m] and whether pre-sliding runs in its per-node form."""
    knobs = {"K": float(values["K"])}
    sensors: dict[str, float] = {}
    x_p = d_b = 0.0
    node = False
    for e in fx:
        own = {p.name: float(values.get(p.name, p.neutral)) for p in e.parameters}
        knobs.update({e.knobs[k]: v for k, v in own.items() if k in e.knobs})
        if isinstance(e, SensorEffect):
            sensors[e.id] = own[e.pname]
        elif isinstance(e, Presliding):
            x_p, node = own["x_p"], values.get(NODE_FORM, 0.0) > 0.5
        elif isinstance(e, DistalBacklash):
            d_b = own["d_b"]
    return knobs, sensors, x_p, d_b, node


def predict(effects: Iterable[Effect | str], values: dict[str, float], s: Series, *,
            compliance: float | None = None, fit_mask: slice | np.ndarray | None = None,
            stop: int | None = None) -> Prediction:
    """Outputs of the base model extended by ``effects`` over a series.

    Order (:func:`estimator.offline.effects.predict.run_model`): proximal sensor corrections (the model runs on
    the true inputs), the kernel, pre-sliding on T_out and the distal backlash on x_out, the distal sensors.

    Parameters
    ----------
    effects : iterable of Effect or id
        The extensions switched on (none: the base model).
    values : dict
        ``K`` [-], optionally the route shares ``r_1``, ``r_2`` (:data:`ROUTE`) or ``r_1`` ... ``r_5``
        (:data:`ROUTE_FINE`) or ``r_1`` ... ``r_11`` (:data:`ROUTE_TWELFTHS`; default the series' own node shape)
        and every parameter of the listed effects (names as in their Parameter lists); missing ones take their
        neutral value.
    s : Series
    compliance : float, optional
        L/EA [m/N]. Without it and with a measured x_out it is fitted by linear least squares on
        ``fit_mask`` (default all samples): x_in - x_out = (L/EA) E1 through the linear reading models.
    stop : int, optional
        Only the first ``stop`` samples are wanted (``fit_mask`` within them): the model runs over the samples
        they depend on, with the same outputs, and the prediction holds those ``stop`` samples.

    Returns
    -------
    Prediction

    Raises
    ------
    KeyError
        An unknown effect id.
    """
    fx: Sequence[Effect] = [e if isinstance(e, Effect) else effect(e) for e in effects]
    knobs, sensors, x_p, d_b, node = _knobs(fx, values)
    u = s.u if "r_1" not in values else route_shape(s.u.shape[0], *route_values(values))
    return run_model(s, knobs, sensors, u, x_p=x_p, d_b=d_b, node=node, compliance=compliance, fit_mask=fit_mask,
                     speed_form=values.get(SPEED_FORM, 0.0) > 0.5,
                     v_st=STRIBECK_SPEED if values.get(STRIBECK_FORM, 0.0) > 0.5 else 0.0,
                     band=NOISE_BAND * s.sigma_T_in, stop=stop)


def below_resolution(effects: Iterable[Effect], values: dict[str, float]) -> bool:
    """Whether a fitted magnitude of ``effects`` sits at the smallest value its effect can show: a lower bound
    above the neutral value (:data:`PRESLIDING_MIN`) reached within 5 %. The data then ask for less of the
    effect than the sensors resolve, so what the fit gains there comes from the form of the model, not from the
    effect (a velocity friction fitted as pre-sliding at its smallest travel)."""
    return any(p.lower > p.neutral and values.get(p.name, p.upper) <= 1.05 * p.lower
               for e in effects for p in e.parameters)


def neutral_values(effects: Iterable[Effect]) -> dict[str, float]:
    """Neutral value of every parameter of ``effects`` (the base model)."""
    return {p.name: p.neutral for e in effects for p in e.parameters}
