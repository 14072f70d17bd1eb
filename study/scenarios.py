"""Realistic recordings from the simulated rig, with one model effect hidden at a seeded magnitude.

A recording is what a bench session with a distal load cell and a distal position sensor gives:

* a motion protocol of repeated blocks; each block is a shuffled mix of a slow (1.5-4 mm/s) and a
  fast (12-25 mm/s) pull/release cycle of random amplitude, minor loops (partial release, re-pull past the old
  peak), staircases with holds, and small oscillations around a mid level (0.5-2 Hz); every block
  starts and ends at rest, so a time split at a block boundary holds out whole cycles;
* or, with ``motion="hand"``, operator-like motion over the same span (:func:`study.motion.hand_motion`:
  band-limited random moves with holds and part-way reversals, speeds up to 25 mm/s);
* the rig of :mod:`slave.simulated` (quasi-static distributed Coulomb tendon, 100 elements, motor
  with 40 Hz bandwidth, a tissue spring at the tip, or with ``load`` nonlinear tissue or free space then contact)
  with randomised K, EA and load stiffness;
* sensors: proximal load cell with white noise, motor encoder quantised at 0.47 um, distal load
  cell with white noise, distal position with noise and 1 um quantisation; both positions are
  zeroed at the start (the encoders are reset at rest), as on a bench.

The hidden effect is one of :func:`scenario_effects` with its magnitude drawn from :func:`realistic_range`
(``level`` in [0, 1] picks the position in the range; random from the seed when omitted). The
returned :class:`Recording` keeps the truth apart from the data, so a diagnosis cannot read it.

The scenario table is the effect catalogue's (estimator/offline/effects/catalogue.py): each entry's scenario
knob gives its realistic range and how a level turns into the rig switch's settings
(:func:`effects_config`); an entry without a rig switch is applied to the recorded signals here (the sensor
channels the rig has no switch for).

Over 400 lines: the rig's scenario table, its loads and its sensor chain belong together as one generator.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from estimator.data import MeasuredData
from estimator.geometry import SheathGeometry
from estimator.offline.effects.catalogue import ALIASES, CATALOGUE, Effect, rig_switches
from slave.rig import RigState, RigTruth
from slave.simulated import SimulatedRig
from study.motion import hand_motion
from teleop.config.effects import EffectsConfig, EffectSwitch
from teleop.config.schema import LoadConfig, RunConfig, SensorConfig, SheathConfig, SimulatedRigConfig

__all__ = [
    "LOADS", "MOTIONS", "RIG_SWITCH", "UNCATALOGUED", "Recording", "realistic_range", "effects_config", "protocol",
    "record",
    "scenario_effects",
]

#: the proximal motions of :func:`record`: the bench protocol (:func:`protocol`) or an operator's hand
#: (:func:`study.motion.hand_motion`)
MOTIONS = ("protocol", "hand")
#: the distal loads of :func:`record`: a linear spring, nonlinear (stiffening) tissue, free space then contact
LOADS = ("spring", "tissue", "contact")
#: Effects outside the catalogue, for testing the answer ``unknown``: a slow wander of the distal
#: load cell's zero (thermal drift of its bridge), smooth on a ~10 s scale.
UNCATALOGUED = ("load_cell_drift", "load_cell_wander")
#: realistic magnitude of the effects outside the catalogue (SI units): a smooth ~10 s random wander of
#: the distal load cell's zero (the catalogue's entries carry their own ranges: ``Effect.knob``)
_UNCATALOGUED_RANGES = {"load_cell_drift": {"amplitude": (0.3, 0.8)},         # N
                        "load_cell_wander": {"amplitude": (0.3, 0.8)}}        # N (the contract's name for the same)


def _entry(name: str) -> Effect | None:
    """The catalogue entry of an id, a former id (ALIASES) or a rig switch key; None when none."""
    e = CATALOGUE.get(ALIASES.get(name, name))
    return e if e is not None else rig_switches().get(name)


def _switch_key(name: str) -> str | None:
    """The rig switch that simulates effect ``name`` (None: applied to the recorded signals)."""
    e = _entry(name)
    return None if e is None or e.switch is None else e.switch.key


def scenario_effects() -> tuple[str, ...]:
    """Every effect a scenario can hide (the live catalogue's entries with a scenario knob, their rig
    switch keys, and :data:`UNCATALOGUED`)."""
    ids = tuple(e.id for e in CATALOGUE.values() if e.knob is not None)
    keys = tuple(k for k, e in rig_switches().items() if e.knob is not None and k not in ids)
    return ids + keys + UNCATALOGUED


#: catalogue id (or switch key) -> the rig switch that simulates it, at import (the others, sensor effects, are
#: applied to the recorded signals on their channel)
RIG_SWITCH = {e: k for e in scenario_effects() if (k := _switch_key(e)) is not None}


@dataclass(frozen=True, eq=False)
class Recording:
    """A simulated recording and its hidden truth.

    data : MeasuredData with time [s], x_in [m], T_in [N], x_out [m], T_out [N] (measured, noisy).
    truth : dict with ``effect`` (id, ids joined by "+", or "none"), ``effects`` (tuple), ``parameters`` (name -> SI
    value), ``K`` [-],
        ``compliance`` L/EA [m/N], ``level`` [0, 1], the noise levels, ``route`` ((length [m], radius [m])
        pieces, proximal to distal) and ``signals`` (noise-free
        T_out [N], x_out [m], x_in [m], shape (n,)); for evaluation only.
    """

    data: MeasuredData
    truth: dict = field(default_factory=dict)


def realistic_range(effect: str) -> dict[str, tuple[float, float]]:
    """The magnitude range(s) of one effect, SI units: its catalogue entry's scenario knob.

    Raises
    ------
    ValueError
        ``effect`` is neither in the catalogue (with a scenario knob) nor in :data:`UNCATALOGUED`.
    """
    e = _entry(effect)
    if e is not None and e.knob is not None:
        return e.knob.range()
    if effect in _UNCATALOGUED_RANGES:
        return dict(_UNCATALOGUED_RANGES[effect])
    raise ValueError(f"unknown effect {effect!r}; expected one of {sorted(scenario_effects())}")


def effects_config(effect: str | None, level: float, K: float, duration: float,
                   rng: np.random.Generator) -> tuple[EffectsConfig, dict[str, float]]:
    """The rig's effect switches for one hidden effect at ``level`` in [0, 1] of its range.

    Returns the :class:`teleop.config.load.EffectsConfig` (the entry's switch on with its knob's values,
    when it has one) and the truth parameters (SI units). The sign of the knob's signed magnitudes
    (offsets, gains, drifts) is drawn from ``rng``.

    Raises
    ------
    ValueError
        An effect that is neither in the catalogue (with a scenario knob) nor in :data:`UNCATALOGUED`.
    """
    fx = EffectsConfig()
    if effect is None or effect == "none" or effect in UNCATALOGUED:
        return fx, {}
    e = _entry(effect)
    if e is None or e.knob is None:
        raise ValueError(f"unknown effect {effect!r}; expected one of {sorted(scenario_effects())}")
    sign = 1.0 if rng.random() < 0.5 else -1.0
    draw = float(rng.random()) if e.knob.drawn else 0.5       # the instant of a step, apart from its size
    values = e.knob.values(level, sign, K, duration, draw)
    truth = e.knob.truth_of(values)
    if e.switch is None:       # applied to the recorded signals by record()
        return fx, truth
    on = EffectSwitch(True, **{st.name: values[st.name] for st in e.switch.settings if st.name in values})
    return fx.replace(**{e.switch.key: on}), truth


def protocol(duration: float, rate_hz: float, x_max: float, rng: np.random.Generator,
             x_rest: float = 0.0) -> np.ndarray:
    """Proximal displacement command [m], shape (round(duration * rate_hz),), relative to the start.

    A hold at 0, a slow move to ``x_rest`` [m], then blocks of shuffled moves (module docstring) from
    and back to ``x_rest``, up to ``x_max`` [m], repeated until ``duration`` [s] is filled; the last
    block is cut where time runs out.
    """
    dt = 1.0 / rate_hz
    n = int(round(duration * rate_hz))
    pts: list[tuple[float, float]] = [(0.0, 0.0)]           # (time [s], position [m]) corners

    def speed(lo: float = 0.002, hi: float = 0.02) -> float:     # log-uniform [m/s]
        return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))

    def move(u: float, v: float | None = None) -> None:
        t, x = pts[-1]
        x1 = x_rest + u * (x_max - x_rest)
        pts.append((t + max(abs(x1 - x) / (v or speed()), dt), x1))

    def hold(lo: float = 0.2, hi: float = 1.2) -> None:
        t, x = pts[-1]
        pts.append((t + rng.uniform(lo, hi), x))

    def cycle(lo: float, hi: float) -> None:
        v = speed(lo, hi)
        move(float(rng.choice([0.35, 0.65, 1.0])) * rng.uniform(0.9, 1.0), v)
        hold()
        move(0.0, v)
        hold(0.3, 1.5)

    def slow() -> None:
        cycle(0.0015, 0.004)

    def fast() -> None:
        cycle(0.012, 0.025)

    def minor() -> None:
        a = rng.uniform(0.4, 0.75)
        move(a)
        hold(0.1, 0.5)
        move(a * rng.uniform(0.3, 0.7))
        hold(0.1, 0.5)
        move(rng.uniform(a + 0.1, 1.0))
        hold(0.1, 0.5)
        move(rng.uniform(0.2, 0.5) * a)
        hold(0.1, 0.5)
        move(0.0)
        hold(0.3, 1.0)

    def stairs() -> None:
        k = int(rng.integers(3, 5))
        for j in range(1, k + 1):
            move(j / k * rng.uniform(0.85, 1.0))
            hold(0.4, 1.0)
        for j in range(k - 1, -1, -1):
            move(j / k)
            hold(0.4, 1.0)

    def wiggle() -> None:
        mid, amp, f = rng.uniform(0.4, 0.6), rng.uniform(0.1, 0.25), rng.uniform(0.5, 2.0)
        move(mid)
        t0, _ = pts[-1]
        for t in np.arange(1, int(rng.integers(3, 6)) * 16 + 1) / (16 * f):
            pts.append((t0 + t, x_rest + (mid + amp * math.sin(2 * math.pi * t * f)) * (x_max - x_rest)))
        move(0.0)
        hold(0.3, 1.0)

    kinds = [slow, fast, minor, stairs, wiggle]
    hold(0.5, 1.0)                                            # at rest where the encoders were zeroed
    move(0.0, 0.002)                                          # take up to the rest position
    hold(0.3, 0.6)
    while pts[-1][0] < duration:
        for j in rng.permutation(len(kinds)):
            kinds[j]()
    t, x = np.array(pts).T
    return np.interp(np.arange(n) * dt, t, x)


def _check(effect: str | tuple[str, ...] | None, level: float | None, duration: float,
           rate_hz: float, motion: str = "protocol", load: str = "spring") -> tuple[str, ...]:
    """The arguments of :func:`record` checked (its Raises); returns the hidden effects' ids."""
    if motion not in MOTIONS or load not in LOADS:
        raise ValueError(f"motion must be one of {MOTIONS} and load one of {LOADS}, got {motion!r}, {load!r}")
    hidden = () if effect in (None, "none") else (effect,) if isinstance(effect, str) else tuple(effect)
    known = scenario_effects()
    for e in hidden:
        if e not in known:
            raise ValueError(f"unknown effect {e!r}; expected None, 'none' or one of {known}")
    if level is not None and not 0.0 <= level <= 1.0:
        raise ValueError(f"level must be in [0, 1], got {level!r}")
    if not (duration >= 5.0 and rate_hz >= 100.0):
        raise ValueError(f"need duration >= 5 s and rate_hz >= 100 Hz, got {duration!r} s, {rate_hz!r} Hz")
    return hidden


