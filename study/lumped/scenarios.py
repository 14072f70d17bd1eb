"""Randomised bench recordings from the dynamic lumped-mass simulator, with hidden effects.

The second, independent simulator (:mod:`study.lumped.simulator`; docs/concepts/model.md, the simulators): the
same :class:`study.scenarios.Recording` and truth keys as :func:`study.scenarios.record`, but a
different physics (tendon masses, an elasto-plastic bristle friction state per node, normal force from
the local curvature)
and a different, seeded randomisation of everything a bench changes between sessions:

* route: 1-4 arcs (position, length and angle random) joined by straight runs, L = 1-2 m, total
  wrap and mu such that K = mu sum(theta) is in [0.2, 1.5];
* tendon EA 6-25 kN; distal load: spring, preloaded spring, constant force or joint with a hard
  limit, with random stiffness, preload, mass and damping;
* sample rate 200-2000 Hz (log-uniform) unless given, motor bandwidth 30-80 Hz;
* sensors: load-cell noise 0.01-0.04 N (proximal) and 0.01-0.05 N (distal), load-cell resolution
  1-5 mN, encoder quantum 0.2-1 um, distal position noise 0-0.5 um and quantum 0.5-2 um;
* protocol (:mod:`study.lumped.protocol`): peak proximal tension 8-20 N, shuffled slow and fast
  cycles, minor loops, dwells, small oscillations and triangle waves; or (``motion="hand"``) operator-like
  motion over the same span (:mod:`study.motion`);
* on request (``load``) nonlinear stiffening tissue or free space then contact as the distal load.

Hidden effects (:data:`EFFECT_IDS`, magnitudes from :func:`study.scenarios.realistic_range` at
``level``) are all physics of the lumped model or of its sensor chain, never the estimator's
kernels: see :func:`_effect_knobs` and docs/concepts/model.md ("The lumped-mass simulator").
"""
from __future__ import annotations

import math

import numpy as np

from estimator.data import MeasuredData
from estimator.geometry import SheathGeometry
from estimator.offline.effects.catalogue import effect
from study.lumped.protocol import command
from study.lumped.simulator import Load, LumpedTendon
from study.motion import hand_motion
from study.scenarios import MOTIONS, Recording, realistic_range

__all__ = ["EFFECT_IDS", "LOADS", "UNCATALOGUED", "record", "draw_route", "draw_load"]

_SENSOR = tuple(f"sensor_{kind}:{ch}" for kind, chans in
                (("offset", ("T_in", "T_out", "x_in", "x_out")), ("gain", ("T_in", "T_out")),
                 ("lag", ("T_in", "T_out", "x_in", "x_out")), ("drift", ("T_in", "T_out"))) for ch in chans)
#: Effect ids of the contract with the diagnosis (physical first, then one per sensor channel).
EFFECT_IDS: tuple[str, ...] = ("velocity_friction", "pretension", "curvature_drift", "friction_step",
                               "tendon_stiffening", "stiction", "friction_offset", "presliding",
                               "distal_backlash") + _SENSOR
#: distal loads :func:`record` can be asked for: the seed's own kinds and nonlinear tissue, free space then contact
LOADS: tuple[str, ...] = ("spring", "preloaded", "constant", "joint", "tissue", "contact")
#: Outside the catalogue: a smooth ~10 s random wander of the distal load cell zero.
UNCATALOGUED: tuple[str, ...] = ("load_cell_wander",)

_STRIBECK_SPEED = 0.5e-3   # m/s, speed scale of the static-friction peak (stiction)
_SETTLE = 1.0              # s of rest simulated before the recording starts (not recorded)


