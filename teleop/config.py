"""Configuration schema (dataclasses) and strict YAML loading.

The schema mirrors configs/default.yaml key for key. Loading merges a file over the defaults and
rejects unknown keys, wrong types and out-of-range values with a :class:`ConfigError` that names the
file and the dotted key.
"""
from __future__ import annotations

import dataclasses
import difflib
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, Optional, Union, get_args, get_origin, get_type_hints

import yaml

from estimator.sheath import Run, SheathGeometry
from teleop.errors import ConfigError

__all__ = [
    "InstrumentConfig", "RunConfig", "SheathConfig", "MotorConfig", "LoadConfig", "SensorConfig",
    "RigConfig", "EffectsConfig", "VelocityFrictionConfig", "PretensionEffectConfig",
    "CurvatureDriftConfig", "TendonStiffeningConfig", "StictionConfig", "FrictionOffsetConfig", "SensorOffsetConfig",
    "SensorDelayConfig", "EstimatorConfig", "CalibrationConfig", "DeviceConfig", "MappingConfig",
    "MasterConfig", "SlaveConfig", "TransportConfig", "TransportAuthConfig", "TransportTlsConfig", "RecordingConfig", "Config",
    "load_config", "config_from_dict", "config_to_dict", "write_config", "RANGES",
]


@dataclass(frozen=True)
class InstrumentConfig:
    id: str = "tsm0"
    # empty: the single-tendon rig of `sheath` and `rig.load`; 1..4 entries: antagonistic-pair joints
    joints: tuple[JointConfig, ...] = ()


@dataclass(frozen=True)
class RunConfig:
    length: float                 # [m] > 0
    radius: float = math.inf      # [m] > 0, inf = straight


@dataclass(frozen=True)
class SheathConfig:
    mu: float = 0.1               # [-] >= 0
    EA: float = 15000.0           # [N] > 0
    runs: tuple[RunConfig, ...] = (
        RunConfig(0.30), RunConfig(0.60, 0.191), RunConfig(0.30), RunConfig(0.30, 0.0955),
    )
    pretension: float = 0.0       # [N] >= 0

    def geometry(self) -> SheathGeometry:
        return SheathGeometry([Run(r.length, r.radius) for r in self.runs])


# ---- instruments of 1..4 joints, each driven by an antagonistic tendon pair (slave/joint_rig.py) --

@dataclass(frozen=True)
class TendonConfig:
    """One tendon-sheath transmission of a joint (its own route, friction and stiffness)."""

    mu: float = 0.1               # [-] >= 0
    EA: float = 15000.0           # [N] > 0
    runs: tuple[RunConfig, ...] = SheathConfig.runs

    def geometry(self) -> SheathGeometry:
        return SheathGeometry([Run(r.length, r.radius) for r in self.runs])


@dataclass(frozen=True)
class TendonPairConfig:
    a: TendonConfig = field(default_factory=TendonConfig)   # pulling a turns the joint to + angles
    b: TendonConfig = field(default_factory=TendonConfig)   # pulling b turns it to - angles


@dataclass(frozen=True)
class JointLoadConfig:
    tissue: bool = True
    tissue_stiffness: float = 0.02        # [N m/rad] torsional tissue spring beyond the contact angle
    tissue_contact: float = 0.2           # [rad] >= 0: in contact where |theta| > tissue_contact
    torque: float = 0.0                   # [N m] constant external torque (gravity, a held load)


@dataclass(frozen=True)
class JointConfig:
    name: str                             # [A-Za-z0-9_-]+, unique in the instrument
    pulley_radius: float = 0.004          # [m] distal pulley: x_out,a = +r theta, x_out,b = -r theta
    limits: tuple[float, ...] = (-1.2, 1.2)  # [rad] lower < 0 < upper (0: the rest pose)
    stiffness: float = 0.005              # [N m/rad] joint return spring
    damping: float = 0.0002               # [N m s/rad]
    limit_stiffness: float = 50.0         # [N m/rad] stiffness of the joint limits
    pretension: float = 0.0               # [N] tension of the pair at rest; 0: none (antagonist slack-free)
    load: JointLoadConfig = field(default_factory=JointLoadConfig)
    tendons: TendonPairConfig = field(default_factory=TendonPairConfig)


