"""The configuration schema: one frozen dataclass per section, mirroring configs/default.yaml key for
key, and :data:`RANGES`, the one table of each numeric setting's valid range and unit.

Defaults live here (the dataclass defaults are the defaults; configs/default.yaml spells them out
with comments). The exception is ``rig.simulated.effects``: its switches, defaults and ranges are
the effect catalogue's entries (:mod:`teleop.config.effects`). A rig's section holds only that rig's
settings: ``rig.simulated`` everything only the simulators use, ``rig.zenoh`` the bridge's; the
instrument's own description (``instrument``, ``sheath``) is what the slave knows. :data:`MOVED` maps the
keys of the former layout to their place. Loading, merging and checking a YAML file is
:mod:`teleop.config.load`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

from estimator.geometry import Run, SheathGeometry
from teleop.config.effects import EffectsConfig
from teleop.config.recording_rig import RecordingRigConfig

__all__ = [
    "InstrumentConfig", "RunConfig", "SheathConfig", "TendonConfig", "TendonPairConfig", "JointLoadConfig",
    "JointConfig", "SimulatedTendonConfig", "SimulatedTendonPairConfig", "SimulatedJointConfig", "MotorConfig",
    "LoadConfig", "SensorConfig", "SimulatedRigConfig", "ZenohRigConfig", "RigConfig", "EstimatorConfig",
    "CalibrationConfig", "ArmConfig", "DeviceConfig", "MappingConfig", "MasterConfig", "SlaveConfig",
    "PairControlConfig", "TransportAuthConfig", "TransportTlsConfig", "TransportConfig", "RerunServeConfig",
    "RecordingConfig",
    "Ros2Config", "SafetyConfig", "Config", "joint_set_tension",
]


@dataclass(frozen=True)
class InstrumentConfig:
    id: str = "tsm0"
    joints: tuple[JointConfig, ...] = ()  # empty: the single tendon of `sheath`; 1..16: pairs (or spindle-driven)
    tool: str | None = None    # the instrument's tool file: configs/tools/<NAME>.yaml or a path (teleop.config.tools)


@dataclass(frozen=True)
class RunConfig:
    length: float                 # [m] > 0
    radius: float = math.inf      # [m] > 0, inf = straight


@dataclass(frozen=True)
class SheathConfig:
    """The single-tendon instrument's transmission as the slave knows it (route, tendon EA, preload);
    the friction of the simulated one is ``rig.simulated.mu``."""

    EA: float = 15000.0           # [N] > 0
    runs: tuple[RunConfig, ...] = (
        RunConfig(0.30), RunConfig(0.60, 0.191), RunConfig(0.30), RunConfig(0.30, 0.0955),
    )
    pretension: float = 0.0       # [N] >= 0

    def geometry(self) -> SheathGeometry:
        return SheathGeometry([Run(r.length, r.radius) for r in self.runs])


# ---- instruments of 1..16 joints, each driven by an antagonistic tendon pair (slave/pair_rig.py) --

@dataclass(frozen=True)
class TendonConfig:
    """One tendon-sheath transmission of a joint as the slave knows it (its own route and stiffness;
    the simulated friction is ``rig.simulated.joints[].tendons``)."""

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
    """One joint of the instrument as the slave knows it (its simulated physics: ``rig.simulated.joints``)."""

    name: str                             # [A-Za-z0-9_-]+, unique in the instrument
    pulley_radius: float = 0.004          # [m] distal pulley: x_out,a = +r theta, x_out,b = -r theta
    limits: tuple[float, ...] = (-1.2, 1.2)  # [rad] lower < 0 < upper (0: the rest pose)
    pretension: float = 0.0               # [N] tension of the pair at rest; 0: none (antagonist slack-free)
    tendons: TendonPairConfig = field(default_factory=TendonPairConfig)
    spindle_radius: float = 0.0           # [m] > 0: one input spindle pulls the pair (slave/spindle_axis.py)


@dataclass(frozen=True)
class SimulatedTendonConfig:
    mu: float = 0.1                       # [-] >= 0 friction coefficient tendon/sheath


@dataclass(frozen=True)
class SimulatedTendonPairConfig:
    a: SimulatedTendonConfig = field(default_factory=SimulatedTendonConfig)
    b: SimulatedTendonConfig = field(default_factory=SimulatedTendonConfig)


@dataclass(frozen=True)
class SimulatedJointConfig:
    """``rig.simulated.joints[]``: the simulated physics of the instrument joint of the same name."""

    name: str                             # an instrument.joints name
    stiffness: float = 0.005              # [N m/rad] joint return spring
    damping: float = 0.0002               # [N m s/rad]
    limit_stiffness: float = 50.0         # [N m/rad] stiffness of the joint limits
    load: JointLoadConfig = field(default_factory=JointLoadConfig)
    tendons: SimulatedTendonPairConfig = field(default_factory=SimulatedTendonPairConfig)


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


# ---- model effects of the simulated rig: EffectsConfig (teleop/config/effects.py), one switch per entry of
# the effect catalogue (estimator/offline/effects/catalogue.py) that has a rig switch; defaults and ranges are the
# entry's.

@dataclass(frozen=True)
class SimulatedRigConfig:
    """``rig.simulated``: everything only the simulators use (slave/simulated.py, slave/pair_rig.py)."""

    n_elements: int = 200                 # sheath elements of the distributed model (per tendon)
    mu: float = 0.1                       # [-] friction coefficient of the simulated single-tendon sheath
    motor: MotorConfig = field(default_factory=MotorConfig)
    load: LoadConfig = field(default_factory=LoadConfig)
    sensors: SensorConfig = field(default_factory=SensorConfig)
    effects: EffectsConfig = field(default_factory=EffectsConfig)
    # joint instruments: per instrument joint (by name; a joint not listed takes these defaults)
    joints: tuple[SimulatedJointConfig, ...] = ()

    def joint(self, name: str) -> SimulatedJointConfig:
        """The simulated physics of instrument joint ``name`` (the defaults when not listed)."""
        return next((j for j in self.joints if j.name == name), SimulatedJointConfig(name))


@dataclass(frozen=True)
class ZenohRigConfig:
    """The ``zenoh`` rig: set-points out, samples in on ``teleop/<instrument>/rig/{setpoint,sample}``."""

    timeout_ms: float = 50.0              # samples older than this are counted as stale [ms]
    wait_s: float = 10.0                  # at start, wait this long for the first sample [s]


@dataclass(frozen=True)
class RigConfig:
    """``rig``: the rig's type and rate, and the settings of each rig type under its own name."""

    type: Literal["simulated", "zenoh", "recording"] = "simulated"
    rate_hz: float = 1000.0
    simulated: SimulatedRigConfig = field(default_factory=SimulatedRigConfig)
    zenoh: ZenohRigConfig = field(default_factory=ZenohRigConfig)
    recording: RecordingRigConfig = field(default_factory=RecordingRigConfig)