def draw_route(rng: np.random.Generator) -> tuple[tuple[tuple[float, float], ...], float]:
    """A random route and friction coefficient: ((length [m], radius [m]) pieces, mu [-]).

    1-4 arcs (20-80 % of the length, radii >= 15 mm) joined by straight runs (a straight run may
    be absent at either end), total length 1-2 m, K = mu * total angle uniform in [0.2, 1.5].
    """
    L = rng.uniform(1.0, 2.0)
    K = rng.uniform(0.2, 1.5)
    mu = rng.uniform(0.08, 0.3)
    total = float(np.clip(K / mu, math.pi / 4, 4 * math.pi))
    mu = K / total
    for _ in range(1000):
        n = int(rng.integers(1, 5))
        f = rng.uniform(0.2, 0.8)
        arcs = rng.dirichlet(np.full(n, 3.0)) * f * L
        straight = rng.dirichlet(np.full(n + 1, 2.0)) * (1 - f) * L
        angles = rng.dirichlet(np.full(n, 3.0)) * total
        if np.all(arcs / angles >= 0.015):
            break
    pieces: list[tuple[float, float]] = []
    for j in range(n):
        if straight[j] > 1e-3:
            pieces.append((float(straight[j]), math.inf))
        pieces.append((float(arcs[j]), float(arcs[j] / angles[j])))
    if straight[n] > 1e-3:
        pieces.append((float(straight[n]), math.inf))
    return tuple(pieces), float(mu)


def draw_load(rng: np.random.Generator, kind: str | None = None, K: float = 0.8) -> Load:
    """A random distal load of ``kind`` (random among spring, preloaded, constant, joint if None; "tissue" and
    "contact" only when asked: :data:`LOADS`); a constant force is drawn so that the proximal tension while it slides,
    P e^K, is 4-12 N."""
    kind = kind or str(rng.choice(["spring", "preloaded", "constant", "joint"]))
    mass, damping = rng.uniform(0.002, 0.010), rng.uniform(0.2, 1.0)
    logu = (lambda lo, hi: float(math.exp(rng.uniform(math.log(lo), math.log(hi)))))
    if kind == "spring":
        return Load("spring", stiffness=logu(500.0, 5000.0), mass=mass, damping=damping)
    if kind == "preloaded":
        return Load("preloaded", stiffness=logu(300.0, 3000.0), preload=rng.uniform(0.5, 3.0), mass=mass,
                    damping=damping)
    if kind == "constant":
        return Load("constant", preload=rng.uniform(4.0, 12.0) * math.exp(-K), mass=mass, damping=damping)
    if kind == "joint":
        return Load("joint", stiffness=rng.uniform(50.0, 300.0), limit=rng.uniform(1e-3, 4e-3),
                    stop=logu(1e5, 1e6), mass=mass, damping=damping)
    if kind == "tissue":              # exponential stiffening over 1-3 mm, 0.2-1 kN/m at first touch
        return Load("tissue", stiffness=logu(200.0, 1000.0), limit=rng.uniform(1e-3, 3e-3), mass=mass,
                    damping=damping)
    if kind == "contact":             # 1-4 mm of free space on a soft spring, then tissue
        return Load("contact", stiffness=rng.uniform(20.0, 100.0), limit=rng.uniform(1e-3, 4e-3),
                    contact_stiffness=logu(500.0, 5000.0), mass=mass, damping=damping)
    return Load(kind, mass=mass, damping=damping)