def _run(rig: SimulatedRig, cmd: np.ndarray, dt: float) -> tuple[np.ndarray, tuple[float, float, float]]:
    """Step the rig through the motor command ``cmd`` [m] at ``dt`` [s] from rest. Returns per sample
    (encoder x_in [m], T_in [N], true x_out [m], true T_out [N], true x_in [m]), shape (n, 5), and the
    encoder's count of the rest position (the zero the bench sets there; the rig's encoder_offset switch reads off
    it), true x_out and true x_in at rest before moving [m]."""
    rest = _truth(rig.state)
    at_rest = (rig.drive.encoder(rest.x_in), rest.x_out, rest.x_in)
    out = np.empty((cmd.size, 5))
    for k, x in enumerate(cmd):
        s = rig.step(float(x), dt)
        tr = _truth(s)
        out[k] = (s.x_in, s.T_in, tr.x_out, tr.T_out, tr.x_in)
    return out, at_rest


def record(effect: str | tuple[str, ...] | None = None, *, seed: int = 0, level: float | None = None,
           duration: float = 90.0, rate_hz: float = 1000.0, motion: str = "protocol",
           load: str = "spring") -> Recording:
    """Run one motion through the simulated rig with ``effect`` hidden (None or "none": clean).

    Parameters
    ----------
    effect : str, tuple of str, or None
        An id of :func:`scenario_effects` (catalogue ids, rig switch keys, :data:`UNCATALOGUED`), several of them (all
        at the same ``level``), or None / "none".
    seed : int
        Seeds the rig (K, EA, load), the protocol, the magnitude and every noise.
    level : float in [0, 1], optional
        Position of the magnitude in :func:`realistic_range`; uniform random from the seed if None.
    duration : float
        Length [s], >= 5.
    rate_hz : float
        Sampling and control rate [Hz], >= 100.
    motion : "protocol" (:func:`protocol`) or "hand" (:func:`study.motion.hand_motion`, operator-like), same span.
    load : "spring", "tissue" or "contact"
        A linear spring (1.1-3.1 kN/m), nonlinear tissue (three pieces, 0.3-0.8, 1.3-3.3, 4.3-11 kN/m) or free
        space then contact (20-100 N/m for 1-4 mm, then 1-3 kN/m): :func:`_load`, from its own random stream.

    Raises
    ------
    ValueError
        Unknown effect, motion or load, ``level`` outside [0, 1], too short or too slowly sampled a recording.
    """
    hidden = _check(effect, level, duration, rate_hz, motion, load)
    # independent streams, so that one seed gives the same rig and protocol whatever the effect
    rng, rng_fx, rng_proto, rng_noise = (np.random.default_rng(s) for s in np.random.SeedSequence([seed, 7]).spawn(4))
    u = float(rng_fx.uniform()) if level is None else float(level)
    L, angle = 1.5, 2.0 * math.pi
    K = float(rng.uniform(0.4, 1.0))
    EA = float(rng.uniform(10e3, 20e3))
    k_tissue = float(rng.uniform(1000.0, 3000.0))
    noise_in, noise_out = float(rng.uniform(0.01, 0.03)), float(rng.uniform(0.02, 0.04))
    noise_x, q_x = 1e-6, 1e-6
    geo = SheathGeometry.uniform(L, angle)
    sheath = SheathConfig(EA=EA, runs=tuple(RunConfig(r.length, r.radius) for r in geo.runs))
    fx, params = EffectsConfig(), {}
    for e in hidden:
        one, p = effects_config(e, u, K, duration, rng_fx)
        if (key := _switch_key(e)) is not None:
            fx = fx.replace(**{key: one[key]})
        params.update(p)
    load_cfg = _load(load, k_tissue, np.random.default_rng(np.random.SeedSequence([seed, 7, 1])))
    rig_cfg = SimulatedRigConfig(n_elements=100, mu=K / angle, effects=fx, load=load_cfg,
                                   sensors=SensorConfig(load_cell_noise=noise_in, seed=int(rng.integers(2**31))))
    rig = SimulatedRig(sheath, rig_cfg)
    c = L / EA
    x0 = _truth(rig.state).x_in
    u_rest, u_top = float(rng.uniform(0.1, 0.4)), float(rng.uniform(12.0, 20.0))
    taut = 1.2 * params["tension_offset"] * math.expm1(K) if "friction_offset" in hidden else 0.0
    x_rest, x_top = _span(load_cfg, load == "spring", K, c, taut, u_rest, u_top)
    if motion == "hand":
        cmd = x0 + hand_motion(duration, rate_hz, x_rest, max(x_top, 1.5 * x_rest), rng_proto)
    else:
        cmd = x0 + protocol(duration, rate_hz, x_top, rng_proto, x_rest=x_rest)
    dt = 1.0 / rate_hz
    out, (enc0, x_out0, x_in0) = _run(rig, cmd, dt)
    time = np.arange(1, cmd.size + 1) * dt
    T_in, x_in, T_true, x_true = out[:, 1], out[:, 0] - enc0, out[:, 3], out[:, 2] - x_out0
    T_out = T_true + noise_out * rng_noise.standard_normal(cmd.size)
    x_out = q_x * np.round((x_true + noise_x * rng_noise.standard_normal(cmd.size)) / q_x)
    T_in, x_in, T_out, x_out = _sensor_effects(hidden, params, time, T_in, x_in, T_out, x_out)
    if "load_cell_drift" in hidden or "load_cell_wander" in hidden:
        T_out = T_out + _wander(u, duration, np.arange(time.size) * dt, rng_fx, params)
    data = MeasuredData(time=time, x_in=x_in, T_in=T_in, x_out=x_out, T_out=T_out,
                        metadata={"source": "study/scenarios.py simulated bench recording",
                                  "units": "time=s, x_in=m, T_in=N, x_out=m, T_out=N"},
                        source=f"<scenario seed {seed}>")
    truth = {"effect": "+".join(hidden) or "none", "effects": hidden, "parameters": params, "level": u,
             "K": K, "compliance": c, "EA": EA, "noise_T_in": noise_in, "noise_T_out": noise_out,
             "noise_x_out": noise_x, "route": tuple((r.length, r.radius) for r in geo.runs),
             "motion": motion, "load": {"kind": load, **_load_truth(load_cfg)},
             "signals": {"T_out": out[:, 3], "x_out": out[:, 2] - x_out0, "x_in": out[:, 4] - x_in0}}
    return Recording(data=data, truth=truth)


