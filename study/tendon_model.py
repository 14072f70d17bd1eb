"""``teleop analyze FILE.csv --model-out OUT.yaml``: the single-tendon model the diagnosis chose, as a model file the
live estimator runs (:mod:`teleop.config.model_file`, docs/reference/formats.md, "Model file").

The file holds: axis ``tendon``, the instrument id (``--instrument ID``, else the default config's
``instrument.id``), structure ``profile_memory`` with its ``base`` calibration as the diagnosis refitted it on the
training block (K [-] and L/EA [m/N] with their ranges, the route shares r_k [-] when the route was fitted, the
node grid ``n_nodes``, the breakaway threshold ``T_min`` [N] and the sample rate ``rate_hz`` [Hz] of the block means
it was fitted on), the chosen extensions with
their fitted parameters, units and the catalogue's ranges (a held form as a parameter of its own:
``velocity_form`` 0/1, the Stribeck speed ``v_st`` [m/s] of stiction (0: the breakaway form), ``presliding_form``
0/1), the per-cycle form (:class:`estimator.online.extended.ExtendedEstimator`), the held-out gain (distal-tension
RMSE on the test block [N] of the base and the extended model; the distal position's [m] when the recording has no
T_out) and the provenance (the recording's file name and SHA-256, the training block's span [s], the project's
version). Nothing is refitted here. An entry whose data cannot be told from a proximal one (the catalogue's
EQUIVALENT: a T_out gain, an x_out offset) is written as that proximal entry with the value that gives the same
outputs; the live loop has no distal sensor to apply the distal one to.
"""
from __future__ import annotations

import datetime as _dt
from pathlib import Path

from estimator.data import MeasuredData
from estimator.offline.diagnosis.result import Diagnosis
from estimator.offline.effects.catalogue import CATALOGUE, SPEED_FORM, STRIBECK_FORM, STRIBECK_SPEED
from estimator.offline.effects.presliding_kernel import NODE_FORM
from estimator.offline.effects.types import K_MAX, ROUTE_KEYS
from estimator.online.extended import PER_CYCLE
from teleop.config.model_file import (
    ModelExtension,
    ModelFile,
    ModelParameter,
    file_sha256,
    project_version,
    save_model,
)
from teleop.errors import ConfigError

__all__ = ["COMPLIANCE_MAX", "tendon_model", "write_tendon_model", "check_model_out", "write_model_out", "held_forms"]

#: upper end of the L/EA range a model file allows [m/N] (a 1 N pull stretching the tendon by 10 cm)
COMPLIANCE_MAX = 0.1

#: the held forms written as parameters: (effect id, the catalogue's values key, the file's name, unit, range)
_FORMS = (("velocity_friction", SPEED_FORM, "velocity_form", "-", (0.0, 1.0)),
          ("stiction", STRIBECK_FORM, "v_st", "m/s", (0.0, 1.0)),
          ("presliding", NODE_FORM, "presliding_form", "-", (0.0, 1.0)))


def held_forms() -> dict[str, tuple[str, str, tuple[float, float]]]:
    """Effect id -> (the held form's parameter name in a model file, its unit, its range)."""
    return {e: (name, unit, rng) for e, _, name, unit, rng in _FORMS}


def _proximal(eid: str, values: dict[str, float]) -> tuple[str, dict[str, float]]:
    """An entry and its values, a distal one with a proximal equivalent written as that one (same outputs)."""
    if eid == "sensor_gain:T_out":         # T_out read (1 + g) T: the same as T_in read / (1 + g)
        return "sensor_gain:T_in", {"g_T_in": 1.0 / (1.0 + values["g_T_out"]) - 1.0}
    if eid == "sensor_offset:x_out":       # only x_in - x_out enters
        return "sensor_offset:x_in", {"b_x_in": -values["b_x_out"]}
    return eid, values


def _extension(eid: str, values: dict[str, float]) -> ModelExtension:
    e = CATALOGUE[eid]
    own = {p.name: float(values.get(p.name, p.neutral)) for p in e.parameters}
    eid, own = _proximal(eid, own)
    e = CATALOGUE[eid]
    params = [ModelParameter(p.name, own[p.name], p.unit, min(p.lower, p.neutral), p.upper) for p in e.parameters]
    for fid, key, name, unit, (lo, hi) in _FORMS:
        if fid == eid:
            on = float(values.get(key, 0.0)) > 0.5
            value = (STRIBECK_SPEED if on else 0.0) if name == "v_st" else float(on)
            params.append(ModelParameter(name, value, unit, lo, hi))
    return ModelExtension(eid, tuple(params))