def _effect_knobs(hidden: tuple[str, ...], u: float, K: float, mu: float, geo: SheathGeometry, duration: float,
                  rng: np.random.Generator) -> tuple[dict, dict, dict]:
    """Simulator keyword arguments, sensor-chain settings and truth parameters per effect id.

    Returns (sim kwargs, sensor dict {id: {name: value}}, truth {id: {name: SI value}}). Signs of
    offsets, gains, drifts and the K drift are drawn from ``rng``.
    """
    sim, sensor, truth = {}, {}, {}
    for e in hidden:
        r = {k: lo + u * (hi - lo) for k, (lo, hi) in realistic_range(e).items()}
        sign = 1.0 if rng.random() < 0.5 else -1.0
        if e == "velocity_friction":           # g(v) = mu (1 + c_v |v|), v the node's sliding speed
            sim["speed_coefficient"] = r["viscous"]
            p = {"viscous": r["viscous"]}
        elif e == "pretension":
            sim["pretension"] = r["tension"]
            p = {"tension": r["tension"]}
        elif e == "curvature_drift":           # mu(t) = mu + mu_rate t, route kept
            sim["mu_rate"] = sign * r["relative_change"] * mu / duration
            p = {"K_rate": sign * r["relative_change"] * K / duration, "relative_change": sign * r["relative_change"]}
        elif e == "friction_step":             # mu -> mu (1 + relative_step) at t_s (the run split there)
            step_knob = effect(e).knob
            if step_knob is None:  # pragma: no cover - the entry has one
                raise ValueError(f"{e}: no scenario knob in the catalogue")
            p = step_knob.values(u, sign, K, duration, float(rng.random()))
            sim["step_time"], sim["step_mu"] = p["t_s"], mu * p["relative_step"]
        elif e == "tendon_stiffening":
            sim["softening"], sim["toe_tension"] = r["softening"], r["toe_tension"]
            p = {"softening": r["softening"], "toe_tension": r["toe_tension"]}
        elif e == "stiction":                  # Stribeck peak of the LuGre g(v)
            sim["static_ratio"], sim["stribeck_speed"] = r["static_ratio"], _STRIBECK_SPEED
            p = {"static_ratio": r["static_ratio"], "stribeck_speed": _STRIBECK_SPEED}
        elif e == "friction_offset":           # q from F0 = mu q int_0^L e^{-mu (theta_L - theta(s))} ds
            s = np.linspace(0.0, geo.length, 2001)
            f = np.exp(-mu * (geo.total_angle - geo.wrap_angle(s)))
            integral = float(np.sum(0.5 * (f[1:] + f[:-1]) * np.diff(s)))
            q = r["distal_offset"] / (mu * integral)
            sim["normal_load"] = q
            p = {"distal_offset": r["distal_offset"], "normal_load": q,
                 "tension_offset": r["distal_offset"] / -math.expm1(-K)}
        elif e == "presliding":                # reversal travel d_p of every node's bristle
            sim["presliding"] = r["distance"]
            p = {"distance": r["distance"]}
        elif e == "distal_backlash":
            sim["backlash"] = r["width"]
            p = {"width": r["width"]}
        elif e.startswith("sensor_"):          # the catalogue's knob: magnitude and which ones take a sign
            knob = effect(e).knob
            if knob is None:  # pragma: no cover - every sensor entry has one
                raise ValueError(f"{e}: no scenario knob in the catalogue")
            p = knob.values(u, sign, K, duration)
            sensor[e] = dict(p)
        elif e == "load_cell_wander":
            sensor[e] = {"amplitude": r["amplitude"]}
            p = {"amplitude": r["amplitude"]}
        else:  # pragma: no cover - record() checked the ids
            raise ValueError(e)
        truth[e] = p
    return sim, sensor, truth


def _channel(sensor: dict, ch: str, t: np.ndarray, x: np.ndarray) -> np.ndarray:
    """A channel through its sensor effects: lag (pure delay), gain, offset, drift (in that order)."""
    lag = sensor.get(f"sensor_lag:{ch}", {}).get("delay", 0.0)
    if lag:
        x = np.interp(t - lag, t, x)   # the value tau ago (held at the start)
    g = sensor.get(f"sensor_gain:{ch}", {}).get("gain", 0.0)
    off = sensor.get(f"sensor_offset:{ch}", {}).get("offset", 0.0)
    rate = sensor.get(f"sensor_drift:{ch}", {}).get("rate", 0.0)
    return (1.0 + g) * x + off + rate * t


