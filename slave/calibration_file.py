"""Calibration data of an instrument: ``<calibration.dir>/<instrument.id>.yaml`` (``calibration.dir`` null:
the per-user data directory, ``$XDG_DATA_HOME/tsm-teleop/calibration``), written by
``teleop calibrate`` (or the slave's power-up routine when the file is missing, or on
``teleop slave --recalibrate``) and reloaded by the slave: one life cycle for every instrument.

Format (YAML, SI units; unknown keys are errors). A joint instrument (``instrument.joints``)::

    instrument: flex3                    # must be the config's instrument.id
    date: 2026-01-01T12:00:00+00:00      # ISO 8601, when the fit was made
    method: joint-limit knee each way (Phee et al. 2009, Sec. IV); K from M_e by Newton (eq. 13)
    target_tension: 20.0                 # [N] where each pull stopped
    use_route: true                      # K solved with each tendon's route shape
    joints:                              # in instrument.joints order, names must match
      - name: bend_ud
        a: {K: 0.62, M_e: 8.1e-05, compliance: 0.0001, knee_x_in: 0.0061, knee_T_in: 4.1,
            residual_rms: 3.0e-07, n_samples: 1500}
        b: {...}

A single-tendon instrument (one axis of one tendon) has ``tendon:`` instead of ``joints:``::

    instrument: tendon0
    date: 2026-01-01T12:00:00+00:00
    method: joint-limit knee (Phee et al. 2009, Sec. IV); K from M_e by Newton (eq. 13)
    target_tension: 20.0
    use_route: true
    tendon: {K: 0.62, M_e: 8.1e-05, compliance: 0.0001, knee_x_in: 0.0061, knee_T_in: 4.1,
             residual_rms: 3.0e-07, n_samples: 1500, tension_noise: 0.02}

K [-] >= 0, M_e [m/N] > 0, compliance = L/EA [m/N] > 0, knee_x_in [m], knee_T_in [N], residual_rms [m]
(of the post-knee line x_in = M_e T_in + c) >= 0, n_samples >= 1 (samples after the knee), and optionally
tension_noise [N] >= 0 (the noise sigma of the pull's T_in, for the estimator's noise band; a file
without it reads as 0: no band).
"""
from __future__ import annotations

import datetime as _dt
import math
import os
from dataclasses import dataclass
from pathlib import Path

import yaml

from estimator.errors import CalibrationError
from estimator.offline.calibration import CalibrationResult
from estimator.sheath import SheathModel
from slave.calibrate import route_wrap_shape
from slave.pair_calibrate import tendon_wrap_shape
from slave.rig import TENDONS
from teleop.config.kinds import instrument_kind
from teleop.config.reader import read_yaml
from teleop.config.schema import Config
from teleop.errors import ConfigError

__all__ = ["TendonCalibration", "InstrumentCalibration", "calibration_path", "user_calibration_dir", "APP_DATA",
           "from_results", "from_tendon_result",
           "save_calibration", "load_calibration", "sheath_models", "tendon_model"]

METHOD = "joint-limit knee each way (Phee et al. 2009, Sec. IV); K from M_e by Newton (eq. 13)"
METHOD_TENDON = "joint-limit knee (Phee et al. 2009, Sec. IV); K from M_e by Newton (eq. 13)"
_TENDON_KEYS = {"K": float, "M_e": float, "compliance": float, "knee_x_in": float, "knee_T_in": float,
                "residual_rms": float, "n_samples": int}
_OPTIONAL_KEYS = {"tension_noise": float}        # missing: 0.0
_NON_NEGATIVE = ("K", "residual_rms", "tension_noise")
_TOP_KEYS = ("instrument", "date", "method", "target_tension", "use_route")       # + joints or tendon


@dataclass(frozen=True)
class TendonCalibration:
    """Fitted values of one tendon (units in the module docstring)."""

    K: float
    M_e: float
    compliance: float
    knee_x_in: float
    knee_T_in: float
    residual_rms: float
    n_samples: int
    tension_noise: float = 0.0

    @classmethod
    def from_result(cls, r: CalibrationResult) -> TendonCalibration:
        return cls(K=r.K, M_e=r.M_e, compliance=r.model.compliance, knee_x_in=r.knee_x_in, knee_T_in=r.knee_T_in,
                   residual_rms=r.residual_rms, n_samples=r.n_samples, tension_noise=r.tension_noise)


@dataclass(frozen=True)
class InstrumentCalibration:
    """A whole instrument: ``joints`` is a tuple of (name, {"a": TendonCalibration, "b": ...}) for a
    joint instrument; ``tendon`` the one tendon of a single-tendon instrument (``joints`` empty)."""

    instrument: str
    date: str
    target_tension: float
    use_route: bool
    joints: tuple[tuple[str, dict[str, TendonCalibration]], ...] = ()
    method: str = METHOD
    tendon: TendonCalibration | None = None

    def as_dict(self) -> dict:
        out = {"instrument": self.instrument, "date": self.date, "method": self.method,
               "target_tension": self.target_tension, "use_route": self.use_route}
        if self.tendon is not None:
            out["tendon"] = {k: getattr(self.tendon, k) for k in (*_TENDON_KEYS, *_OPTIONAL_KEYS)}
        else:
            out["joints"] = [{"name": n, **{t: {k: getattr(c[t], k) for k in (*_TENDON_KEYS, *_OPTIONAL_KEYS)}
                                             for t in TENDONS}}
                             for n, c in self.joints]
        return out


