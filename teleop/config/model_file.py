"""Model files: the model a diagnosis chose for one axis of one instrument, as the live estimator runs it.

``teleop analyze ... --model-out OUT.yaml`` writes one; ``estimator.model: PATH`` (or ``--model PATH``) makes
the slave run it (docs/reference/formats.md, "Model file"). A file holds:

* ``format`` (:data:`FORMAT`) and ``version`` (:data:`VERSION`; another version is refused, never guessed);
* ``axis``: the axis kind the model is for (:data:`AXIS_KINDS`), and ``instrument``: the instrument's id;
* ``structure``: the base model it extends (``profile_memory`` for one tendon, ``capstan`` or ``seed`` for an
  antagonistic pair, ``spindle`` for a spindle-driven pair) with its ``base`` calibration: each parameter an SI
  value, or (value, unit, range) as an extension's parameter, its value then checked within its range;
* ``extensions``: the catalogue entries it adds, each with its fitted ``parameters`` (value, unit and the
  range the catalogue allows, ``null`` for a coefficient the catalogue leaves unbounded);
* ``per_cycle``: the per-cycle form the live estimator runs it as;
* ``gain``: the held-out errors of the base and the extended model where it was fitted, and their unit;
* ``provenance``: the recording's file name and SHA-256, the span fitted on [s], the project's version and the
  date the file was written.

Reading is strict: an unknown or missing key, a value of the wrong type, a non-finite number or a parameter
outside its range ends in one :class:`~teleop.errors.ConfigError` line naming the file and the dotted key.
Whether the live estimator can run each extension is the consumer's question
(:func:`check_runnable`); whether the model fits the configured instrument is :func:`check_instrument`.
"""
from __future__ import annotations

import hashlib
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from teleop.config.reader import read_yaml
from teleop.errors import ConfigError

__all__ = ["FORMAT", "VERSION", "AXIS_KINDS", "STRUCTURES", "ModelParameter", "ModelExtension", "ModelFile",
           "load_model", "save_model", "check_runnable", "check_instrument", "file_sha256", "project_version"]

FORMAT = "tsm-teleop model"
VERSION = 1
#: axis kind -> the base structures a model of that kind extends
STRUCTURES: dict[str, tuple[str, ...]] = {
    "tendon": ("profile_memory",),
    "pair": ("capstan", "seed"),
    "spindle": ("spindle",),
}
AXIS_KINDS = tuple(STRUCTURES)
_TOP = ("format", "version", "axis", "instrument", "structure", "base", "extensions", "per_cycle", "gain",
        "provenance")
_PARAM = ("value", "unit", "range")
_GAIN = ("base", "extended", "unit")
_PROVENANCE = ("recording", "sha256", "span_s", "project_version", "written")


@dataclass(frozen=True)
class ModelParameter:
    """One fitted parameter: its value in ``unit`` (SI), within the catalogue's closed range [lo, hi] (-inf, inf when
    the catalogue leaves it unbounded)."""
    name: str
    value: float
    unit: str
    lo: float
    hi: float


@dataclass(frozen=True)
class ModelExtension:
    """One catalogue entry of the model (its id as the catalogue spells it) with its fitted parameters."""
    id: str
    parameters: tuple[ModelParameter, ...]

    def values(self) -> dict[str, float]:
        """Parameter name -> value [SI]."""
        return {p.name: p.value for p in self.parameters}


@dataclass(frozen=True)
class ModelFile:
    """A model file as read (:func:`load_model`) or to be written (:func:`save_model`).

    ``base`` maps the base model's parameter names to SI values, ``base_ranges`` those written with their unit and
    range to (unit, low, high); ``gain`` holds ``base`` and ``extended``
    (held-out errors, in ``unit``); ``provenance`` the recording, its ``sha256``, ``span_s`` [s, s], the
    ``project_version`` and the ``written`` date. ``sha256`` is the file's own digest (empty before it is
    written); :attr:`model_id` names the model in logs, stats and summaries.
    """
    axis: str
    instrument: str
    structure: str
    base: dict[str, float]
    extensions: tuple[ModelExtension, ...]
    per_cycle: str
    gain: dict[str, Any]
    provenance: dict[str, Any]
    sha256: str = ""
    path: str = ""
    base_ranges: dict[str, tuple[str, float, float]] = field(default_factory=dict)

    @property
    def model_id(self) -> str:
        """``<instrument>/<axis>/<structure>+<extension>+...`` (the catalogue ids in file order)."""
        return f"{self.instrument}/{self.axis}/" + "+".join((self.structure, *(e.id for e in self.extensions)))

    def values(self) -> dict[str, float]:
        """Every parameter of the model, base and extensions, name -> SI value."""
        out = dict(self.base)
        for e in self.extensions:
            out.update(e.values())
        return out


def project_version() -> str:
    """The installed version of the ``tsm-teleop`` distribution, as provenance writes it ("unknown" when it is
    not installed)."""
    import importlib.metadata
    try:
        return importlib.metadata.version("tsm-teleop")
    except importlib.metadata.PackageNotFoundError:
        return "unknown"