def _load(kind: str, k_tissue: float, rng: np.random.Generator) -> LoadConfig:
    """The rig's distal load of ``kind`` (:func:`record`'s ``load``); ``k_tissue`` [N/m] the spring's tissue."""
    if kind == "tissue":              # stiffening: three pieces of rising slope
        k1, x1, x2 = float(rng.uniform(300.0, 800.0)), float(rng.uniform(1e-3, 3e-3)), float(rng.uniform(1e-3, 3e-3))
        return LoadConfig(joint_stiffness=k1, tissue_contact=x1, tissue_stiffness=float(rng.uniform(1000.0, 2500.0)),
                          joint_limit=x1 + x2, limit_stiffness=float(rng.uniform(3000.0, 8000.0)), tissue=True)
    if kind == "contact":             # free space on a soft joint spring, then tissue
        return LoadConfig(joint_stiffness=float(rng.uniform(20.0, 100.0)),
                          tissue_contact=float(rng.uniform(1e-3, 4e-3)),
                          tissue_stiffness=float(rng.uniform(1000.0, 3000.0)), joint_limit=0.05, tissue=True)
    return LoadConfig(joint_stiffness=100.0, joint_limit=0.05, tissue_stiffness=k_tissue, tissue_contact=0.0,
                      tissue=True, force=0.0)


