"""The model file the slave's estimator runs (``estimator.model``, ``--model``): read and checked against the
configured instrument before any process starts, and built as the per-cycle estimator of its axis kind.

:func:`configured_model` is the one check (``teleop slave`` and ``teleop demo`` run it on their config before
anything starts; the slave's axis runs it again when it builds its estimator): the file reads strictly
(:func:`teleop.config.model_file.load_model`: format, version, keys, finite values, the extensions' parameters within
their ranges), it is for the configured axis kind and instrument id (:func:`teleop.config.model_file.check_instrument`),
every extension has a per-cycle form (:func:`teleop.config.model_file.check_runnable`, with the reason of one that has
none), the base parameters lie within the catalogue's ranges, the per-cycle estimator accepts the values, and the
configured rig's axis runs a model file. Any of these fails as one :class:`~teleop.errors.ConfigError` line naming the
file and the key.

Which axes run a model file, per axis kind:

* ``pair``: the recording rig's pair axis (:class:`slave.recording.pair.RecordedPairAxis`) runs
  :class:`estimator.online.pair_model.PairModelEstimator` (structure ``capstan`` or ``seed`` with the pair effects of
  :data:`estimator.online.pair_model.PER_CYCLE`);
* ``spindle``: the recording rig's spindle axis (:class:`slave.recording.spindle.RecordedSpindleAxis`) runs the
  spindle pair model and, when the file chose it, the centre map (:mod:`study.mrd.model_file` writes them);
* ``tendon``: the single-tendon axis (:class:`slave.tendon_axis.TendonAxis`, on any rig) runs
  :class:`estimator.online.extended.ExtendedEstimator` beside the base estimator (:mod:`slave.tendon_model`: the
  checks, the fallback where the extended estimate leaves the physical range).
"""
from __future__ import annotations

from pathlib import Path

from teleop.config.kinds import instrument_kind
from teleop.config.model_file import ModelFile, check_instrument, check_runnable, load_model
from teleop.config.schema import Config
from teleop.errors import ConfigError

__all__ = ["SPINDLE_FORMS", "pair_forms", "configured_model", "pair_model_estimator", "with_model"]

#: The spindle model's extensions: id -> None (it has a per-cycle form) or why it has none.
SPINDLE_FORMS: dict[str, str | None] = {"centre_map": None}


def pair_forms() -> dict[str, str | None]:
    """Every pair effect -> None when it has a per-cycle form, else why it has none
    (:data:`estimator.online.pair_model.PER_CYCLE`)."""
    from estimator.online.pair_model import PER_CYCLE
    return {e: None if has else why for e, (has, why) in PER_CYCLE.items()}


def pair_model_estimator(model: ModelFile, pretension: tuple[float, float]):
    """The per-cycle estimator of a pair model file (:class:`estimator.online.pair_model.PairModelEstimator`, at rest
    at ``pretension`` [N]). Raises ConfigError (``<file>: <why>``) when it refuses the model's values."""
    from estimator.online.pair_model import PairModelEstimator
    try:
        return PairModelEstimator(model.structure, tuple(e.id for e in model.extensions), model.values(), pretension)
    except ValueError as e:
        raise ConfigError(f"{model.path}: the per-cycle estimator refuses this model: {e}") from None


def _check_pair(model: ModelFile, cfg: Config) -> None:
    from estimator.offline.pair.models import PAIR_EFFECTS, STRUCTURES
    check_runnable(model, pair_forms())
    for p in STRUCTURES[model.structure]:      # the catalogue's ranges, whatever ranges the file wrote
        v = model.base.get(p.name)
        if v is None:
            raise ConfigError(f"{model.path}: base: missing parameter {p.name!r} of the {model.structure} structure "
                              f"(expected {', '.join(q.name for q in STRUCTURES[model.structure])})")
        if not p.lo <= v <= p.hi:
            raise ConfigError(f"{model.path}: base.{p.name}: {v:g} {p.unit} is outside the catalogue's range "
                              f"[{p.lo:g}, {p.hi:g}]")
    for i, e in enumerate(model.extensions):
        for p in PAIR_EFFECTS[e.id].parameters:
            v = e.values().get(p.name)
            if v is None or not p.lo <= v <= p.hi:
                raise ConfigError(f"{model.path}: extensions[{i}].parameters.{p.name}: " + (
                    f"missing (the {e.id} parameters: {', '.join(q.name for q in PAIR_EFFECTS[e.id].parameters)})"
                    if v is None else f"{v:g} {p.unit} is outside the catalogue's range [{p.lo:g}, {p.hi:g}]"))
    extra = sorted(set(model.base) - {p.name for p in STRUCTURES[model.structure]})
    if extra:
        raise ConfigError(f"{model.path}: base: {extra[0]!r} is no parameter of the {model.structure} structure")
    pre = float(cfg.instrument.joints[0].pretension)
    pair_model_estimator(model, (pre, pre))
    if cfg.rig.type != "recording":
        raise ConfigError(f"{model.path}: the pair axis runs a model file on the recording rig (rig.type recording, "
                          f"a KAIST recording); rig.type is {cfg.rig.type}")


def _check_spindle(model: ModelFile, cfg: Config) -> None:
    from estimator.online.spindle import SpindleParams
    check_runnable(model, SPINDLE_FORMS)
    names = set(SpindleParams().as_dict()) | {"theta_ref", "band_centre"}
    missing = sorted(names - set(model.base))
    extra = sorted(set(model.base) - names)
    if missing or extra:
        raise ConfigError(f"{model.path}: base: " + (f"missing parameter {missing[0]!r}" if missing else
                                                     f"{extra[0]!r} is no parameter of the spindle model"))
    if cfg.rig.type != "recording":
        raise ConfigError(f"{model.path}: the spindle axis runs a model file on the recording rig (rig.type "
                          f"recording, an MRD run); rig.type is {cfg.rig.type}")


def configured_model(cfg: Config) -> ModelFile | None:
    """The model file of ``estimator.model``, read and checked (module docstring); None when none is set.

    Raises
    ------
    ConfigError
        One line naming the file and the key: unreadable or malformed, another version, another axis kind or
        instrument, an extension without a per-cycle form (with the reason), a parameter outside its range or
        refused by the per-cycle estimator, a rig whose axis runs no model file.
    """
    if cfg.estimator.model is None:
        return None
    path = Path(cfg.estimator.model).expanduser()
    if not path.is_file():
        raise ConfigError(f"estimator.model: {cfg.estimator.model}: no such file")
    model = load_model(path)
    kind = instrument_kind(cfg)
    check_instrument(model, kind, cfg.instrument.id)
    if kind == "pair":
        _check_pair(model, cfg)
    elif kind == "spindle":
        _check_spindle(model, cfg)
    elif kind == "tendon":
        from slave.tendon_model import check_tendon
        check_tendon(model)
    else:
        raise ConfigError(f"{model.path}: axis: the {kind} axis runs no model file yet")
    return model


def with_model(cfg: Config, path: str | None) -> Config:
    """``cfg`` with ``estimator.model`` set to ``path`` (``--model``; None: ``cfg`` unchanged), and the model path,
    given or configured, made absolute (``~`` expanded): the side processes read it from the run's config."""
    import dataclasses
    chosen = path if path is not None else cfg.estimator.model
    if chosen is None:
        return cfg
    full = str(Path(chosen).expanduser().resolve())
    return dataclasses.replace(cfg, estimator=dataclasses.replace(cfg.estimator, model=full))