@dataclass(frozen=True)
class MotorConfig:
    bandwidth_hz: float = 40.0
    max_speed: float = 0.05               # [m/s]
    pulley_radius: float = 0.005          # [m]
    encoder_lines_per_rev: int = 67000


@dataclass(frozen=True)
class LoadConfig:
    joint_stiffness: float = 100.0        # [N/m]
    joint_limit: float = 0.020            # [m]
    limit_stiffness: float = 2.0e6        # [N/m]
    tissue_stiffness: float = 2000.0      # [N/m]
    tissue_contact: float = 0.0           # [m]
    tissue: bool = True
    force: float = 0.0                    # [N]


@dataclass(frozen=True)
class SensorConfig:
    load_cell_noise: float = 0.02         # [N]
    seed: int = 0


# ---- model effects of the simulated rig (estimator/effects.py has the matching extensions) -------
# Each effect is off by default; the magnitude fields are in SI units (the range table has them).

@dataclass(frozen=True)
class VelocityFrictionConfig:
    enabled: bool = False
    viscous: float = 15.0                 # [s/m] mu(v) = mu (1 + viscous |v|), v sliding speed


@dataclass(frozen=True)
class PretensionEffectConfig:
    enabled: bool = False
    tension: float = 3.0                  # [N] uniform tension at rest, added to sheath.pretension


@dataclass(frozen=True)
class CurvatureDriftConfig:
    enabled: bool = False
    rate: float = 0.002                   # [1/s] dK/dt: K(t) = K + rate t (route/mu drift)


@dataclass(frozen=True)
class TendonStiffeningConfig:
    enabled: bool = False
    softening: float = 2.0                # [-] extra compliance at zero tension: (1 + softening e^-T/T_c)/EA
    toe_tension: float = 2.0              # [N] T_c, tension where the toe stiffens


@dataclass(frozen=True)
class StictionConfig:
    enabled: bool = False
    static_ratio: float = 0.3             # [-] mu_static / mu_kinetic - 1
    slip_time: float = 0.02               # [s] after breakaway mu relaxes from static to kinetic (time constant)


@dataclass(frozen=True)
class FrictionOffsetConfig:
    enabled: bool = False
    tension_offset: float = 1.0           # [N] a = q / mu in dT/dtheta = -mu (T + a)


@dataclass(frozen=True)
class SensorOffsetConfig:
    enabled: bool = False
    offset: float = 0.5                   # [N] zero offset added to the proximal load-cell reading


@dataclass(frozen=True)
class SensorDelayConfig:
    enabled: bool = False
    delay: float = 0.02                   # [s] the proximal load-cell reading lags the truth


@dataclass(frozen=True)
class EffectsConfig:
    velocity_friction: VelocityFrictionConfig = field(default_factory=VelocityFrictionConfig)
    pretension: PretensionEffectConfig = field(default_factory=PretensionEffectConfig)
    curvature_drift: CurvatureDriftConfig = field(default_factory=CurvatureDriftConfig)
    tendon_stiffening: TendonStiffeningConfig = field(default_factory=TendonStiffeningConfig)
    stiction: StictionConfig = field(default_factory=StictionConfig)
    friction_offset: FrictionOffsetConfig = field(default_factory=FrictionOffsetConfig)
    sensor_offset: SensorOffsetConfig = field(default_factory=SensorOffsetConfig)
    sensor_delay: SensorDelayConfig = field(default_factory=SensorDelayConfig)


@dataclass(frozen=True)
class ZenohRigConfig:
    """The ``zenoh`` rig: set-points out, samples in on ``teleop/<instrument>/rig/{setpoint,sample}``."""

    timeout_ms: float = 50.0              # samples older than this are counted as stale [ms]
    wait_s: float = 10.0                  # at start, wait this long for the first sample [s]


@dataclass(frozen=True)
class RigConfig:
    type: Literal["simulated", "zenoh"] = "simulated"
    n_elements: int = 200
    rate_hz: float = 1000.0
    motor: MotorConfig = field(default_factory=MotorConfig)
    load: LoadConfig = field(default_factory=LoadConfig)
    sensors: SensorConfig = field(default_factory=SensorConfig)
    effects: EffectsConfig = field(default_factory=EffectsConfig)
    zenoh: ZenohRigConfig = field(default_factory=ZenohRigConfig)