#: Directory of this application's data under the per-user data directory (XDG base directory spec)
APP_DATA = "tsm-teleop"


def user_calibration_dir() -> Path:
    """The per-user calibration directory: ``$XDG_DATA_HOME/tsm-teleop/calibration``, else
    ``~/.local/share/tsm-teleop/calibration`` (an empty or relative ``XDG_DATA_HOME`` is ignored, as the
    XDG base directory specification says)."""
    base = os.environ.get("XDG_DATA_HOME", "")
    root = Path(base) if base and Path(base).is_absolute() else Path.home() / ".local" / "share"
    return root / APP_DATA / "calibration"


def calibration_path(cfg: Config) -> Path:
    """``<calibration.dir>/<instrument.id>.yaml``; without ``calibration.dir`` (null, the default) the
    file lives in :func:`user_calibration_dir`, never in the current directory."""
    folder = Path(cfg.calibration.dir) if cfg.calibration.dir else user_calibration_dir()
    return folder / f"{cfg.instrument.id}.yaml"


def from_results(cfg: Config, results: list[dict[str, CalibrationResult]],
                 date: str | None = None) -> InstrumentCalibration:
    """The calibration data of a finished :class:`~slave.pair_calibrate.PairCalibration` (date: now, UTC)."""
    date = date or _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")
    joints = tuple((j.name, {t: TendonCalibration.from_result(res[t]) for t in TENDONS})
                   for j, res in zip(cfg.instrument.joints, results, strict=False))
    return InstrumentCalibration(instrument=cfg.instrument.id, date=date, target_tension=cfg.calibration.target_tension,
                                 use_route=cfg.calibration.use_route, joints=joints)


def from_tendon_result(cfg: Config, result: CalibrationResult, date: str | None = None) -> InstrumentCalibration:
    """The calibration data of a single tendon's finished :class:`~slave.calibrate.JointLimitCalibration`
    (date: now, UTC)."""
    date = date or _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")
    return InstrumentCalibration(instrument=cfg.instrument.id, date=date, target_tension=cfg.calibration.target_tension,
                                 use_route=cfg.calibration.use_route, method=METHOD_TENDON,
                                 tendon=TendonCalibration.from_result(result))