def tendon_model(result: Diagnosis, recording: str | Path, instrument: str, T_min: float,
                 rate_hz: float) -> ModelFile:
    """The model file of a diagnosis (module docstring), not yet written.

    Parameters
    ----------
    result : the diagnosis of ``recording`` (:func:`study.analyze.diagnose_file`)
    recording : the CSV it diagnosed (its name and SHA-256 go in the provenance)
    instrument : the instrument id
    T_min : the breakaway threshold [N] of the prepared recording (``Series.T_min``)
    rate_hz : the sample rate [Hz] of the prepared recording the model was fitted on (its block means)
    """
    m = result.model
    v = m.values
    base: dict[str, float] = {"K": float(v["K"]), "compliance": float(m.compliance)}
    ranges = {"K": ("-", 0.0, K_MAX), "compliance": ("m/N", 0.0, COMPLIANCE_MAX)}
    for k in ROUTE_KEYS:
        if k in v:
            base[k] = float(v[k])
            ranges[k] = ("-", 0.0, 1.0)
    base["n_nodes"] = float(result.settings.get("n_nodes", 32))
    base["T_min"] = float(T_min)
    base["rate_hz"] = float(rate_hz)
    exts = tuple(_extension(eid, v) for eid in m.effects)
    how = "; ".join(f"{e.id}: {PER_CYCLE[e.id][1]}" for e in exts) or "the base model"
    signal, unit = ("rmse_T_out_N", "N") if result.base.get("rmse_T_out_N") is not None else ("rmse_x_out_m", "m")
    train = result.split["train"]["time_s"]
    return ModelFile(
        axis="tendon", instrument=instrument, structure="profile_memory", base=base, extensions=exts,
        per_cycle=f"estimator.online.extended.ExtendedEstimator ({'+'.join(m.effects) or 'base'}), driven by the "
                  f"measured proximal tension and position: {how}",
        base_ranges=ranges,
        gain={"base": float(result.base[signal] or 0.0), "extended": float(result.extended[signal] or 0.0),
              "unit": unit},
        provenance={"recording": Path(recording).name, "sha256": file_sha256(recording),
                    "span_s": [float(train[0]), float(train[1])], "project_version": project_version(),
                    "written": _dt.datetime.now(_dt.UTC).date().isoformat()})


def write_tendon_model(result: Diagnosis, recording: str | Path, instrument: str, T_min: float, rate_hz: float,
                       out: str | Path) -> Path:
    """Write the model file of a diagnosis to ``out`` (:func:`tendon_model`); returns the path.

    Raises
    ------
    ConfigError
        A model that would not read back (:func:`teleop.config.model_file.save_model`).
    """
    return save_model(tendon_model(result, recording, instrument, T_min, rate_hz), out)


def check_model_out(out: str | Path, instrument: str | None, route: str | None) -> str:
    """The arguments of ``--model-out`` for a CSV checked before the diagnosis runs; returns the instrument id
    (``instrument``, or the default config's).

    Raises
    ------
    ConfigError
        ``out`` is a directory or its folder does not exist, ``instrument`` is no valid id, or ``route`` is set (a
        held route's shape is not written in a model file).
    """
    from teleop.config.schema import Config
    from teleop.wire.keys import validate_instrument_id
    if Path(out).is_dir() or not Path(out).resolve().parent.is_dir():
        raise ConfigError(f"--model-out {out}: the single-tendon model is one file (OUT.yaml) in an existing folder")
    if route is not None:
        raise ConfigError(f"--model-out {out}: with --route the model runs on the held route's shape, which a model "
                          "file does not hold; diagnose without --route to write one")
    return validate_instrument_id(instrument if instrument is not None else Config().instrument.id,
                                  where="--instrument")


def write_model_out(result: Diagnosis, data: MeasuredData, recording: str | Path, out: str | Path,
                    instrument: str | None, route: str | None) -> Path:
    """``teleop analyze FILE.csv --model-out OUT.yaml [--instrument ID]``: the model file of the diagnosis
    ``result`` of ``data`` (read from ``recording``) written to ``out``; the instrument id ``instrument`` or the
    default config's. Returns the path.

    Raises
    ------
    ConfigError
        ``out`` is a directory, ``instrument`` is no valid id, ``route`` is set (a held route's shape is not
        written in a model file), or a model that would not read back.
    """
    from estimator.offline.diagnosis.fit import prepare
    name = check_model_out(out, instrument, route)
    st = result.settings
    s = prepare(data, n_nodes=int(st.get("n_nodes", 32)), target_rate=float(st.get("target_rate_hz", 200.0)))
    rate = (len(s) - 1) / max(float(s.time[-1] - s.time[0]), 1e-12)
    return write_tendon_model(result, recording, name, s.T_min, rate, out)
