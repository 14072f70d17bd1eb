"""What the base model gets wrong on a recording, which physical effect explains it, and the gain.

:func:`diagnose` fits the base model (profile memory with K and L/EA) on a training block, holds
out the rest (whole cycles: the split is moved to a rest), fits every extension of the catalogue
(:mod:`estimator.effects`) on the same block and scores all of them on the held-out block. The
extension with the lowest held-out score

    S = sum_signals (rmse_ext / floor)^2 / sum_signals (rmse_base / floor)^2

(rmse on the held-out measured samples, floor = the noise a perfect model would leave on that signal)
is accepted when

    S + PENALTY * n_extra_parameters < 1                       (relative to the model so far)

PENALTY is an information-criterion-like price calibrated on clean recordings so that no extension
earns its place there (docs/diagnosis.md). A second extension is tried on the same rule, relative to
the first, while the residual still holds structure: held-out rmse above STRUCTURE_RATIO times the
noise of a signal. With nothing accepted the answer is ``none`` - or ``unknown`` when the base
residual holds such structure. Fitting helpers live in :mod:`estimator.diagnosis_fit`.
"""
from __future__ import annotations

import math
import sys
import time as _time
from typing import Callable

import numpy as np

from estimator.diagnosis_fit import (SIGNALS, fit_model, heldout_mse, noise_level, prepare, raw_rmse, split_at_rest,
                                     start_points)
from estimator.effects import CATALOGUE, NONE, UNKNOWN, Effect, predict
from estimator.data import MeasuredData

__all__ = ["diagnose", "predictions", "PENALTY", "STRUCTURE_RATIO"]

PENALTY = 0.30          # price per extra parameter on the held-out score S (base = 1) [-]
STRUCTURE_RATIO = 3.0   # held-out rmse / noise above this on a signal: structure left [-]
_UNITS = {"T_out": "N", "x_out": "m"}


class _Progress:
    """A one-line stderr bar (``enabled`` True), a callback(done, total, label), or nothing."""

    def __init__(self, total: int, enabled: bool | Callable):
        self.total, self.done, self.enabled = total, 0, enabled

    def __call__(self, label: str) -> None:
        self.done = min(self.done + 1, self.total)
        if callable(self.enabled):
            self.enabled(self.done, self.total, label)
        elif self.enabled:
            n = 30 * self.done // self.total
            sys.stderr.write(f"\rdiagnose [{'#' * n}{'.' * (30 - n)}] {self.done}/{self.total} {label:<28}")
            if self.done >= self.total:
                sys.stderr.write("\n")
            sys.stderr.flush()

    def finish(self) -> None:
        if self.done < self.total:
            self.done = self.total - 1
            self("done")


class _Fit:
    """One fitted model (a list of extensions) with its held-out scores."""

    def __init__(self, effects: list[Effect], values: dict, compliance: float, s, k: int, data, t_split: float,
                 base: "_Fit | None" = None, floor: dict[str, float] | None = None):
        self.effects, self.values, self.compliance = effects, values, compliance
        self.pred = predict(effects, values, s, compliance=compliance)
        self.mse = heldout_mse(self.pred, s, k)                       # averaged series (structure test)
        self.raw = raw_rmse(self.pred, s, data, t_split)               # measured samples (selection, gain)
        self.S = 1.0 if base is None else _score(self.raw, base.raw, floor)

    @property
    def n_params(self) -> int:
        return sum(len(e.parameters) for e in self.effects)

    @property
    def ids(self) -> list[str]:
        return [e.id for e in self.effects]


def _score(raw: dict, base: dict, floor: dict[str, float]) -> float:
    """Held-out score relative to the base: sum over signals of (rmse / floor)^2, extension over base.

    Each signal counts by how far above its noise floor it is, so a signal the extension does not
    touch (T_out for tendon stiffening) does not dilute what it explains in the other."""
    num = den = 0.0
    for key, f in floor.items():
        if raw.get(key) is not None and base.get(key) and f > 0:
            num += (raw[key] / f) ** 2
            den += (base[key] / f) ** 2
    return num / den if den > 0 else 1.0


def _structure(fit: _Fit, s, k: int, noise: dict[str, float]) -> dict[str, float]:
    """Held-out rmse / noise floor per signal on the averaged series [-]."""
    return {n: math.sqrt(fit.mse[n]) / max(noise[n], 1e-300) for n in fit.mse}


def _gain(ext: dict, base: dict, signal: str) -> float | None:
    b, e = base.get(f"rmse_{signal}_{_UNITS[signal]}"), ext.get(f"rmse_{signal}_{_UNITS[signal]}")
    return None if b is None or e is None or b <= 0 else 1.0 - e / b


