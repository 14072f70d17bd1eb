"""The rig switch and the scenario knob of a catalogue entry (:mod:`estimator.offline.effects.catalogue`), as plain
data.

An effect of the catalogue is one entry: its model extension (parameters with fit bounds) and, with
the types below, how the simulated rig switches it on and how a hidden-effect scenario sets it:

* :class:`RigSwitch`: the config block ``rig.simulated.effects.<key>`` of the simulated rig, an
  ``enabled`` flag (default false) and one :class:`Setting` per magnitude (default, SI unit, valid
  range, meaning);
* :class:`ScenarioKnob`: the realistic magnitude range of the effect; a scenario level u in [0, 1]
  gives m = lo + u (hi - lo), with a sign drawn from the seed for the ``signed`` ones, turned into the
  switch settings and the truth parameters of the recording (``settings``; default: as they are).

The config schema and loader (teleop/config/effects.py), the default config's documentation, the
simulated rig's switch list (slave/simulated_effects.py) and the scenario table (study/scenarios.py)
are derived from these; the simulators' kernels stay their own code. estimator/ imports nothing of them.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

__all__ = ["Setting", "RigSwitch", "ScenarioKnob", "SENSOR_KNOBS", "SENSOR_SWITCHES", "drift_rate", "offset_at_tip",
           "step_at",
           "SENSOR_TEXT", "SENSOR_CAUSE", "SENSOR_SIGNATURE", "SENSOR_WHAT"]


@dataclass(frozen=True)
class Setting:
    """One setting of a rig switch, ``rig.simulated.effects.<key>.<name>``.

    ``default`` in ``unit`` (SI); ``valid``: ``"any"``, ``">= x"``, ``"> x"`` or ``"lo..hi"`` (the
    config loader's range rules); ``meaning``: one line for the config's documentation.
    """

    name: str
    default: float
    unit: str
    valid: str = "any"
    meaning: str = ""


@dataclass(frozen=True)
class RigSwitch:
    """The simulated rig's switch of an effect: config block ``rig.simulated.effects.<key>`` holding
    ``enabled`` (default false) and ``settings``; ``summary`` documents the block."""

    key: str
    summary: str
    settings: tuple[Setting, ...]

    def defaults(self) -> dict[str, float]:
        """Setting name -> default value (SI)."""
        return {s.name: s.default for s in self.settings}


@dataclass(frozen=True)
class ScenarioKnob:
    """How a hidden-effect scenario sets the effect from its level u in [0, 1].

    ``ranges``: (name, low, high) realistic magnitudes in SI units (docs/concepts/effects.md); ``signed``:
    the names whose sign the scenario draws from its seed; ``settings(m, K, duration)``: the
    magnitudes m (signed), the rig's friction exponent K [-] and the recording's duration [s] ->
    the values of the recording (switch settings by name, and truth parameters); None: m as it is;
    ``truth``: the names reported as the recording's truth (empty: all of them); ``drawn``: (name, low, high)
    values placed by a second uniform draw of the scenario, apart from the level (the instant of a step).
    """

    ranges: tuple[tuple[str, float, float], ...]
    signed: tuple[str, ...] = ()
    settings: Callable[[dict[str, float], float, float], dict[str, float]] | None = None
    truth: tuple[str, ...] = ()
    drawn: tuple[tuple[str, float, float], ...] = ()

    def range(self) -> dict[str, tuple[float, float]]:
        """Name -> (low, high) of the realistic magnitudes, SI units."""
        return {n: (lo, hi) for n, lo, hi in self.ranges}

    def values(self, level: float, sign: float, K: float, duration: float, draw: float = 0.5) -> dict[str, float]:
        """Every value of a recording at ``level`` in [0, 1]; ``sign`` (+-1) applies to :attr:`signed`; ``draw`` in
        [0, 1] places the :attr:`drawn` values in their ranges."""
        m = {n: (sign if n in self.signed else 1.0) * (lo + level * (hi - lo)) for n, lo, hi in self.ranges}
        m.update({n: lo + draw * (hi - lo) for n, lo, hi in self.drawn})
        return m if self.settings is None else self.settings(m, K, duration)

    def truth_of(self, values: dict[str, float]) -> dict[str, float]:
        """The truth parameters among :meth:`values`."""
        return dict(values) if not self.truth else {n: values[n] for n in self.truth}


def drift_rate(m: dict[str, float], K: float, duration: float) -> dict[str, float]:
    """Curvature drift: a relative change of K over the recording -> dK/dt [1/s]."""
    rate = m["relative_change"] * K / duration
    return {"K_rate": rate, "rate": rate, "relative_change": m["relative_change"]}


def step_at(m: dict[str, float], K: float, duration: float) -> dict[str, float]:
    """Friction step: a relative step of K at a share of the recording -> dK [-] and the instant t_s [s] (the rig
    switch's ``change`` and ``time``)."""
    dK, t_s = m["relative_step"] * K, m["instant_share"] * duration
    return {"dK": dK, "change": dK, "t_s": t_s, "time": t_s, "relative_step": m["relative_step"]}


def offset_at_tip(m: dict[str, float], K: float, duration: float) -> dict[str, float]:
    """Friction offset: the distal offset F0 [N] -> the tension offset a = F0 / (1 - e^-K) [N]."""
    return {"tension_offset": m["distal_offset"] / -math.expm1(-K), "distal_offset": m["distal_offset"]}


#: scenario knob of each sensor effect: (kind, channel letter) -> knob (either sign for offsets, gains, drifts)
SENSOR_KNOBS = {
    ("offset", "T"): ScenarioKnob((("offset", 0.2, 1.0),), ("offset",)),                   # N
    ("gain", "T"): ScenarioKnob((("gain", 0.03, 0.10),), ("gain",)),                        # relative
    ("lag", "T"): ScenarioKnob((("delay", 0.010, 0.050),)),                                # s
    ("drift", "T"): ScenarioKnob((("rate", 0.003, 0.012),), ("rate",)),                    # N/s (0.3-1 N in 90 s)
    ("offset", "x"): ScenarioKnob((("offset", 20e-6, 100e-6),), ("offset",)),              # m
    ("lag", "x"): ScenarioKnob((("delay", 0.010, 0.050),)),                                # s
}
#: the simulated rig's switches of sensor effects: (kind, channel) -> switch (the proximal load cell and encoder)
SENSOR_SWITCHES = {
    ("offset", "T_in"): RigSwitch("sensor_offset", "zero offset of the proximal load cell",
                                  (Setting("offset", 0.5, "N", "any", "added to the T_in reading"),)),
    ("gain", "T_in"): RigSwitch("sensor_gain", "scale error of the proximal load cell (calibration factor)",
                                (Setting("gain", 0.05, "-", "-0.5..0.5", "T_in reading = (1 + gain) true T_in"),)),
    ("lag", "T_in"): RigSwitch("sensor_delay", "the proximal load-cell channel lags the others",
                               (Setting("delay", 0.02, "s", ">= 0", "T_in reading = true T_in delay seconds ago"),)),
    ("drift", "T_in"): RigSwitch("sensor_drift", "slow zero drift of the proximal load cell (bridge temperature)",
                                 (Setting("rate", 0.005, "N/s", "-0.1..0.1", "added to the T_in reading: rate t "
                                          "(t from the start)"),)),
    ("offset", "x_in"): RigSwitch("encoder_offset", "zero offset of the proximal encoder (zeroed off the rest)",
                                  (Setting("offset", 5e-5, "m", "-0.005..0.005", "added to the x_in reading (read at "
                                           "the rest too)"),)),
}


# the sensor entries' text and fit data (estimator.offline.effects.catalogue.SensorEffect)
# per channel: kind -> (parameter prefix, unit of the parameter by channel, bounds, starts, meaning)
SENSOR_TEXT = {
    "offset": ("b", {"T": ("N", -10.0, 10.0, (-0.5, 0.5)), "x": ("m", -5e-3, 5e-3, (-5e-5, 5e-5))},
               "zero offset: reading = true + b"),
    "gain": ("g", {"T": ("-", -0.5, 0.5, (-0.05, 0.05))}, "scale error: reading = (1 + g) true"),
    "lag": ("tau", {"T": ("s", 0.0, 0.2, (0.01, 0.04)), "x": ("s", 0.0, 0.2, (0.01, 0.04))},
            "time delay of the channel: reading(t) = true(t - tau)"),
    "drift": ("d", {"T": ("N/s", -0.1, 0.1, (-0.005, 0.005))}, "linear zero drift: reading = true + d (t - t_0)"),
}
SENSOR_CAUSE = {"offset": "zero offset of the {what} (tare, encoder zeroed off the rest)",
                "gain": "scale error of the {what} (calibration factor)",
                "lag": "the {what} channel lags the others (filter, bus or sampling skew)",
                "drift": "slow zero drift of the {what} (thermal drift of the bridge)"}
SENSOR_SIGNATURE = {"offset": "a constant residual of one sign on pull and release; a non-zero reading at the initial "
                    "rest",
                    "gain": "the pull and release slopes scaled together (their product is not 1)",
                    "lag": "residual proportional to the rate of the channel; loop area grows with frequency",
                    "drift": "residual growing linearly with time on both branches"}
SENSOR_WHAT = {"T_in": "proximal load cell", "T_out": "distal load cell", "x_in": "proximal encoder",
               "x_out": "distal position sensor"}