@dataclass(frozen=True)
class EstimatorConfig:
    n_nodes: int = 100
    hold_rate: float = 0.5                # [N/s]
    rate_time_constant: float = 0.02      # [s]
    profile_points: int = 50
    tension_noise: float | None = None  # [N] noise of T_in for the banded update; None: the calibration's
    model: str | None = None              # model file the live estimator runs (teleop analyze --model-out)


@dataclass(frozen=True)
class CalibrationConfig:
    target_tension: float = 20.0          # [N]
    speed: float = 0.004                  # [m/s]
    use_route: bool = True
    dir: str | None = None             # <dir>/<instrument.id>.yaml; None: the per-user data directory


@dataclass(frozen=True)
class ArmConfig:                          # the simulated operator's arm + device (master/arm.py)
    mass: float = 1.5                     # [kg]
    damping: float = 15.0                 # [N s/m]
    stiffness: float = 300.0              # [N/m]
    device_mass: float = 0.1              # [kg]
    device_damping: float = 0.5           # [N s/m]
    device_friction: float = 0.2          # [N]


@dataclass(frozen=True)
class DeviceConfig:
    type: Literal["simulated", "hid", "evdev", "forcedimension", "touch"] = "simulated"   # master/devices.py
    file: str | None = None            # device file (configs/devices/*.yaml), required when type is hid
    arm: ArmConfig = field(default_factory=ArmConfig)