def _load_truth(ld: LoadConfig) -> dict[str, float]:
    """The load's law for the truth: slopes [N/m] and where they start [m]."""
    return {"joint_stiffness": ld.joint_stiffness, "tissue_contact": ld.tissue_contact,
            "tissue_stiffness": ld.tissue_stiffness, "joint_limit": ld.joint_limit,
            "limit_stiffness": ld.limit_stiffness}


def _wander(u: float, duration: float, t: np.ndarray, rng: np.random.Generator, params: dict) -> np.ndarray:
    """The uncatalogued slow wander of the distal load cell's zero at ``u`` of its range [N], shape of ``t`` [s] (its
    amplitude kept in ``params``)."""
    amp = realistic_range("load_cell_wander")["amplitude"]
    amplitude = amp[0] + u * (amp[1] - amp[0])
    knots = np.arange(0.0, duration + 20.0, 10.0)
    wander = np.interp(t, knots, rng.uniform(-1.0, 1.0, knots.size))
    params["amplitude"] = amplitude
    return amplitude * wander / max(np.max(np.abs(wander)), 1e-9)


def _span(ld: LoadConfig, spring: bool, K: float, c: float, taut: float, u_rest: float,
          u_top: float) -> tuple[float, float]:
    """Rest and top positions of the motion [m]: the travel that pulls the tendon to ``u_rest`` (plus ``taut``, the
    tension that keeps a tendon with a friction offset taut at the tip) and ``u_top`` [N] of proximal tension."""
    if spring:
        per_newton = math.exp(-K) / (ld.joint_stiffness + ld.tissue_stiffness) + c * -math.expm1(-K) / K
        # rest where the tendon stays taut: friction holds a(e^K - 1) at the tip
        return u_rest * per_newton + taut * (1.0 / (ld.joint_stiffness + ld.tissue_stiffness) + c), u_top * per_newton
    return _reach(ld, K, c, u_rest + taut), _reach(ld, K, c, u_top)