@dataclass(frozen=True)
class EstimatorConfig:
    n_nodes: int = 100
    hold_rate: float = 0.5                # [N/s]
    rate_time_constant: float = 0.02      # [s]
    profile_points: int = 50


@dataclass(frozen=True)
class CalibrationConfig:
    target_tension: float = 20.0          # [N]
    speed: float = 0.004                  # [m/s]
    use_route: bool = True
    dir: str = "configs/calibration"      # joint instruments: <dir>/<instrument.id>.yaml


@dataclass(frozen=True)
class DeviceConfig:
    type: Literal["simulated", "hid"] = "simulated"
    file: Optional[str] = None            # device file (configs/devices/*.yaml), required when type is hid


@dataclass(frozen=True)
class MappingConfig:
    motion_scale: float = 0.2
    force_scale: float = 0.2
    force_limit: float = 4.0              # [N]
    ramp_time: float = 0.5                # [s]
    force_rate_limit: float = 100.0       # [N/s]
    passivity: bool = True                # time-domain passivity controller on the force channel
    align_tolerance: float = 0.001        # [m] of tendon: re-engage only when this close to the slave
    clutch_button: int = 1                # bit of DeviceState.buttons held to clutch; -1: no clutch


@dataclass(frozen=True)
class MasterConfig:
    rate_hz: float = 1000.0
    device: DeviceConfig = field(default_factory=DeviceConfig)
    mapping: MappingConfig = field(default_factory=MappingConfig)
    watchdog_ms: float = 50.0
    max_tension: float = 200.0            # [N] estimates with |T_in| or |T_out_hat| above: rejected


@dataclass(frozen=True)
class SlaveConfig:
    watchdog_ms: float = 50.0
    heartbeat_hz: float = 50.0
    relax_speed: float = 0.005            # [m/s] SAFE: release toward sheath.pretension at this speed
    x_in_min: float = -0.005              # [m] commands outside [x_in_min, x_in_max]: rejected
    x_in_max: float = 0.03                # [m]
    engage_tolerance: float = 0.002       # [m] (re-)engage only on a command this close to x_in


@dataclass(frozen=True)
class PairControlConfig:
    """Slave-side control of each antagonistic pair (slave/pair_control.py)."""

    min_tension: float = 0.5              # [N] antagonist's set tension when the joint has no pretension
    tension_gain: float = 0.01            # [m/(N s)] integral gain of the antagonist's tension loop
    switch_band: float = 0.01             # [rad] |command| below: both tendons hold their set tension
    feedforward: bool = True              # antagonist pays out the pulling side's commanded travel
    axes: tuple[int, ...] = ()            # master: device axis of each joint; empty: joint i on axis i


@dataclass(frozen=True)
class TransportAuthConfig:
    """Zenoh user/password authentication of every link (teleop/link_security.py); null: none."""

    user: Optional[str] = None            # this process's user name
    password: Optional[str] = None        # its password (prefer password_file outside tests)
    password_file: Optional[str] = None   # file holding the password (first line)
    dictionary_file: Optional[str] = None  # listener: accepted "user:password" lines


@dataclass(frozen=True)
class TransportTlsConfig:
    """TLS of ``tls/...`` endpoints: PEM files; null: no TLS settings."""

    root_ca: Optional[str] = None         # CA certificate that signs the peers' certificates
    certificate: Optional[str] = None     # this process's certificate (listener; mutual: connector too)
    private_key: Optional[str] = None     # its private key
    mutual: bool = False                  # connectors must present a certificate too


@dataclass(frozen=True)
class TransportConfig:
    mode: Literal["peer", "client"] = "peer"
    listen: tuple[str, ...] = ("tcp/127.0.0.1:7447",)
    connect: tuple[str, ...] = ()
    multicast_scouting: bool = False
    auto_connect: bool = True             # bare start: listen, or connect when the port is taken (teleop/discovery.py)
    run_id_timeout: float = 3.0           # [s] a connecting side asks its peers for the run id this long
    lock_master: bool = True              # slave: commands and master heartbeats from one master session only
    auth: TransportAuthConfig = field(default_factory=TransportAuthConfig)
    tls: TransportTlsConfig = field(default_factory=TransportTlsConfig)


@dataclass(frozen=True)
class RecordingConfig:
    dir: str = "runs"
    rerun: Literal["save", "spawn", "off"] = "save"
    log_every: int = 10
    profile_every: int = 5
    flush_interval: float = 0.02          # [s] recorder files handed to the OS at least this often