@dataclass(frozen=True)
class MappingConfig:
    motion_scale: float = 0.2
    force_scale: float = 0.2
    force_limit: float = 4.0              # [N]
    ramp_time: float = 0.5                # [s]
    force_rate_limit: float = 100.0       # [N/s]
    passivity: bool = True                # time-domain passivity controller on the force channel
    passivity_reserve: float = 0.005      # [J] below it the outgoing force eases off (master/passivity.py)
    align_tolerance: float = 0.001        # [m] of tendon: re-engage only when this close to the slave
    clutch_button: int = 1                # bit of DeviceState.buttons held to clutch; -1: no clutch


@dataclass(frozen=True)
class MasterConfig:
    rate_hz: float = 1000.0
    device: DeviceConfig = field(default_factory=DeviceConfig)
    mapping: MappingConfig = field(default_factory=MappingConfig)
    watchdog_ms: float = 50.0
    max_tension: float = 200.0            # [N] estimates with |T_in| or |T_out_hat| above: rejected
    # SCHED_FIFO priority of the loop thread, 1-99 (teleop/timing/realtime.py); 0: off
    realtime_priority: int = 20


@dataclass(frozen=True)
class SlaveConfig:
    watchdog_ms: float = 50.0
    heartbeat_hz: float = 50.0
    relax_speed: float = 0.005            # [m/s] SAFE: release toward sheath.pretension at this speed
    x_in_min: float = -0.005              # [m] commands outside [x_in_min, x_in_max]: rejected
    x_in_max: float = 0.03                # [m]
    engage_tolerance: float = 0.002       # [m] (re-)engage only on a command this close to x_in
    max_step: float = 0.001               # [m] tendon travel: a command further from the last accepted one is refused
    max_speed: float = 0.05               # [m/s] tendon travel: the followed target moves no faster
    max_tension: float = 80.0             # [N] a measured |T_in| above: SAFE in that cycle, relax (slave/node_base.py)
    # SCHED_FIFO priority of the loop thread, 1-99 (teleop/timing/realtime.py); 0: off
    realtime_priority: int = 20


@dataclass(frozen=True)
class PairControlConfig:
    """Slave-side control of each antagonistic pair (slave/pair_control.py)."""

    min_tension: float = 0.5              # [N] antagonist's set tension when the joint has no pretension
    tension_gain: float = 0.01            # [m/(N s)] integral gain of the antagonist's tension loop
    switch_band: float = 0.01             # [rad] |command| below: both tendons hold their set tension
    feedforward: bool = True              # antagonist pays out the pulling side's commanded travel
    backlash_compensation: bool = False   # puller pays out the reversal band when the command turns back
    backlash_width: float = 0.005         # [rad] half-width of the command play that compensation spreads over
    axes: tuple[int, ...] = ()            # master: device axis of each joint; empty: joint i on axis i


@dataclass(frozen=True)
class TransportAuthConfig:
    """Zenoh user/password authentication of every link (teleop/session/link_security.py); null: none."""

    installation: bool = True             # no user given: each process uses its role's installation credentials
    user: str | None = None            # this process's user name
    password: str | None = None        # its password (prefer password_file outside tests)
    password_file: str | None = None   # file holding the password (first line)
    dictionary_file: str | None = None  # listener: accepted "user:password" lines


