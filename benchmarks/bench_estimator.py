"""Estimator speed: online step time per tendon and batch throughput. Prints figures, never fails on time."""
from __future__ import annotations

import math
import time

import numpy as np

from estimator.capstan import phase_formula_batch
from estimator.online.distal import DistalEstimator, estimate_batch
from estimator.online.extended import ExtendedEstimator
from estimator.online.pair_model import PairModelEstimator
from estimator.pair_kernels import EFFECT_PARAMS
from estimator.sheath import SheathModel
from teleop.config.schema import Config


def _model() -> SheathModel:
    cfg = Config()
    return SheathModel.from_geometry(cfg.sheath.geometry(), cfg.rig.simulated.mu, cfg.sheath.EA)


def bench_step(n_nodes: int, n: int = 50_000, tension_noise: float = 0.0) -> float:
    est = DistalEstimator(_model(), n_nodes=n_nodes, tension_noise=tension_noise)
    t = np.arange(n) * 1e-3
    T_in = 12 + 8 * np.sin(2 * np.pi * 0.5 * t) + np.random.default_rng(0).normal(0, 0.02, n)
    for k in range(2000):  # warm-up (numba compile, caches)
        est.step(T_in[k], 0.0, t[k])
    best = math.inf
    for _ in range(3):
        t0 = time.perf_counter()
        for k in range(n):
            est.step(T_in[k], 0.0, t[k])
        best = min(best, (time.perf_counter() - t0) / n)
    return best


def bench_batch(n_nodes: int, n: int = 2_000_000) -> float:
    m = _model()
    t = np.arange(n) * 1e-3
    T_in = 12 + 8 * np.sin(2 * np.pi * 0.5 * t) + np.random.default_rng(0).normal(0, 0.02, n)
    x_in = np.zeros(n)
    estimate_batch(T_in[:1000], x_in[:1000], m, time=t[:1000], n_nodes=n_nodes)  # compile
    t0 = time.perf_counter()
    estimate_batch(T_in, x_in, m, time=t, n_nodes=n_nodes)
    return n / (time.perf_counter() - t0)


def bench_paper(n: int = 200_000) -> float:
    T_in = 12 + 8 * np.sin(np.arange(n) * 2e-3)
    t0 = time.perf_counter()
    phase_formula_batch(T_in, 0.63, 1e-4)
    return n / (time.perf_counter() - t0)


#: the capstan-joint pair model's parameters (KAIST-like, SI; estimator.offline.pair.models) and its effects' values
PAIR = {"G": 1.4, "lam": 0.4, "K_a": 0.9, "K_b": 0.5, "k": 4.0, "theta0": 0.0}
PAIR_EXTRA = {"b": 0.01, "tau": 0.02, "lam_s": 0.1, "lam_d": 0.05, "toe": 4.0, "toe_tension": 1.0}
PAIR_MODELS = ((), ("series_compliance",), ("joint_backlash", "sensor_delay"), ("drive_observer",), ("tendon_toe",))


def bench_pair_model(effects: tuple[str, ...], n_nodes: int = 24, n: int = 20_000) -> float:
    """Seconds per :meth:`PairModelEstimator.step` (one joint, one 1 kHz sample) of the capstan-joint pair model."""
    values = PAIR | {p: PAIR_EXTRA[p] for e in effects for p in EFFECT_PARAMS[e]}
    t = np.arange(n) * 1e-3
    c = 1.0 * np.sin(2 * np.pi * 0.5 * t)
    rng = np.random.default_rng(0)
    Ta = 5 + 3 * c + rng.normal(0, 0.02, n)
    Tb = 5 - 3 * c + rng.normal(0, 0.02, n)
    best = math.inf
    for _ in range(3):
        est = PairModelEstimator("capstan", effects, values, (5.0, 5.0), n_nodes=n_nodes)
        for k in range(200):   # warm-up (numba compile, caches)
            est.step(c[k], Ta[k], Tb[k], t[k])
        est.reset()
        t0 = time.perf_counter()
        for k in range(n):
            est.step(c[k], Ta[k], Tb[k], t[k])
        best = min(best, (time.perf_counter() - t0) / n)
    return best


#: extended single-tendon models (catalogue names, SI) timed per cycle: the base model through the shared loop, one
#: effect, every per-cycle form at once, and the friction step with K tracked online (True: ``track_friction``)
EXTENDED = (("base", {"K": 0.7}, False), ("stiction", {"K": 0.7, "r_s": 0.4}, False),
            ("all forms", {"K": 0.7, "c_v": 15.0, "K_rate": 0.002, "r_s": 0.3, "a": 0.5, "T0": 1.0, "beta": 1.0,
                           "x_p": 60e-6, "d_b": 100e-6, "b_T_in": 0.2, "g_T_in": 0.03, "d_T_in": 0.005,
                           "b_x_in": 2e-5}, False),
            ("friction step, K tracked online", {"K": 0.7, "dK": 0.2, "t_s": 20.0}, True))


def bench_extended(values: dict, track: bool = False, n_nodes: int = 32, average: int = 5, n: int = 50_000) -> float:
    """Seconds per :meth:`ExtendedEstimator.step` (one tendon, one 1 kHz sample, the readings averaged over 5)."""
    u, w = SheathModel(K=1.0, compliance=1.0).nodes(n_nodes)
    t = np.arange(n) * 1e-3
    x = 2e-3 * np.sin(2 * np.pi * 0.5 * t) ** 2
    T_in = 1.0 + 6e3 * x + np.random.default_rng(0).normal(0, 0.02, n)
    best = math.inf
    for _ in range(3):
        est = ExtendedEstimator(values, u, w, 1e-4, tension_noise=0.02, average=average, track_friction=track)
        for k in range(200):   # warm-up (numba compile, caches)
            est.step(T_in[k], x[k], t[k])
        est.reset()
        t0 = time.perf_counter()
        for k in range(n):
            est.step(T_in[k], x[k], t[k])
        best = min(best, (time.perf_counter() - t0) / n)
    return best


def main() -> None:
    print("estimator (profile memory, one tendon)")
    for nodes in (50, 100, 200):
        print(f"  online step   n_nodes={nodes:4d}: {bench_step(nodes) * 1e6:7.2f} us/sample   (aim <= 10 us)")
    for nodes in (50, 100, 200):
        print(f"  + noise band  n_nodes={nodes:4d}: {bench_step(nodes, tension_noise=0.02) * 1e6:7.2f} us/sample   "
              "(aim <= 10 us)")
    for nodes in (50, 100, 200):
        print(f"  batch         n_nodes={nodes:4d}: {bench_batch(nodes) / 1e6:7.2f} M samples/s (aim >= 1)")
    print(f"  paper phase formulas (compiled)   : {bench_paper() / 1e6:7.3f} M samples/s")
    print("extended single-tendon model per cycle (one tendon, n_nodes=32, readings averaged over 5)")
    for name, values, track in EXTENDED:
        print(f"  {name:40s}: {bench_extended(values, track) * 1e6:7.2f} us/step   (aim <= 10 us)")
    print("capstan-joint pair model per cycle (one joint, n_nodes=24)")
    for effects in PAIR_MODELS:
        name = "+".join(("capstan", *effects))
        print(f"  {name:40s}: {bench_pair_model(effects) * 1e6:7.2f} us/step   (aim <= 50 us)")


if __name__ == "__main__":
    main()