def _reach(ld: LoadConfig, K: float, c: float, T_in: float) -> float:
    """Proximal travel [m] that pulls the tendon to ``T_in`` [N] from slack: the load's travel to T_in e^-K plus
    the elongation c T_in (1 - e^-K) / K (``c`` = L/EA [m/N])."""
    x = np.linspace(0.0, 0.05, 20001)
    springs = ((0.0, ld.joint_stiffness), (ld.tissue_contact, ld.tissue_stiffness),
               (ld.joint_limit, ld.limit_stiffness))
    F = sum(k * np.maximum(0.0, x - x0) for x0, k in springs)
    return float(np.interp(T_in * math.exp(-K), F, x)) + c * T_in * -math.expm1(-K) / K


def _truth(s: RigState) -> RigTruth:
    """The single-tendon ground truth of a simulated rig's state (always there: SimulatedRig._read)."""
    if not isinstance(s.truth, RigTruth):
        raise RuntimeError(f"the simulated rig returned no single-tendon truth (got {type(s.truth).__name__})")
    return s.truth


def _sensor_effects(hidden, params, time, T_in, x_in, T_out, x_out):
    """The sensor effects on the recorded channels other than the rig's load cell (offset, gain, lag
    [s], drift [unit/s]; sign conventions of estimator.offline.effects.catalogue.SensorEffect)."""
    chans = {"T_in": T_in, "x_in": x_in, "T_out": T_out, "x_out": x_out}
    for e in hidden:
        if not e.startswith("sensor_") or ":" not in e or _switch_key(e) is not None:
            continue
        kind, ch = e[7:].split(":")
        y = chans[ch]
        if kind == "offset":
            y = y + params["offset"]
        elif kind == "gain":
            y = y * (1.0 + params["gain"])
        elif kind == "drift":
            y = y + params["rate"] * time
        elif kind == "lag":
            y = np.interp(time - params["delay"], time, y)
        chans[ch] = y
    return chans["T_in"], chans["x_in"], chans["T_out"], chans["x_out"]