@dataclass(frozen=True)
class TransportTlsConfig:
    """TLS of ``tls/...`` endpoints: PEM files; null: no TLS settings."""

    root_ca: str | None = None         # CA certificate that signs the peers' certificates
    certificate: str | None = None     # this process's certificate (listener; mutual: connector too)
    private_key: str | None = None     # its private key
    mutual: bool = False                  # connectors must present a certificate too


@dataclass(frozen=True)
class TransportConfig:
    mode: Literal["peer", "client"] = "peer"
    listen: tuple[str, ...] = ("tcp/127.0.0.1:7447",)
    connect: tuple[str, ...] = ()
    multicast_scouting: bool = False
    auto_connect: bool = True             # bare start: listen, or connect when the port is taken (live/discovery.py)
    run_id_timeout: float = 3.0           # [s] a connecting side asks its peers for the run id this long
    lock_master: bool = True              # slave: commands and master heartbeats from one master session only
    auth: TransportAuthConfig = field(default_factory=TransportAuthConfig)
    tls: TransportTlsConfig = field(default_factory=TransportTlsConfig)


@dataclass(frozen=True)
class RerunServeConfig:
    """``recording.rerun: serve``: where each side serves its live Rerun stream (gRPC) and the web viewer (HTTP)."""

    bind: str = "127.0.0.1"               # address both servers listen on; another one is a safety waiver
    slave_port: int = 9877                # gRPC port of the slave's stream
    master_port: int = 9878               # gRPC port of the master's stream
    slave_web_port: int = 9097            # HTTP port of the web viewer the slave serves; 0: none
    master_web_port: int = 9098           # the same for the master
    memory_limit: float = 2.56e8          # [B] a side's server keeps this much of the recent stream for late viewers


@dataclass(frozen=True)
class RecordingConfig:
    dir: str = "runs"
    rerun: Literal["save", "spawn", "serve", "off"] = "save"
    rerun_serve: RerunServeConfig = field(default_factory=RerunServeConfig)
    log_every: int = 40                   # [cycles] Rerun: the signals every this many cycles (25 Hz at 1 kHz)
    profile_every: int = 5                # [logs] of those, every n-th also the tension profile (5 Hz)
    csv_every: int = 10                   # [cycles] the sides' per-cycle CSVs get a row every this many cycles
    mcap_every: int = 20                  # session.mcap: a 1 kHz stream's messages whose seq is a multiple of this
    flush_interval: float = 0.02          # [s] recorder files handed to the OS at least this often
    csv: Literal["low_rate", "all"] = "low_rate"   # recorder per-stream CSVs: heartbeats only, or every stream too
    max_bytes: float | None = 5.0e9    # [B] run directory size past which the recorder drops the high-rate streams
    min_free_bytes: float | None = 5.0e8  # [B] free disk space below which it does the same (live/record/budget.py)


@dataclass(frozen=True)
class Ros2Config:
    """The CRTK topics as ROS 2 messages on Zenoh, the rmw_zenoh way (teleop/ros2/wire.py, docs/reference/crtk.md)."""

    enabled: bool = False
    accept_commands: bool = False         # the slave takes servo_jp and state_command from ROS 2 (else publishes only)
    domain_id: int = 0                    # ROS_DOMAIN_ID of the ROS 2 graph, 0..232
    rate_hz: float = 100.0                # [Hz] 1..1000, publication rate of the CRTK topics (off the control loop)


@dataclass(frozen=True)
class SafetyConfig:
    """``safety``: waivers of the hard bounds of :mod:`teleop.config.bounds` (docs/reference/safety-bounds.md)."""

    override: tuple[str, ...] = ()        # bounded keys allowed past their bound; announced and recorded


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
    safety: SafetyConfig = field(default_factory=SafetyConfig)
    ros2: Ros2Config = field(default_factory=Ros2Config)



def joint_set_tension(cfg: Config, joint: JointConfig) -> float:
    """The antagonist's set tension of a joint [N]: its pretension, else ``pair_control.min_tension``."""
    return joint.pretension if joint.pretension > 0 else cfg.pair_control.min_tension