def _span(geo: SheathGeometry, mu: float, EA: float, load: Load, sim_kw: dict, T_rest: float, T_peak: float,
          travel: float, tension_offset: float) -> tuple[float, float, float]:
    """Rest and top positions of the protocol [m] from the rest state, and M_e [m/N].

    A bench operator aims at a proximal tension: the travel to a pull at T [N] is the load's travel
    to T e^-K plus the elongation (1/EA) int phi(T e^{-mu theta(s)}) ds (phi the stiffening law, the
    identity without it), counted from the rest state (pretension included). With a friction offset
    the rest is raised so that the tendon stays taut; a constant-force load adds ``travel`` [m].
    """
    K = mu * geo.total_angle
    s = np.linspace(0.0, geo.length, 2001)
    f = np.exp(-mu * geo.wrap_angle(s))
    M_e = float(np.sum(0.5 * (f[1:] + f[:-1]) * np.diff(s))) / EA
    beta, Tc = sim_kw.get("softening", 0.0), sim_kw.get("toe_tension", 1.0)
    T0 = sim_kw.get("pretension", 0.0)

    def reach(T: float) -> float:
        prof = T * f
        strain = prof + beta * Tc * -np.expm1(-prof / Tc)
        elong = float(np.sum(0.5 * (strain[1:] + strain[:-1]) * np.diff(s))) / EA
        if load.kind == "constant":
            return elong
        return max(load.position_at(T * math.exp(-K)) - load.position_at(T0), 0.0) + elong

    base = reach(T0)
    T_low = T_rest + 1.2 * tension_offset * math.expm1(K)
    x_rest = max(reach(T_low) - base, 0.0)
    x_top = max(reach(max(T_peak, T_low + 2.0)) - base, 0.0) + (travel if load.kind == "constant" else 0.0)
    return x_rest, x_top, M_e


def _run(tl: LumpedTendon, cmd: np.ndarray, rate: float, step: tuple[float, float] | None) -> dict[str, np.ndarray]:
    """The run over ``cmd``; with a friction ``step`` (t_s [s], d mu [-]) split at the first sample at or after t_s,
    mu stepped there (the sheath reshaped at one instant)."""
    if step is None:
        return tl.run(cmd, rate)
    k = min(max(int(math.ceil(step[0] * rate)) - 1, 0), cmd.size)
    first = tl.run(cmd[:k], rate)
    tl.mu += step[1]
    second = tl.run(cmd[k:], rate)
    return {name: np.concatenate([first[name], second[name]]) for name in first}


def _check(effect: str | tuple[str, ...] | None, seed: int, level: float | None, duration: float,
           rate_hz: float | None, motion: str = "protocol", load: str | None = None) -> tuple[str, ...]:
    """The arguments of :func:`record` checked (its Raises); returns the hidden effects' ids."""
    if motion not in MOTIONS or (load is not None and load not in LOADS):
        raise ValueError(f"motion must be one of {MOTIONS} and load None or one of {LOADS}, got {motion!r}, {load!r}")
    hidden = () if effect in (None, "none") else (effect,) if isinstance(effect, str) else tuple(effect)
    for e in hidden:
        if e not in EFFECT_IDS + UNCATALOGUED:
            raise ValueError(f"effect: unknown id {e!r}; expected None, 'none' or ids of {EFFECT_IDS + UNCATALOGUED}")
    if len(set(hidden)) != len(hidden):
        raise ValueError(f"effect: an id is repeated in {hidden!r}")
    if not isinstance(seed, (int, np.integer)) or isinstance(seed, bool) or seed < 0:
        raise ValueError(f"seed must be an int >= 0, got {seed!r}")
    if level is not None and not (isinstance(level, (int, float)) and 0.0 <= level <= 1.0):
        raise ValueError(f"level must be in [0, 1], got {level!r}")
    if not (isinstance(duration, (int, float)) and math.isfinite(duration) and duration >= 5.0):
        raise ValueError(f"duration must be >= 5 s, got {duration!r}")
    if rate_hz is not None and not (isinstance(rate_hz, (int, float)) and 100.0 <= rate_hz <= 20000.0):
        raise ValueError(f"rate_hz must be in [100, 20000] Hz or None, got {rate_hz!r}")
    return hidden