@dataclass(frozen=True)
class Config:
    instrument: InstrumentConfig = field(default_factory=InstrumentConfig)
    sheath: SheathConfig = field(default_factory=SheathConfig)
    rig: RigConfig = field(default_factory=RigConfig)
    estimator: EstimatorConfig = field(default_factory=EstimatorConfig)
    calibration: CalibrationConfig = field(default_factory=CalibrationConfig)
    master: MasterConfig = field(default_factory=MasterConfig)
    slave: SlaveConfig = field(default_factory=SlaveConfig)
    transport: TransportConfig = field(default_factory=TransportConfig)
    recording: RecordingConfig = field(default_factory=RecordingConfig)
    pair_control: PairControlConfig = field(default_factory=PairControlConfig)


# ---- loading: strict YAML -> Config ------------------------------------------------------------

# Valid range and unit of every numeric setting ("[]" stands for any list index). A test checks that
# each numeric field of the schema has an entry and each entry names a field.
RANGES: dict[str, tuple[str, str]] = {
    "sheath.mu": (">= 0", "-"), "sheath.EA": ("> 0", "N"), "sheath.pretension": (">= 0", "N"),
    "sheath.runs[].length": ("> 0", "m"), "sheath.runs[].radius": ("> 0", "m, .inf = straight"),
    "rig.n_elements": (">= 1", "-"), "rig.rate_hz": ("> 0", "Hz"),
    "rig.motor.bandwidth_hz": ("> 0", "Hz"), "rig.motor.max_speed": ("> 0", "m/s"),
    "rig.motor.pulley_radius": ("> 0", "m"), "rig.motor.encoder_lines_per_rev": (">= 1", "-"),
    "rig.load.joint_stiffness": (">= 0", "N/m"), "rig.load.joint_limit": ("> 0", "m"),
    "rig.load.limit_stiffness": ("> 0", "N/m"), "rig.load.tissue_stiffness": (">= 0", "N/m"),
    "rig.load.tissue_contact": ("any", "m"), "rig.load.force": (">= 0", "N"),
    "rig.sensors.load_cell_noise": (">= 0", "N"), "rig.sensors.seed": (">= 0", "-"),
    "rig.zenoh.timeout_ms": ("> 0", "ms"), "rig.zenoh.wait_s": ("> 0", "s"),
    "rig.effects.velocity_friction.viscous": (">= 0", "s/m"), "rig.effects.pretension.tension": (">= 0", "N"),
    "rig.effects.curvature_drift.rate": ("any", "1/s"), "rig.effects.tendon_stiffening.softening": (">= 0", "-"),
    "rig.effects.tendon_stiffening.toe_tension": ("> 0", "N"), "rig.effects.stiction.static_ratio": (">= 0", "-"),
    "rig.effects.stiction.slip_time": ("> 0", "s"), "rig.effects.friction_offset.tension_offset": (">= 0", "N"),
    "rig.effects.sensor_offset.offset": ("any", "N"), "rig.effects.sensor_delay.delay": (">= 0", "s"),
    "estimator.n_nodes": (">= 2", "-"), "estimator.hold_rate": (">= 0", "N/s"),
    "estimator.rate_time_constant": ("> 0", "s"), "estimator.profile_points": ("0..65535", "-"),
    "calibration.target_tension": ("> 0", "N"), "calibration.speed": ("> 0", "m/s"),
    "master.rate_hz": ("> 0", "Hz"), "master.watchdog_ms": ("> 0", "ms"),
    "master.mapping.motion_scale": ("> 0", "-"), "master.mapping.force_scale": (">= 0", "-"),
    "master.mapping.force_limit": (">= 0", "N"), "master.mapping.ramp_time": (">= 0", "s"),
    "master.mapping.force_rate_limit": ("> 0", "N/s"), "master.mapping.align_tolerance": ("> 0", "m"),
    "master.mapping.clutch_button": ("-1..31", "bit"), "master.max_tension": ("> 0", "N"),
    "slave.relax_speed": (">= 0", "m/s"), "slave.x_in_min": ("any", "m"), "slave.x_in_max": ("any", "m"),
    "slave.engage_tolerance": ("> 0", "m"),
    "slave.watchdog_ms": ("> 0", "ms"), "slave.heartbeat_hz": ("> 0", "Hz"),
    "recording.log_every": (">= 1", "samples"),
    "instrument.joints[].pulley_radius": ("> 0", "m"), "instrument.joints[].limits[]": ("any", "rad"),
    "instrument.joints[].stiffness": (">= 0", "N m/rad"), "instrument.joints[].damping": (">= 0", "N m s/rad"),
    "instrument.joints[].limit_stiffness": ("> 0", "N m/rad"), "instrument.joints[].pretension": (">= 0", "N"),
    "instrument.joints[].load.tissue_stiffness": (">= 0", "N m/rad"),
    "instrument.joints[].load.tissue_contact": (">= 0", "rad"), "instrument.joints[].load.torque": ("any", "N m"),
    **{f"instrument.joints[].tendons.{t}.{k}": v for t in "ab" for k, v in (
        ("mu", (">= 0", "-")), ("EA", ("> 0", "N")), ("runs[].length", ("> 0", "m")),
        ("runs[].radius", ("> 0", "m, .inf = straight")))},
    "pair_control.min_tension": ("> 0", "N"), "pair_control.tension_gain": ("> 0", "m/(N s)"),
    "pair_control.switch_band": (">= 0", "rad"), "pair_control.axes[]": (">= 0", "-"),
    "recording.profile_every": (">= 1", "logs"),
    "recording.flush_interval": ("> 0", "s"), "transport.run_id_timeout": (">= 0", "s"),
}
_INF_OK = {"sheath.runs[].radius", "instrument.joints[].tendons.a.runs[].radius",
           "instrument.joints[].tendons.b.runs[].radius"}