def _parameters(fit: _Fit) -> dict:
    out = {"K": {"value": fit.values["K"], "unit": "-", "effect": "base"},
           "compliance": {"value": fit.compliance, "unit": "m/N", "effect": "base"}}
    for e in fit.effects:
        for p in e.parameters:
            out[p.name] = {"value": fit.values[p.name], "unit": p.unit, "effect": e.id}
    return out


def diagnose(data: MeasuredData, *, train_fraction: float = 0.6, progress: bool | Callable = False,
             effects: tuple[str, ...] | None = None, max_effects: int = 2, n_nodes: int = 32,
             target_rate: float = 200.0, wrap_shape: np.ndarray | None = None) -> dict:
    """Diagnose one recording: base model error, the effect that explains it, the held-out gain.

    Parameters
    ----------
    data : MeasuredData
        time [s], x_in [m], T_in [N] and at least one of T_out [N], x_out [m]; positions zeroed at a
        rest of the unloaded tendon (or at the preloaded rest: that is the pretension effect).
    train_fraction : float in [0.3, 0.9]
        Nominal share of the duration used for fitting; the split moves to a rest within 8 %.
    progress : bool or callable(done, total, label)
        A stderr progress bar, or a callback per fitted model.
    effects : tuple of ids, optional
        Candidate extensions (default: the whole catalogue).
    max_effects : int
        Most extensions accepted together, >= 1.
    n_nodes, target_rate, wrap_shape
        Profile elements, averaging rate [Hz] and route shape, see :func:`estimator.diagnosis_fit.prepare`.

    Returns
    -------
    dict, JSON-ready:
        ``cause`` one id (an effect, "none" or "unknown"); ``causes`` accepted ids in order (plus
        "unknown" when structure is left); ``base``, ``extended`` {rmse_T_out_N, rmse_x_out_m} on the
        held-out measured samples (None for a signal not recorded); ``gain`` 1 - extended/base on
        ``primary_signal`` (T_out when recorded, x_out for the effects that leave T_out alone after
        the first pull: pretension, tendon_stiffening, or without T_out); ``parameters`` name ->
        {value, unit, effect}; ``candidates`` id -> {rmse_T_out_N, rmse_x_out_m, gain, gain_T_out,
        gain_x_out, score, accepted, parameters}; ``split``, ``noise``, ``structure``, ``model`` and
        ``base_model`` (enough to re-run both, see :func:`teleop.report.write_report`), ``settings``,
        ``elapsed_s``.

    Raises
    ------
    DataError
        No distal signal. ValueError: too short a recording, a bad fraction or an unknown effect id.
    """
    t_start = _time.perf_counter()
    names = tuple(CATALOGUE) if effects is None else tuple(effects)
    for n in names:
        if n not in CATALOGUE:
            raise ValueError(f"unknown effect {n!r}; known: {', '.join(CATALOGUE)}")
    if max_effects < 1:
        raise ValueError(f"max_effects must be >= 1, got {max_effects!r}")
    s = prepare(data, n_nodes=n_nodes, target_rate=target_rate, wrap_shape=wrap_shape)
    k = split_at_rest(s, train_fraction)
    train = s.slice(k)
    t_split = float(s.time[k] - 0.5 * (s.time[1] - s.time[0]))
    cands = [CATALOGUE[n] for n in names]
    bar = _Progress(1 + len(cands) + (max_effects - 1) * max(len(cands) - 1, 0), progress)
    sensor = {n: noise_level(getattr(s, n)) for n in SIGNALS if getattr(s, n) is not None}
    sensor_raw = {n: noise_level(np.asarray(getattr(data, n), dtype=float)) for n in sensor}

    vals, c, _ = fit_model([], train, [{"K": K0} for K0 in (0.2, 0.6, 1.2)])
    base = _Fit([], vals, c, s, k, data, t_split)
    bar("base model")
    # the floor a perfect model reaches: sensor noise plus the load-cell noise carried through it
    sigma_in = s.sigma_T_in
    gain_in = {"T_out": 1.0, "x_out": base.compliance}   # d(signal)/d(T_in), order of magnitude
    noise = {n: math.hypot(v, sigma_in * gain_in[n]) for n, v in sensor.items()}
    floor = {f"rmse_{n}_{_UNITS[n]}": math.hypot(v, sigma_in * gain_in[n]) for n, v in sensor_raw.items()}
    singles: dict[str, _Fit] = {}
    for e in cands:
        vals, c, _ = fit_model([e], train, start_points([e], base.values, s, {}))
        singles[e.id] = _Fit([e], vals, c, s, k, data, t_split, base, floor)
        bar(e.id)

    # forward selection with a price per parameter, relative to the model so far
    chosen = base
    pool = dict(singles)
    while len(chosen.effects) < max_effects and pool:
        if chosen is not base and max(_structure(chosen, s, k, noise).values()) <= STRUCTURE_RATIO:
            break                       # nothing left above the noise for another effect to explain
        if chosen is base:
            trial = pool
        else:
            trial = {}
            for eid in pool:
                fx = chosen.effects + [CATALOGUE[eid]]
                vals, c, _ = fit_model(fx, train, start_points(fx, chosen.values, s, chosen.values))
                trial[eid] = _Fit(fx, vals, c, s, k, data, t_split, base, floor)
                bar(f"{'+'.join(chosen.ids)}+{eid}")
        price = {eid: f.S / chosen.S + PENALTY * (f.n_params - chosen.n_params) for eid, f in trial.items()}
        best = min(price, key=price.get)
        if price[best] >= 1.0:
            break
        chosen = trial[best]
        pool.pop(best)
    bar.finish()

    base_raw, ext_raw = base.raw, chosen.raw
    left = _structure(chosen, s, k, noise)
    causes = chosen.ids + ([UNKNOWN] if max(left.values()) > STRUCTURE_RATIO else [])
    cause = causes[0] if causes else NONE
    measured = [n for n in SIGNALS if getattr(data, n) is not None]

    def primary(fx: list[Effect]) -> str:
        want = fx[0].primary if fx else "T_out"
        return want if want in measured else measured[0]

    candidates = {}
    for eid, f in singles.items():
        raw = f.raw
        candidates[eid] = {**raw, "gain": _gain(raw, base_raw, primary(f.effects)),
                           "gain_T_out": _gain(raw, base_raw, "T_out"), "gain_x_out": _gain(raw, base_raw, "x_out"),
                           "score": f.S, "penalised_score": f.S + PENALTY * f.n_params,
                           "accepted": eid in chosen.ids, "parameters": _parameters(f)}
    prim = primary(chosen.effects)
    return {
        "cause": cause, "causes": causes, "base": base_raw, "extended": ext_raw,
        "gain": _gain(ext_raw, base_raw, prim) or 0.0 if chosen.effects else 0.0, "primary_signal": prim,
        "parameters": _parameters(chosen), "candidates": candidates,
        "split": {"time_s": t_split, "n_train": int(np.sum(data.time < t_split)),
                  "n_heldout": int(np.sum(data.time >= t_split)),
                  "train_fraction": float((t_split - data.time[0]) / max(data.duration, 1e-12))},
        "noise": {**{f"{n}_{_UNITS[n]}": v for n, v in sensor_raw.items()}, "T_in_N": sigma_in,
                  **{f"floor_{k[5:]}": v for k, v in floor.items()}},
        "structure": {"base": _structure(base, s, k, noise), "extended": left},
        "model": {"effects": chosen.ids, "values": chosen.values, "compliance": chosen.compliance},
        "base_model": {"effects": [], "values": base.values, "compliance": base.compliance},
        "settings": {"train_fraction": train_fraction, "n_nodes": n_nodes, "target_rate_hz": target_rate,
                     "penalty_per_parameter": PENALTY, "structure_ratio": STRUCTURE_RATIO,
                     "wrap_shape": None if wrap_shape is None else [float(v) for v in wrap_shape]},
        "elapsed_s": _time.perf_counter() - t_start,
    }