def _measure(sensor: dict, t: np.ndarray, true: dict[str, np.ndarray], noise: tuple[float, float, float],
             quanta: tuple[float, float, float], rng_noise: np.random.Generator, rng_fx: np.random.Generator,
             duration: float, rate: float, seed: int) -> MeasuredData:
    """What the bench's sensors read of the ``true`` signals (T_in, T_out [N], x_in, x_out [m], shape (n,)):
    the hidden sensor effects, white noise (sigma of T_in, T_out [N], x_out [m]), a slow load-cell wander
    when hidden, and quantisation (quanta of T [N], x_in, x_out [m])."""
    noise_in, noise_out, noise_x = noise
    q_T, q_in, q_out = quanta
    n = t.size
    T_in = _channel(sensor, "T_in", t, true["T_in"]) + noise_in * rng_noise.standard_normal(n)
    T_out = _channel(sensor, "T_out", t, true["T_out"]) + noise_out * rng_noise.standard_normal(n)
    if "load_cell_wander" in sensor:
        knots = np.arange(0.0, duration + 20.0, 10.0)
        w = np.interp(t, knots + rng_fx.uniform(-3.0, 3.0), rng_fx.uniform(-1.0, 1.0, knots.size))
        w = np.convolve(w, np.ones(max(1, int(rate))) / max(1, int(rate)), mode="same")   # smooth corners (1 s)
        T_out = T_out + sensor["load_cell_wander"]["amplitude"] * w / max(float(np.max(np.abs(w))), 1e-9)
    x_in = _channel(sensor, "x_in", t, true["x_in"])
    x_out = _channel(sensor, "x_out", t, true["x_out"]) + noise_x * rng_noise.standard_normal(n)
    return MeasuredData(time=t, x_in=q_in * np.round(x_in / q_in), T_in=q_T * np.round(T_in / q_T),
                        x_out=q_out * np.round(x_out / q_out), T_out=q_T * np.round(T_out / q_T),
                        metadata={"source": "study/lumped/scenarios.py lumped-mass bench recording",
                                  "units": "time=s, x_in=m, T_in=N, x_out=m, T_out=N"},
                        source=f"<lumped scenario seed {seed}>")


def _flat(by_effect: dict) -> dict[str, float]:
    """The truth parameters of every hidden effect in one dict (a name two effects share prefixed by the second's
    id)."""
    params: dict[str, float] = {}
    for e, p in by_effect.items():
        for k, val in p.items():
            params[k if k not in params else f"{e}.{k}"] = float(val)
    return params