def file_sha256(path: str | Path) -> str:
    """Hex SHA-256 of a file's bytes (read in 1 MiB blocks)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _where(path: Path, lines: dict[str, int], key: str) -> str:
    line = lines.get(key)
    return f"{path}:{line}: {key}" if line else f"{path}: {key}"


def _mapping(data: Any, keys: tuple[str, ...], path: Path, lines: dict[str, int], at: str,
             required: tuple[str, ...] | None = None) -> dict[str, Any]:
    where = _where(path, lines, at) if at else str(path)
    if not isinstance(data, dict):
        raise ConfigError(f"{where}: expected a mapping, got {type(data).__name__}")
    unknown = sorted(set(data) - set(keys))
    if unknown:
        raise ConfigError(f"{where}: unknown key {unknown[0]!r} (expected {', '.join(keys)})")
    missing = [k for k in (keys if required is None else required) if k not in data]
    if missing:
        raise ConfigError(f"{where}: missing key {missing[0]!r}")
    return data


def _number(v: Any, path: Path, lines: dict[str, int], key: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(float(v)):
        raise ConfigError(f"{_where(path, lines, key)}: expected a finite number, got {v!r}")
    return float(v)


def _text(v: Any, path: Path, lines: dict[str, int], key: str) -> str:
    if not isinstance(v, str) or not v.strip():
        raise ConfigError(f"{_where(path, lines, key)}: expected a non-empty string, got {v!r}")
    return v


def _parameter(name: str, v: Any, path: Path, lines: dict[str, int], key: str) -> ModelParameter:
    d = _mapping(v, _PARAM, path, lines, key)
    value = _number(d["value"], path, lines, f"{key}.value")
    unit = d["unit"]
    if not isinstance(unit, str):
        raise ConfigError(f"{_where(path, lines, key + '.unit')}: expected a unit string, got {unit!r}")
    rng = d["range"]
    if rng is None:                 # no range in the catalogue (an unbounded least-squares coefficient)
        return ModelParameter(name, value, unit, -math.inf, math.inf)
    if not (isinstance(rng, list) and len(rng) == 2):
        raise ConfigError(f"{_where(path, lines, key + '.range')}: expected [low, high] or null, got {rng!r}")
    lo, hi = (_number(x, path, lines, f"{key}.range") for x in rng)
    if not lo <= value <= hi:
        raise ConfigError(f"{_where(path, lines, key + '.value')}: {value:g} {unit} is outside its range "
                          f"[{lo:g}, {hi:g}]")
    return ModelParameter(name, value, unit, lo, hi)


def _extensions(v: Any, path: Path, lines: dict[str, int]) -> tuple[ModelExtension, ...]:
    if not isinstance(v, list):
        raise ConfigError(f"{_where(path, lines, 'extensions')}: expected a list, got {type(v).__name__}")
    out, seen = [], set()
    for i, e in enumerate(v):
        key = f"extensions[{i}]"
        d = _mapping(e, ("id", "parameters"), path, lines, key)
        eid = _text(d["id"], path, lines, f"{key}.id")
        if eid in seen:
            raise ConfigError(f"{_where(path, lines, key + '.id')}: {eid!r} appears twice")
        seen.add(eid)
        params = _mapping(d["parameters"], tuple(d["parameters"] or ()) if isinstance(d["parameters"], dict)
                          else (), path, lines, f"{key}.parameters")
        out.append(ModelExtension(eid, tuple(_parameter(str(n), p, path, lines, f"{key}.parameters.{n}")
                                             for n, p in params.items())))
    return tuple(out)


def load_model(path: str | Path) -> ModelFile:
    """Read and check a model file.

    Raises
    ------
    ConfigError
        One line naming the file and the dotted key: not a model file, another version, an unknown axis kind
        or structure, an unknown or missing key, a non-finite number, a parameter outside its range.
    """
    p = Path(path)
    data, lines = read_yaml(p)
    d = _mapping(data, _TOP, p, lines, "")
    if d["format"] != FORMAT:
        raise ConfigError(f"{_where(p, lines, 'format')}: not a model file (format {d['format']!r}, "
                          f"expected {FORMAT!r})")
    if d["version"] != VERSION or isinstance(d["version"], bool):
        raise ConfigError(f"{_where(p, lines, 'version')}: model file version {d['version']!r} is unknown to this "
                          f"program (it reads version {VERSION}); write the model again with this version's "
                          "`teleop analyze --model-out`")
    axis = d["axis"]
    if axis not in STRUCTURES:
        raise ConfigError(f"{_where(p, lines, 'axis')}: unknown axis kind {axis!r} (expected one of "
                          f"{', '.join(AXIS_KINDS)})")
    structure = d["structure"]
    if structure not in STRUCTURES[axis]:
        raise ConfigError(f"{_where(p, lines, 'structure')}: {structure!r} is no base model of a {axis} axis "
                          f"(expected one of {', '.join(STRUCTURES[axis])})")
    base = _mapping(d["base"], tuple(d["base"]) if isinstance(d["base"], dict) else (), p, lines, "base")
    ranged = {str(k): _parameter(str(k), v, p, lines, f"base.{k}") for k, v in base.items() if isinstance(v, dict)}
    gain = _mapping(d["gain"], _GAIN, p, lines, "gain")
    prov = _mapping(d["provenance"], _PROVENANCE, p, lines, "provenance")
    return ModelFile(axis=axis, instrument=_text(d["instrument"], p, lines, "instrument"), structure=structure,
                     base={str(k): ranged[str(k)].value if str(k) in ranged else _number(v, p, lines, f"base.{k}")
                           for k, v in base.items()},
                     base_ranges={k: (q.unit, q.lo, q.hi) for k, q in ranged.items()},
                     extensions=_extensions(d["extensions"], p, lines),
                     per_cycle=_text(d["per_cycle"], p, lines, "per_cycle"),
                     gain={"base": _number(gain["base"], p, lines, "gain.base"),
                           "extended": _number(gain["extended"], p, lines, "gain.extended"),
                           "unit": _text(gain["unit"], p, lines, "gain.unit")},
                     provenance=dict(prov), sha256=file_sha256(p), path=str(p))


def _base_entry(model: ModelFile, name: str, value: float) -> Any:
    """A base parameter as written: the SI value, or {value, unit, range} when ``base_ranges`` has it."""
    if name not in model.base_ranges:
        return float(value)
    unit, lo, hi = model.base_ranges[name]
    return {"value": float(value), "unit": unit, "range": _range(lo, hi)}


def _range(lo: float, hi: float) -> list[float] | None:
    """A parameter's range as written: [low, high], or None (null) for a parameter the catalogue leaves unbounded."""
    return None if math.isinf(lo) and math.isinf(hi) else [float(lo), float(hi)]