def predictions(result: dict, data: MeasuredData) -> dict[str, np.ndarray | None]:
    """Re-run the base and the extended model of a :func:`diagnose` result on the measured samples.

    Returns
    -------
    dict of ndarray, shape (n_samples,) (None for a signal not recorded): ``T_out_base``,
    ``T_out_ext`` [N], ``x_out_base``, ``x_out_ext`` [m] (interpolated from the averaged series to
    ``data.time``), ``velocity`` [m/s] and ``phase`` (int8 codes of :class:`estimator.phase.Phase`,
    from the base model).
    """
    from estimator.distal import estimate_batch      # local: phase classification only
    from estimator.sheath import SheathModel

    st = result["settings"]
    shape = None if st.get("wrap_shape") is None else np.asarray(st["wrap_shape"], dtype=float)
    s = prepare(data, n_nodes=st["n_nodes"], target_rate=st["target_rate_hz"], wrap_shape=shape)
    out: dict[str, np.ndarray | None] = {}
    for tag, model in (("base", result["base_model"]), ("ext", result["model"])):
        pr = predict(model["effects"], model["values"], s, compliance=model["compliance"])
        for name in SIGNALS:
            out[f"{name}_{tag}"] = None if getattr(data, name) is None else np.interp(data.time, s.time,
                                                                                     getattr(pr, name))
    out["velocity"] = np.interp(data.time, s.time, s.velocity)
    base = result["base_model"]
    out["phase"] = estimate_batch(np.interp(data.time, s.time, s.T_in), data.x_in,
                                  SheathModel(K=base["values"]["K"], compliance=max(base["compliance"], 1e-12),
                                              wrap_shape=shape), time=data.time, n_nodes=st["n_nodes"]).phase
    return out