_NON_SI = ("_mm", "_deg", "_ms", "_hz")


def _in_range(v: float, rule: str) -> bool:
    if rule == "any":
        return True
    if ".." in rule:
        lo, hi = (float(x) for x in rule.split(".."))
        return lo <= v <= hi
    op, bound = rule.split()
    return v > float(bound) if op == ">" else v >= float(bound)


class _Loader(yaml.SafeLoader):
    """YAML 1.2 core scalars: ``2.0e6`` and ``1e-3`` are floats, only true/false are booleans
    (``off``, ``no`` stay strings), integers are decimal (``010`` is ten)."""


_Loader.yaml_implicit_resolvers = {
    ch: [(tag, rx) for tag, rx in rs if tag not in ("tag:yaml.org,2002:bool", "tag:yaml.org,2002:float",
                                                   "tag:yaml.org,2002:int")]
    for ch, rs in yaml.SafeLoader.yaml_implicit_resolvers.items()}
_Loader.add_implicit_resolver("tag:yaml.org,2002:bool", re.compile(r"^(?:true|True|TRUE|false|False|FALSE)$"),
                              list("tTfF"))
_Loader.add_implicit_resolver("tag:yaml.org,2002:int", re.compile(r"^[-+]?[0-9]+$"), list("-+0123456789"))
_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^(?:[-+]?(?:\.[0-9]+|[0-9]+(?:\.[0-9]*)?)(?:[eE][-+]?[0-9]+)?"
               r"|[-+]?\.(?:inf|Inf|INF)|\.(?:nan|NaN|NAN))$"), list("-+0123456789."))
_Loader.add_constructor("tag:yaml.org,2002:int", lambda loader, node: int(loader.construct_scalar(node), 10))


class _Ctx:
    """Where values come from (a file, or "overrides") and the line of each dotted key in it."""

    def __init__(self, source: str, lines: dict[str, int] | None = None):
        self.source, self.lines = source, lines or {}

    def error(self, path: str, msg: str) -> ConfigError:
        line = self.lines.get(path)
        return ConfigError(f"{self.source}:{line}: {msg}" if line else f"{self.source}: {msg}")


def _show(v: Any) -> str:
    kind = {dict: "a mapping", list: "a list", type(None): "nothing (null)"}.get(type(v))
    return kind or f"{v!r} ({type(v).__name__})"


def _schema_keys(cls: type, prefix: str = "") -> list[str]:
    out = []
    for name, tp in get_type_hints(cls).items():
        p = f"{prefix}.{name}" if prefix else name
        out.append(p)
        if dataclasses.is_dataclass(tp):
            out += _schema_keys(tp, p)
        elif get_origin(tp) is tuple and dataclasses.is_dataclass(get_args(tp)[0]):
            out += _schema_keys(get_args(tp)[0], p + "[]")
    return out


