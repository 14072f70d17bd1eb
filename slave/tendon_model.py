"""A single-tendon model file in the slave: checked against the catalogue, built as the per-cycle estimator, and run
beside the base estimator that stands in where its estimate leaves the physical range.

* :func:`check_tendon` (called by :func:`slave.estimator_model.configured_model`): every extension has a per-cycle
  form (:data:`estimator.online.extended.PER_CYCLE`, with the reason of one that has none; pre-sliding in its
  per-node form drives the distal end by the measured x_out and is refused too), the base holds K and L/EA, each
  parameter lies within the catalogue's range, and the per-cycle estimator accepts the values;
* :func:`tendon_model_estimator`: the :class:`estimator.online.extended.ExtendedEstimator` of a model file (its
  node grid, route, parameters; the noise band from the live reading's noise; the readings averaged over the fitted
  sample interval, :func:`live_average`; friction that changed in the recording tracked online,
  :data:`estimator.online.extended.TRACKED`);
* :class:`ModelRunner`: one step of the model beside the base estimator's sample; where the model's estimate leaves
  the physical range (a negative distal tension, a distal tension above the proximal one by more than e^K:
  :meth:`estimator.online.extended.ExtendedEstimator.out_of_range`) the base estimator's sample stands in, counted
  and logged the first time.
"""
from __future__ import annotations

import logging
from typing import Any

import numpy as np

from estimator.offline.effects.catalogue import CATALOGUE
from estimator.offline.effects.types import ROUTE_KEYS, route_shape, route_values
from estimator.online.distal import DistalSample
from estimator.online.extended import PER_CYCLE, TRACKED, ExtendedEstimator
from estimator.sheath import SheathModel
from teleop.config.model_file import ModelFile, check_runnable
from teleop.errors import ConfigError

__all__ = ["tendon_forms", "check_tendon", "tendon_model_estimator", "live_average", "base_of", "ModelRunner"]

log = logging.getLogger("teleop.slave")

#: the held forms a model file writes as parameters: effect id -> (name, unit)
_FORMS = {"velocity_friction": "velocity_form", "stiction": "v_st", "presliding": "presliding_form"}
_BASE_PLAIN = ("n_nodes", "T_min", "rate_hz")


def tendon_forms() -> dict[str, str | None]:
    """Every single-tendon catalogue entry -> None when it has a per-cycle form, else why it has none."""
    return {e: None if has else why for e, (has, why) in PER_CYCLE.items()}


def base_of(model: ModelFile) -> tuple[np.ndarray, np.ndarray, int]:
    """The node grid of a model file: (u, w, n_nodes): the nodes' normalised wrap angle (the route shares r_k of its
    base, uniform without them) and trapezoid weights, shape (n_nodes + 1,)."""
    n = int(model.base.get("n_nodes", 32))
    u, w = SheathModel(K=1.0, compliance=1.0).nodes(n)
    r = route_values(model.base)
    if r:
        u = route_shape(n + 1, *r)
    return u, w, n


def _values(model: ModelFile) -> dict[str, float]:
    v = {"K": model.base["K"]}
    for e in model.extensions:
        v.update(e.values())
    v.pop("presliding_form", None)
    return v


def check_tendon(model: ModelFile, tension_noise: float = 0.0) -> None:
    """Refuse a single-tendon model file the live estimator cannot run (module docstring).

    Raises
    ------
    ConfigError
        One line naming the file and the key.
    """
    check_runnable(model, tendon_forms())
    for k in ("K", "compliance"):
        if k not in model.base:
            raise ConfigError(f"{model.path}: base: missing parameter {k!r} of the profile_memory structure")
    extra = sorted(set(model.base) - {"K", "compliance", *ROUTE_KEYS, *_BASE_PLAIN})
    if extra:
        raise ConfigError(f"{model.path}: base: {extra[0]!r} is no parameter of the profile_memory structure")
    n = model.base.get("n_nodes", 32)
    if not (n == int(n) and 1 <= n <= 1000):
        raise ConfigError(f"{model.path}: base.n_nodes: {n:g} is no node count in [1, 1000]")
    for i, e in enumerate(model.extensions):
        names = {p.name: p for p in CATALOGUE[e.id].parameters}
        form = _FORMS.get(e.id)
        for q in e.parameters:
            p = names.get(q.name)
            if p is None and q.name != form:
                raise ConfigError(f"{model.path}: extensions[{i}].parameters.{q.name}: no parameter of {e.id} (its "
                                  f"parameters: {', '.join([*names, *([form] if form else [])])})")
            if p is not None and not min(p.lower, p.neutral) <= q.value <= p.upper:
                raise ConfigError(f"{model.path}: extensions[{i}].parameters.{q.name}: {q.value:g} {p.unit} is "
                                  f"outside the catalogue's range [{min(p.lower, p.neutral):g}, {p.upper:g}]")
        if e.id == "presliding" and e.values().get("presliding_form", 0.0) > 0.5:
            raise ConfigError(f"{model.path}: extensions[{i}].parameters.presliding_form: the per-node form has no "
                              f"per-cycle form: {PER_CYCLE['presliding'][1].split('; ')[1]}")
    tendon_model_estimator(model, tension_noise)