def save_calibration(cal: InstrumentCalibration, path: str | Path) -> Path:
    """Write ``cal`` as YAML to ``path`` (directories created); returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    kind = "a single-tendon" if cal.tendon is not None else "a joint"
    head = (f"# tendon-sheath calibration of {kind} instrument (teleop calibrate); SI units:\n"
            "# K [-], M_e and compliance = L/EA [m/N], knee_x_in [m], knee_T_in [N], residual_rms [m]\n")
    path.write_text(head + yaml.safe_dump(cal.as_dict(), sort_keys=False), encoding="utf-8")
    return path


def _fail(path: Path, msg: str) -> CalibrationError:
    return CalibrationError(f"{path}: {msg}")


def load_calibration(path: str | Path, cfg: Config) -> InstrumentCalibration:
    """Read and check a calibration file against the config.

    Raises
    ------
    CalibrationError
        Missing or unreadable file, YAML error, unknown or missing key, a value of the wrong type or
        out of range, another instrument id, joints that are not the config's (names in order), a
        single tendon's file for a joint instrument or the other way round. The message starts with
        the file name and names the key.
    """
    path = Path(path)
    if not path.exists():
        raise _fail(path, "calibration file not found (run `teleop calibrate --config ...`)")
    try:
        data = read_yaml(path)[0]           # bounded: size, nesting, aliases (teleop/config/reader.py)
    except ConfigError as e:
        raise CalibrationError(str(e)) from None
    kind = "tendon" if instrument_kind(cfg) == "tendon" else "joints"
    keys = _TOP_KEYS + (kind,)
    if not isinstance(data, dict):
        raise _fail(path, "expected a mapping with keys " + ", ".join(keys))
    other = "tendon" if kind == "joints" else "joints"
    if other in data:
        raise _fail(path, f"{other}: this is the calibration of a {'single-tendon' if other == 'tendon' else 'joint'} "
                          f"instrument, the config's is a {'joint' if kind == 'joints' else 'single-tendon'} "
                          "instrument")
    for k in data:
        if k not in keys:
            raise _fail(path, f"unknown key {k!r} (expected {', '.join(keys)})")
    for k in keys:
        if k not in data:
            raise _fail(path, f"missing key {k!r}")
    if data["instrument"] != cfg.instrument.id:
        raise _fail(path, f"instrument is {data['instrument']!r}, the config's instrument.id is {cfg.instrument.id!r}: "
                          f"this calibration is for another instrument")
    if not isinstance(data["date"], (str, _dt.datetime, _dt.date)):
        raise _fail(path, f"date: expected an ISO 8601 date, got {data['date']!r}")
    date = data["date"] if isinstance(data["date"], str) else data["date"].isoformat()
    try:
        _dt.datetime.fromisoformat(date)
    except ValueError:
        raise _fail(path, f"date: {date!r} is not an ISO 8601 date") from None
    tt = data["target_tension"]
    if isinstance(tt, bool) or not isinstance(tt, (int, float)) or not (math.isfinite(tt) and tt > 0):
        raise _fail(path, f"target_tension: expected a tension > 0 N, got {tt!r}")
    if not isinstance(data["use_route"], bool):
        raise _fail(path, f"use_route: expected true or false, got {data['use_route']!r}")
    if kind == "tendon":
        return InstrumentCalibration(instrument=data["instrument"], date=date, target_tension=float(tt),
                                     use_route=data["use_route"], method=str(data["method"]),
                                     tendon=_tendon_values(path, "tendon", data["tendon"]))
    names = [j.name for j in cfg.instrument.joints]
    joints = data["joints"]
    if not isinstance(joints, list) or [j.get("name") if isinstance(j, dict) else None for j in joints] != names:
        got = [j.get("name") if isinstance(j, dict) else j for j in joints] if isinstance(joints, list) else joints
        raise _fail(path, f"joints: expected the config's joints {names} in that order, got {got}")
    out = []
    for i, j in enumerate(joints):
        extra = set(j) - {"name", *TENDONS}
        if extra:
            raise _fail(path, f"joints[{i}] ({j['name']}): unknown key {sorted(extra)[0]!r}")
        tend = {t: _tendon_values(path, f"joints[{i}].{t} ({j['name']})", j.get(t)) for t in TENDONS}
        out.append((j["name"], tend))
    return InstrumentCalibration(instrument=data["instrument"], date=date, target_tension=float(tt),
                                 use_route=data["use_route"], joints=tuple(out), method=str(data["method"]))


def _tendon_values(path: Path, where: str, v) -> TendonCalibration:
    """One tendon's fitted values, checked (module docstring: ranges); ``where`` names it in errors."""
    if not isinstance(v, dict):
        raise _fail(path, f"{where}: missing or not a mapping of fitted values")
    unknown = set(v) - set(_TENDON_KEYS) - set(_OPTIONAL_KEYS)
    if unknown:
        raise _fail(path, f"{where}: unknown key {sorted(unknown)[0]!r}")
    vals = {}
    for key, tp in {**_TENDON_KEYS, **{k: t for k, t in _OPTIONAL_KEYS.items() if k in v}}.items():
        x = v.get(key)
        if not _valid_value(key, x, tp):
            raise _fail(path, f"{where}.{key}: expected {'an integer >= 1' if tp is int else 'a finite number'}"
                              f"{' > 0' if key in ('M_e', 'compliance') else ' >= 0' if key in _NON_NEGATIVE else ''}"
                              f", got {x!r}")
        vals[key] = tp(x)
    return TendonCalibration(**vals)


def _valid_value(key: str, x: object, tp: type) -> bool:
    """Whether ``x`` is a finite number (an int when ``tp`` is int, never a bool) in ``key``'s range."""
    if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x):
        return False
    if tp is int and not isinstance(x, int):
        return False
    if key in ("M_e", "compliance"):
        return x > 0
    if key in _NON_NEGATIVE:
        return x >= 0
    if key == "n_samples":
        return x >= 1
    return True


def tendon_model(cal: InstrumentCalibration, cfg: Config) -> SheathModel:
    """The estimator's model of a single-tendon instrument: calibrated K and L/EA, and the route shape
    (``sheath``) when the calibration used it.

    Raises
    ------
    CalibrationError
        ``cal`` is a joint instrument's calibration.
    """
    if cal.tendon is None:
        raise CalibrationError(f"the calibration of {cal.instrument} is a joint instrument's: no single tendon")
    shape = route_wrap_shape(cfg) if cal.use_route else None
    return SheathModel(K=cal.tendon.K, compliance=cal.tendon.compliance, wrap_shape=shape)


def sheath_models(cal: InstrumentCalibration, cfg: Config) -> list[tuple[SheathModel, SheathModel]]:
    """Per joint, the estimator's models of tendons a and b: calibrated K and L/EA, and the route shape
    when the calibration used it."""
    out = []
    for (_name, tend), joint in zip(cal.joints, cfg.instrument.joints, strict=False):
        pair = []
        for t in TENDONS:
            shape = tendon_wrap_shape(getattr(joint.tendons, t)) if cal.use_route else None
            pair.append(SheathModel(K=tend[t].K, compliance=tend[t].compliance, wrap_shape=shape))
        out.append((pair[0], pair[1]))
    return out