def _unknown(ctx: _Ctx, path: str, name: str, siblings: list[str]) -> ConfigError:
    for suf in _NON_SI:
        if name.endswith(suf) and name[: -len(suf)] in siblings:
            return ctx.error(path, f"unknown key '{path}': non-SI '{suf}' keys are accepted only where the "
                                   f"schema names them; give '{name[: -len(suf)]}' in SI units")
    prefix = path[: len(path) - len(name)]
    near = difflib.get_close_matches(path, [prefix + s for s in siblings] + _schema_keys(Config), 1, 0.6)
    hint = f" (did you mean '{near[0]}'?)" if near else f" (expected one of: {', '.join(siblings)})"
    return ctx.error(path, f"unknown key '{path}'{hint}")


def _convert(v: Any, tp: Any, path: str, ctx: _Ctx) -> Any:
    """Check ``v`` against the schema type ``tp`` and return it as that type."""
    rule_key = re.sub(r"\[\d+\]", "[]", path)
    if dataclasses.is_dataclass(tp):
        return _merge(tp, None, v, path, ctx)
    origin = get_origin(tp)
    if origin is Union and type(None) in get_args(tp):      # Optional[X]: null or an X
        if v is None:
            return None
        tp = next(a for a in get_args(tp) if a is not type(None))
        origin = get_origin(tp)
    if origin is Literal:
        if v not in get_args(tp) or isinstance(v, bool):
            choices = ", ".join(repr(c) for c in get_args(tp))
            raise ctx.error(path, f"{path}: expected one of {choices}, got {_show(v)}")
        return v
    if origin is tuple:
        if not isinstance(v, (list, tuple)):
            raise ctx.error(path, f"{path}: expected a list, got {_show(v)}")
        return tuple(_convert(x, get_args(tp)[0], f"{path}[{i}]", ctx) for i, x in enumerate(v))
    if tp is bool:
        if not isinstance(v, bool):
            raise ctx.error(path, f"{path}: expected true or false, got {_show(v)}")
        return v
    if tp is str:
        if not isinstance(v, str) or not v:
            raise ctx.error(path, f"{path}: expected a non-empty string, got {_show(v)}")
        return v
    if tp is int:
        if isinstance(v, bool) or not isinstance(v, int):
            raise ctx.error(path, f"{path}: expected an integer, got {_show(v)}")
    elif tp is float:
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise ctx.error(path, f"{path}: expected a number, got {_show(v)}")
        v = float(v)
        if math.isnan(v) or (math.isinf(v) and rule_key not in _INF_OK):
            raise ctx.error(path, f"{path}: expected a finite number, got {v!r}")
    else:  # pragma: no cover - a schema type this loader does not know
        raise TypeError(f"config schema type {tp!r} of {path} is not supported")
    rule, unit = RANGES.get(rule_key, ("any", ""))
    if not _in_range(v, rule):
        raise ctx.error(path, f"{path}: {v!r} is out of range: expected {rule} [{unit}]")
    return v


def _merge(cls: type, base: Any, data: Any, path: str, ctx: _Ctx) -> Any:
    """A ``cls`` instance: ``base`` (None: the field defaults) with the keys of ``data`` replaced."""
    if data is None:                     # an empty section: nothing overridden
        data = {}
    if not isinstance(data, dict):
        raise ctx.error(path, f"{path or 'top level'}: expected a mapping of settings, got {_show(data)}")
    hints = get_type_hints(cls)
    changes = {}
    for name, v in data.items():
        p = f"{path}.{name}" if path else str(name)
        if name not in hints:
            raise _unknown(ctx, p, str(name), list(hints))
        tp = hints[name]
        if dataclasses.is_dataclass(tp):
            changes[name] = _merge(tp, None if base is None else getattr(base, name), v, p, ctx)
        else:
            changes[name] = _convert(v, tp, p, ctx)
    if base is not None:
        return dataclasses.replace(base, **changes)
    for f in dataclasses.fields(cls):
        if f.name not in changes and f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            raise ctx.error(path, f"{path}: missing key '{f.name}'")
    return cls(**changes)