def record(effect: str | tuple[str, ...] | None = None, *, seed: int = 0, level: float | None = None,
           duration: float = 90.0, rate_hz: float | None = None, motion: str = "protocol",
           load: str | None = None) -> Recording:
    """One randomised bench recording from the lumped simulator with ``effect`` hidden.

    Parameters
    ----------
    effect : None, "none", an id of :data:`EFFECT_IDS` or :data:`UNCATALOGUED`, or a tuple of ids
        (all at the same ``level``).
    seed : int
        Seeds the rig, route, load, rate, sensors, protocol, magnitudes and noise. The rig and the
        protocol of a seed do not depend on ``effect``.
    level : float in [0, 1], optional
        Position of each magnitude in its realistic range; uniform random from the seed if None.
    duration : float >= 5 [s]
    rate_hz : float in [100, 20000] [Hz], optional; log-uniform in [200, 2000] from the seed if None.
    motion : "protocol" (:func:`study.lumped.protocol.command`) or "hand" (operator-like motion over the same span,
        :func:`study.motion.hand_motion`: random moves with holds, speeds up to 25 mm/s).
    load : None (the seed's own among spring, preloaded, constant, joint) or a kind of :data:`LOADS` ("tissue":
        nonlinear stiffening tissue; "contact": free space then contact), drawn from a separate stream: the rig's
        other draws are the seed's whatever ``load``.

    Returns
    -------
    Recording
        data: time, x_in, T_in, x_out, T_out (shape (n,), n = round(duration * rate)); truth: as
        :func:`study.scenarios.record` plus simulator, route ((length, radius) pairs), rate_hz,
        load (dict), EA, L, mu, parameters_by_effect and the sensor levels.

    Raises
    ------
    ValueError
        Unknown effect, motion or load, ``seed`` not an int, ``level``, ``duration`` or ``rate_hz`` out of range.
    """
    hidden = _check(effect, seed, level, duration, rate_hz, motion, load)
    rng, rng_fx, rng_proto, rng_noise = (np.random.default_rng(s)
                                         for s in np.random.SeedSequence([int(seed), 8]).spawn(4))
    route, mu = draw_route(rng)
    geo = SheathGeometry(route)
    K, L = mu * geo.total_angle, geo.length
    EA = float(rng.uniform(6e3, 25e3))
    drawn = draw_load(rng, K=K)
    dist = draw_load(np.random.default_rng(np.random.SeedSequence([int(seed), 8, 1])), load, K) if load else drawn
    rate = float(round(math.exp(rng.uniform(math.log(200.0), math.log(2000.0)))))   # drawn always: same rig
    rate = rate if rate_hz is None else float(rate_hz)
    noise_in, noise_out = float(rng.uniform(0.01, 0.04)), float(rng.uniform(0.01, 0.05))
    q_T, q_in = float(rng.uniform(1e-3, 5e-3)), float(rng.uniform(0.2e-6, 1e-6))
    q_out = float(rng.uniform(0.5e-6, 2e-6))
    noise_x = float(rng.uniform(0.0, 0.5e-6))
    bw, vmax = float(rng.uniform(30.0, 80.0)), float(rng.uniform(0.1, 0.2))
    T_peak, T_rest = float(rng.uniform(8.0, 20.0)), float(rng.uniform(0.3, 1.5))
    travel = float(rng.uniform(2e-3, 6e-3))
    u = float(rng_fx.uniform()) if level is None else float(level)
    sim_kw, sensor, by_effect = _effect_knobs(hidden, u, K, mu, geo, duration, rng_fx)
    step = (sim_kw.pop("step_time"), sim_kw.pop("step_mu")) if "step_time" in sim_kw else None
    tl = LumpedTendon(geo, mu, EA, dist, motor_bandwidth_hz=bw, motor_max_speed=vmax, **sim_kw)
    x_rest, x_top, M_e = _span(geo, mu, EA, dist, sim_kw, T_rest, T_peak, travel,
                               by_effect.get("friction_offset", {}).get("tension_offset", 0.0))
    tl.run(np.full(int(round(_SETTLE * rate)), tl.state[0]), rate)   # settle at rest, not recorded
    tl.state[3] = 0.0
    start = {k: float(v) for k, v in zip(("x_motor", "x_joint", "x_end"), (tl.state[0], tl.state[2], tl.u[-1]),
                                         strict=False)}
    move = hand_motion if motion == "hand" else command
    cmd = start["x_motor"] + move(duration, rate, x_rest, x_top, rng_proto)
    sig = _run(tl, cmd, rate, step)
    n = cmd.size
    t = np.arange(1, n + 1) / rate
    x_in_true = sig["x_motor"] - start["x_motor"]
    x_out_true = sig["x_joint"] - start["x_joint"]
    data = _measure(sensor, t, {"T_in": sig["T_in"], "T_out": sig["T_out"], "x_in": x_in_true, "x_out": x_out_true},
                    (noise_in, noise_out, noise_x), (q_T, q_in, q_out), rng_noise, rng_fx, duration, rate, seed)
    params = _flat(by_effect)
    truth = {"effect": "+".join(hidden) or "none", "effects": hidden, "parameters": params,
             "parameters_by_effect": by_effect, "level": u, "K": K, "mu": mu, "compliance": L / EA, "EA": EA,
             "L": L, "M_e": M_e, "noise_T_in": noise_in, "noise_T_out": noise_out, "noise_x_out": noise_x,
             "quantum_T": q_T, "quantum_x_in": q_in, "quantum_x_out": q_out, "simulator": "lumped",
             "route": route, "rate_hz": rate, "load": dist.describe(), "motion": motion, "motor_bandwidth_hz": bw,
             "signals": {"T_out": sig["T_out"].copy(), "T_in": sig["T_in"].copy(), "x_out": x_out_true,
                         "x_in": x_in_true, "x_end": sig["x_end"] - start["x_end"]}}
    return Recording(data=data, truth=truth)