def _plain(model: ModelFile) -> dict[str, Any]:
    return {
        "format": FORMAT, "version": VERSION, "axis": model.axis, "instrument": model.instrument,
        "structure": model.structure, "base": {k: _base_entry(model, k, v) for k, v in model.base.items()},
        "extensions": [{"id": e.id, "parameters": {
            q.name: {"value": float(q.value), "unit": q.unit, "range": _range(q.lo, q.hi)}
            for q in e.parameters}} for e in model.extensions],
        "per_cycle": model.per_cycle,
        "gain": {"base": float(model.gain["base"]), "extended": float(model.gain["extended"]),
                 "unit": str(model.gain["unit"])},
        "provenance": {k: model.provenance.get(k) for k in _PROVENANCE},
    }


def save_model(model: ModelFile, path: str | Path) -> Path:
    """Write ``model`` as a model file (created with its parent folders; an existing file is replaced
    atomically) and return the path. The file is read back with :func:`load_model` before this returns, so a
    model this program cannot read again is never left behind.

    Raises
    ------
    ConfigError
        The model does not pass :func:`load_model`'s checks (the file is then removed).
    """
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    tmp = p.with_name(p.name + ".writing")
    text = f"# {FORMAT} (docs/reference/formats.md, \"Model file\")\n" + yaml.safe_dump(
        _plain(model), sort_keys=False, default_flow_style=None, width=110)
    tmp.write_text(text, encoding="utf-8")
    try:
        load_model(tmp)
    except ConfigError:
        tmp.unlink(missing_ok=True)
        raise
    tmp.replace(p)
    return p


def check_runnable(model: ModelFile, forms: Mapping[str, str | None]) -> None:
    """Refuse a model the live estimator cannot run: ``forms`` maps each catalogue id of the axis kind to None
    (it has a per-cycle form) or the reason it has none.

    Raises
    ------
    ConfigError
        ``<file>: extensions[i].id: <id> ...`` naming the first extension with no per-cycle form, or unknown.
    """
    for i, e in enumerate(model.extensions):
        if e.id not in forms:
            raise ConfigError(f"{model.path}: extensions[{i}].id: {e.id!r} is no {model.axis} catalogue entry "
                              f"(known: {', '.join(sorted(forms))})")
        reason = forms[e.id]
        if reason is not None:
            raise ConfigError(f"{model.path}: extensions[{i}].id: {e.id!r} has no per-cycle form: {reason}")


def check_instrument(model: ModelFile, axis_kind: str, instrument_id: str) -> None:
    """Refuse a model made for another axis kind or another instrument.

    Raises
    ------
    ConfigError
        ``<file>: axis: ...`` or ``<file>: instrument: ...``, naming both sides.
    """
    if model.axis != axis_kind:
        raise ConfigError(f"{model.path}: axis: the model is for a {model.axis} axis, the configured instrument "
                          f"is a {axis_kind} instrument")
    if model.instrument != instrument_id:
        raise ConfigError(f"{model.path}: instrument: the model is for {model.instrument!r}, the configured "
                          f"instrument is {instrument_id!r} (instrument.id)")