def _check(cfg: Config, ctx: _Ctx) -> Config:
    """Checks beyond one value's type and range."""
    from teleop.keys import validate_instrument_id
    try:
        validate_instrument_id(cfg.instrument.id)
    except ConfigError as e:
        raise ctx.error("instrument.id", str(e)) from None
    for name in ("listen", "connect"):
        for i, ep in enumerate(getattr(cfg.transport, name)):
            if not re.fullmatch(r"[a-z0-9]+/\S+", ep):
                raise ctx.error(f"transport.{name}[{i}]", f"transport.{name}[{i}]: {ep!r} is not a zenoh "
                                                         f"endpoint (expected e.g. 'tcp/127.0.0.1:7447')")
    if not cfg.sheath.runs:
        raise ctx.error("sheath.runs", "sheath.runs: expected at least one run")
    if cfg.master.device.type == "hid" and not cfg.master.device.file:
        raise ctx.error("master.device.type", "master.device.file: a device file (configs/devices/*.yaml) "
                                              "is required when master.device.type is 'hid'")
    if not cfg.slave.x_in_min < cfg.slave.x_in_max:
        raise ctx.error("slave.x_in_max", f"slave.x_in_max ({cfg.slave.x_in_max!r} m) must be above "
                                          f"slave.x_in_min ({cfg.slave.x_in_min!r} m)")
    _check_joints(cfg, ctx)
    return cfg


MAX_JOINTS = 4
_JOINT_NAME = re.compile(r"[A-Za-z0-9_-]+")


def _check_joints(cfg: Config, ctx: _Ctx) -> None:
    """instrument.joints: 0 (single tendon) or 1..4 joints with unique names, limits [lower < 0 < upper],
    non-empty tendon routes; pair_control.axes empty or one distinct axis per joint."""
    joints = cfg.instrument.joints
    if len(joints) > MAX_JOINTS:
        raise ctx.error("instrument.joints", f"instrument.joints: {len(joints)} joints, an instrument has "
                                             f"1 to {MAX_JOINTS}")
    seen: dict[str, int] = {}
    for i, j in enumerate(joints):
        where = f"instrument.joints[{i}]"
        if not _JOINT_NAME.fullmatch(j.name):
            raise ctx.error(f"{where}.name", f"{where}.name: {j.name!r} is not a joint name (letters, digits, "
                                             f"'_' or '-' only)")
        if j.name in seen:
            raise ctx.error(f"{where}.name", f"{where}.name: {j.name!r} is already the name of "
                                             f"instrument.joints[{seen[j.name]}]")
        seen[j.name] = i
        lim = j.limits
        if len(lim) != 2 or not (lim[0] < 0.0 < lim[1]):
            raise ctx.error(f"{where}.limits", f"{where}.limits ({j.name}): expected [lower, upper] [rad] with "
                                               f"lower < 0 < upper (0 is the rest pose), got {list(lim)}")
        for t in ("a", "b"):
            if not getattr(j.tendons, t).runs:
                raise ctx.error(f"{where}.tendons.{t}.runs", f"{where}.tendons.{t}.runs ({j.name}): expected "
                                                             f"at least one run")
    axes = cfg.pair_control.axes
    if axes and (len(axes) != len(joints) or len(set(axes)) != len(axes)):
        raise ctx.error("pair_control.axes", f"pair_control.axes: expected one distinct device axis per joint "
                                             f"({len(joints)}), got {list(axes)}")


def _line_map(node: Any, path: str, out: dict[str, int], ctx: _Ctx) -> None:
    """Record the line of each dotted key; reject duplicate keys (PyYAML keeps the last silently)."""
    if isinstance(node, yaml.MappingNode):
        seen = set()
        for k, v in node.value:
            p = f"{path}.{k.value}" if path else str(k.value)
            if k.value in seen:
                raise ConfigError(f"{ctx.source}:{k.start_mark.line + 1}: duplicate key '{p}'")
            seen.add(k.value)
            out[p] = k.start_mark.line + 1
            _line_map(v, p, out, ctx)
    elif isinstance(node, yaml.SequenceNode):
        for i, item in enumerate(node.value):
            out[f"{path}[{i}]"] = item.start_mark.line + 1
            _line_map(item, f"{path}[{i}]", out, ctx)


