"""The range table and the moved-key table of the configuration schema (:mod:`teleop.config.schema` uses both).

:data:`RANGES` gives each numeric setting's valid range and unit; :data:`MOVED` maps keys of the former
layout to their place (loading an old key raises one ConfigError saying so).
"""
from __future__ import annotations

__all__ = ["RANGES", "MOVED", "LOOP_RATE"]

#: The control loops' rate range [Hz] (``rig.rate_hz``, ``master.rate_hz``): from a 100 ms period, the longest a
#: loop may sleep between two looks at its stop request, to a 100 us one, below a cycle's own work. The rates and
#: waits below are bounded alike: each is a sleep or a timeout of a thread, which a value past its range would
#: make endless (a period of days) or a busy loop (a period of nothing), or past the platform's largest timeout.
LOOP_RATE = "10..10000"

# Valid range and unit of every numeric setting ("[]" stands for any list index). A test checks that each numeric field
# of the schema has an entry and each entry names a field.
RANGES: dict[str, tuple[str, str]] = {
    "sheath.EA": ("> 0", "N"), "sheath.pretension": (">= 0", "N"),
    "sheath.runs[].length": ("> 0", "m"), "sheath.runs[].radius": ("> 0", "m, .inf = straight"),
    "rig.rate_hz": (LOOP_RATE, "Hz"), "rig.zenoh.timeout_ms": ("> 0", "ms"), "rig.zenoh.wait_s": ("0.01..3600", "s"),
    **{f"rig.simulated.{k}": v for k, v in {
        "n_elements": ("1..10000", "-"), "mu": (">= 0", "-"),
        "motor.bandwidth_hz": ("> 0", "Hz"), "motor.max_speed": ("> 0", "m/s"),
        "motor.pulley_radius": ("> 0", "m"), "motor.encoder_lines_per_rev": (">= 1", "-"),
        "load.joint_stiffness": (">= 0", "N/m"), "load.joint_limit": ("> 0", "m"),
        "load.limit_stiffness": ("> 0", "N/m"), "load.tissue_stiffness": (">= 0", "N/m"),
        "load.tissue_contact": ("any", "m"), "load.force": (">= 0", "N"),
        "sensors.load_cell_noise": (">= 0", "N"), "sensors.seed": (">= 0", "-")}.items()},
    # rig.simulated.effects.*: each setting's range and unit are its catalogue entry's (effects_config.effect_ranges)
    "estimator.n_nodes": ("2..10000", "-"), "estimator.hold_rate": (">= 0", "N/s"),
    "estimator.rate_time_constant": ("> 0", "s"), "estimator.profile_points": ("0..65535", "-"),
    "estimator.tension_noise": (">= 0", "N"),
    "calibration.target_tension": ("> 0", "N"), "calibration.speed": ("> 0", "m/s"),
    "master.rate_hz": (LOOP_RATE, "Hz"), "master.watchdog_ms": ("> 0", "ms"),
    "master.mapping.motion_scale": ("> 0", "-"), "master.mapping.force_scale": (">= 0", "-"),
    "master.mapping.force_limit": (">= 0", "N"), "master.mapping.ramp_time": (">= 0", "s"),
    "master.mapping.force_rate_limit": ("> 0", "N/s"), "master.mapping.align_tolerance": ("> 0", "m"),
    "master.mapping.clutch_button": ("-1..31", "bit"), "master.max_tension": ("> 0", "N"),
    "master.mapping.passivity_reserve": (">= 0", "J"), "master.device.arm.mass": ("> 0", "kg"),
    "master.device.arm.damping": (">= 0", "N s/m"),
    "master.device.arm.stiffness": ("> 0", "N/m"), "master.device.arm.device_mass": (">= 0", "kg"),
    "master.device.arm.device_damping": (">= 0", "N s/m"), "master.device.arm.device_friction": (">= 0", "N"),
    "slave.relax_speed": (">= 0", "m/s"), "slave.x_in_min": ("any", "m"), "slave.x_in_max": ("any", "m"),
    "slave.engage_tolerance": ("> 0", "m"), "slave.watchdog_ms": ("> 0", "ms"), "slave.heartbeat_hz": ("1..1000", "Hz"),
    "slave.max_tension": ("> 0", "N"), "slave.max_step": ("> 0", "m"), "slave.max_speed": ("> 0", "m/s"),
    "master.realtime_priority": ("0..99", "-"), "slave.realtime_priority": ("0..99", "-"),
    "instrument.joints[].pulley_radius": ("> 0", "m"), "instrument.joints[].limits[]": ("any", "rad"),
    "instrument.joints[].pretension": (">= 0", "N"), "instrument.joints[].spindle_radius": (">= 0", "m"),
    **{f"instrument.joints[].tendons.{t}.{k}": v for t in "ab" for k, v in (
        ("EA", ("> 0", "N")), ("runs[].length", ("> 0", "m")), ("runs[].radius", ("> 0", "m, .inf = straight")))},
    "rig.simulated.joints[].stiffness": (">= 0", "N m/rad"), "rig.simulated.joints[].damping": (">= 0", "N m s/rad"),
    "rig.simulated.joints[].limit_stiffness": ("> 0", "N m/rad"),
    "rig.simulated.joints[].load.tissue_stiffness": (">= 0", "N m/rad"),
    "rig.simulated.joints[].load.tissue_contact": (">= 0", "rad"), "rig.simulated.joints[].load.torque": ("any", "N m"),
    "rig.simulated.joints[].tendons.a.mu": (">= 0", "-"), "rig.simulated.joints[].tendons.b.mu": (">= 0", "-"),
    "pair_control.min_tension": ("> 0", "N"), "pair_control.tension_gain": ("> 0", "m/(N s)"),
    "pair_control.switch_band": (">= 0", "rad"), "pair_control.backlash_width": ("> 0", "rad"),
    "pair_control.axes[]": (">= 0", "-"),
    "recording.log_every": (">= 1", "samples"), "recording.profile_every": (">= 1", "logs"),
    "recording.csv_every": (">= 1", "cycles"), "recording.mcap_every": (">= 1", "messages"),
    "recording.flush_interval": ("0.001..10", "s"), "transport.run_id_timeout": ("0..60", "s"),
    "recording.max_bytes": ("> 0", "B"), "recording.min_free_bytes": (">= 0", "B"),
    **{f"recording.rerun_serve.{k}": ("1..65535", "-") for k in ("slave_port", "master_port")},
    **{f"recording.rerun_serve.{k}": ("0..65535", "-") for k in ("slave_web_port", "master_web_port")},
    "recording.rerun_serve.memory_limit": (">= 1.0e6", "B"),
    "ros2.domain_id": ("0..232", "-"), "ros2.rate_hz": ("1..1000", "Hz"),
}


#: Keys of the former layout -> where they live now (loading an old key raises one ConfigError saying so).
MOVED: dict[str, str] = {
    **{f"rig.{k}": f"rig.simulated.{k}" for k in ("n_elements", "motor", "load", "sensors", "effects")},
    "sheath.mu": "rig.simulated.mu",
    **{f"instrument.joints[].{k}": f"rig.simulated.joints[].{k} (the entry with the joint's name)"
       for k in ("stiffness", "damping", "limit_stiffness", "load")},
    **{f"instrument.joints[].tendons.{t}.mu": f"rig.simulated.joints[].tendons.{t}.mu (the entry with the joint's name)"
       for t in "ab"},
}