def live_average(model: ModelFile, rate_hz: float) -> int:
    """The readings the per-cycle estimator averages per step at the live rate ``rate_hz`` [Hz]: the model's fitted
    sample interval (``base.rate_hz``, its block means) in live samples, at least 1."""
    fit = model.base.get("rate_hz")
    return 1 if not fit or not rate_hz > 0 else max(1, int(round(rate_hz / fit)))


def tendon_model_estimator(model: ModelFile, tension_noise: float = 0.0, rate_time_constant: float = 0.02,
                           rate_hz: float = 0.0, track_friction: bool | None = None) -> ExtendedEstimator:
    """The per-cycle estimator of a single-tendon model file, at rest; ``tension_noise`` [N] the live T_in reading's
    noise sigma (the noise band), ``rate_time_constant`` [s] the velocity's smoothing when it averages nothing,
    ``rate_hz`` [Hz] the live rate (:func:`live_average`; 0: no averaging), ``track_friction`` the friction tracked
    online (None: where the model names a friction that changes, :data:`estimator.online.extended.TRACKED`; False:
    the fitted change replayed, the batch model's form).
    Raises ConfigError (``<file>: <why>``) when it refuses the model's values."""
    u, w, _ = base_of(model)
    try:
        return ExtendedEstimator(_values(model), u, w, model.base["compliance"], tension_noise=tension_noise,
                                 T_min=model.base.get("T_min"), rate_time_constant=rate_time_constant,
                                 average=live_average(model, rate_hz),
                                 track_friction=any(e.id in TRACKED for e in model.extensions)
                                 if track_friction is None else track_friction)
    except ValueError as e:
        raise ConfigError(f"{model.path}: the per-cycle estimator refuses this model: {e}") from None


class ModelRunner:
    """A model file's estimator stepped beside the base estimator (module docstring).

    ``model``: the file; ``estimator``: its :class:`ExtendedEstimator`; ``name``: the axis's name for the log.
    ``cycles`` counts the steps, ``fallbacks`` those where the base estimator's sample stood in.
    """

    def __init__(self, model: ModelFile, estimator: ExtendedEstimator, name: str = "tendon"):
        self.model, self.estimator, self.name = model, estimator, name
        self.cycles = self.fallbacks = 0
        tracked = ", its friction tracked online from the proximal loop's width" if estimator.track_friction else ""
        log.info("%s: estimator model %s (sha256 %s...) from %s, driven by the measured proximal tension and "
                 "position%s; held-out %.4g %s where it was fitted (base %.4g)", name, model.model_id,
                 model.sha256[:12], model.path, tracked, model.gain["extended"], model.gain["unit"], model.gain["base"])

    def step(self, T_in: float, x_in: float, t: float, base: DistalSample) -> DistalSample:
        """The model's estimate of this cycle as a :class:`DistalSample` (the base sample's phase), or ``base`` where
        the model's leaves the physical range or cannot read the sample."""
        self.cycles += 1
        try:
            s = self.estimator.step(T_in, x_in, t)
            why = self.estimator.out_of_range(s)
        except ValueError as e:
            why = str(e)
        if why is None:
            return DistalSample(s.T_out, s.elongation, s.x_out, base.phase)
        self.fallbacks += 1
        if self.fallbacks == 1:
            log.warning("%s: the model's estimate leaves the physical range at t = %.3f s (%s): the base estimator's "
                        "stands in for every such cycle (counted as model.fallbacks in slave_stats.json)",
                        self.name, t, why)
        return base

    def stats(self) -> dict[str, Any]:
        """The model's entry of the slave's stats: id, sha256, path, cycles run, fallbacks, the held-out gain and,
        where the friction is tracked, its last value K [-] and the branch estimates it came from."""
        m, est = self.model, self.estimator
        out = {"id": m.model_id, "sha256": m.sha256, "path": m.path, "cycles": self.cycles,
               "fallbacks": self.fallbacks, "gain": dict(m.gain),
               "fallback_share": self.fallbacks / self.cycles if self.cycles else 0.0}
        if est.tracker is not None:
            out["friction"] = {"tracked": True, "K": est.friction, "K_fitted": est.values["K"],
                               "estimates": est.tracker.estimates, "bias": est.tracker.bias}
        return out
