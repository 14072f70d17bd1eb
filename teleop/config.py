"""Configuration schema (dataclasses) and strict YAML loading.

The schema mirrors configs/default.yaml key for key. Loading merges a file over the defaults and
rejects unknown keys, wrong types and out-of-range values with a :class:`ConfigError` that names the
file and the dotted key.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

from estimator.sheath import Run, SheathGeometry

__all__ = [
    "InstrumentConfig", "RunConfig", "SheathConfig", "MotorConfig", "LoadConfig", "SensorConfig",
    "RigConfig", "EstimatorConfig", "CalibrationConfig", "DeviceConfig", "MappingConfig",
    "MasterConfig", "SlaveConfig", "TransportConfig", "RecordingConfig", "Config",
]


@dataclass(frozen=True)
class InstrumentConfig:
    id: str = "tsm0"


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


@dataclass(frozen=True)
class RigConfig:
    type: Literal["simulated"] = "simulated"
    n_elements: int = 200
    rate_hz: float = 1000.0
    motor: MotorConfig = field(default_factory=MotorConfig)
    load: LoadConfig = field(default_factory=LoadConfig)
    sensors: SensorConfig = field(default_factory=SensorConfig)


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


@dataclass(frozen=True)
class DeviceConfig:
    type: Literal["simulated", "hid"] = "simulated"


@dataclass(frozen=True)
class MappingConfig:
    motion_scale: float = 0.2
    force_scale: float = 0.2
    force_limit: float = 4.0              # [N]
    ramp_time: float = 0.5                # [s]
    force_rate_limit: float = 100.0       # [N/s]


@dataclass(frozen=True)
class MasterConfig:
    rate_hz: float = 1000.0
    device: DeviceConfig = field(default_factory=DeviceConfig)
    mapping: MappingConfig = field(default_factory=MappingConfig)
    watchdog_ms: float = 50.0


@dataclass(frozen=True)
class SlaveConfig:
    watchdog_ms: float = 50.0
    heartbeat_hz: float = 50.0


@dataclass(frozen=True)
class TransportConfig:
    mode: Literal["peer", "client"] = "peer"
    listen: tuple[str, ...] = ("tcp/127.0.0.1:7447",)
    connect: tuple[str, ...] = ()
    multicast_scouting: bool = False


@dataclass(frozen=True)
class RecordingConfig:
    dir: str = "runs"
    rerun: Literal["save", "spawn", "off"] = "save"
    log_every: int = 10


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


# ---- loading: to be completed (strict YAML -> Config). See the module docstring. ----