def _read_yaml(path: Path) -> tuple[Any, dict[str, int]]:
    source = str(path)
    if not path.is_file():
        raise ConfigError(f"{source}: config file not found (looked for {path.resolve()})")
    try:
        text = path.read_text(encoding="utf-8")
        lines: dict[str, int] = {}
        node = yaml.compose(text, Loader=_Loader)
        _line_map(node, "", lines, _Ctx(source))
        return yaml.load(text, Loader=_Loader), lines
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None) or getattr(e, "context_mark", None)
        where = f"{source}:{mark.line + 1}:{mark.column + 1}" if mark else source
        problem = getattr(e, "problem", None) or str(e)
        raise ConfigError(f"{where}: YAML syntax error: {problem}") from None
    except (OSError, UnicodeDecodeError) as e:
        raise ConfigError(f"{source}: cannot read config file ({e})") from None


def _expand_dotted(overrides: dict) -> dict:
    """``{"rig.rate_hz": 500}`` -> ``{"rig": {"rate_hz": 500}}``, deep-merged with nested entries."""
    out: dict = {}
    for k, v in overrides.items():
        *parents, last = str(k).split(".")
        d = out
        for p in parents:
            d = d.setdefault(p, {})
        if isinstance(v, dict) and isinstance(d.get(last), dict):
            d[last] = {**d[last], **_expand_dotted(v)}
        else:
            d[last] = _expand_dotted(v) if isinstance(v, dict) else v
    return out


def config_from_dict(data: dict | None, *, source: str = "<dict>", base: Config | None = None) -> Config:
    """Apply a nested mapping of settings over ``base`` (default: the schema defaults).

    Raises
    ------
    ConfigError
        Unknown key, wrong type, value out of range (message names ``source`` and the dotted key).
    """
    ctx = _Ctx(source)
    return _check(_merge(Config, base or Config(), data, "", ctx), ctx)


def load_config(path: str | Path | None = None, overrides: dict | None = None) -> Config:
    """Load a YAML config over the defaults, then apply ``overrides``.

    The dataclass defaults are the defaults (configs/default.yaml spells them out); a file changes only
    the keys it names (sections merge deeply, lists are replaced whole).

    Parameters
    ----------
    path : str or Path, optional
        YAML file; None: defaults only.
    overrides : dict, optional
        Nested (``{"rig": {"rate_hz": 500}}``) or dotted (``{"rig.rate_hz": 500}``) settings applied
        last; errors name them as ``overrides``.

    Returns
    -------
    Config

    Raises
    ------
    ConfigError
        Missing or unreadable file; YAML syntax error (file, line, column); duplicate key; unknown key
        (with the closest known key); wrong type (key, expected type, value); value out of range (key,
        range, unit); invalid instrument id or endpoint. Messages start with ``<file>:<line>:``.
    """
    cfg = Config()
    if path is not None:
        data, lines = _read_yaml(Path(path))
        ctx = _Ctx(str(path), lines)
        cfg = _check(_merge(Config, cfg, data, "", ctx), ctx)
    if overrides:
        cfg = config_from_dict(_expand_dotted(overrides), source="overrides", base=cfg)
    return cfg


def joint_set_tension(cfg: Config, joint: JointConfig) -> float:
    """The antagonist's set tension of a joint [N]: its pretension, else ``pair_control.min_tension``."""
    return joint.pretension if joint.pretension > 0 else cfg.pair_control.min_tension


def config_to_dict(cfg: Any) -> Any:
    """Plain YAML-ready data of a config (lists for tuples; a straight run omits its radius).

    ``config_from_dict(config_to_dict(cfg)) == cfg`` for every valid ``cfg``.
    """
    if isinstance(cfg, RunConfig):
        return {"length": cfg.length} if math.isinf(cfg.radius) else {"length": cfg.length, "radius": cfg.radius}
    if dataclasses.is_dataclass(cfg):
        return {f.name: config_to_dict(getattr(cfg, f.name)) for f in dataclasses.fields(cfg)}
    if isinstance(cfg, (tuple, list)):
        return [config_to_dict(x) for x in cfg]
    return cfg


def write_config(cfg: Config, path: str | Path) -> Path:
    """Write the resolved config as YAML (e.g. next to a recording); returns the path."""
    path = Path(path)
    text = "# resolved teleop configuration (every setting, SI units unless the key has a suffix)\n"
    path.write_text(text + yaml.safe_dump(config_to_dict(cfg), sort_keys=False), encoding="utf-8")
    return path
