"""CRTK names of the project's messages: topics, joint states, wrenches and operating states.

CRTK (the Collaborative Robotics Toolkit, collaborative-robotics/documentation: "Robot motion" and
"Operating states") names what a robot arm publishes and accepts. Each side is one CRTK arm:

* the slave, arm ``<instrument>`` (:func:`slave_arm`), per cycle's latest :class:`~teleop.wire.messages.Estimate`:

  ==================================  ===================================  =============================================
  topic                               type                                 content, per instrument axis
  ==================================  ===================================  =============================================
  ``/<arm>/measured_js``              ``sensor_msgs/msg/JointState``       the axis in ``servo_jp``'s space: a tendon's
                                                                           encoder ``x_in`` [m] and load cell ``T_in``
                                                                           [N]; a pair's joint angle [rad] (from its
                                                                           encoders less the estimated elongation, the
                                                                           only reading of a pair's angle) and its
                                                                           proximal torque ``r (T_in,a - T_in,b)`` [N m]
  ``/<arm>/actuators/measured_js``    ``sensor_msgs/msg/JointState``       one entry per tendon: ``x_in`` [m],
                                                                           ``T_in`` [N]
  ``/<arm>/distal/measured_js``       ``sensor_msgs/msg/JointState``       the estimate: ``position_hat`` [m or rad],
                                                                           ``effort_hat`` (``T_out_hat`` [N], or the
                                                                           joint torque [N m])
  ``/<arm>/setpoint_js``              ``sensor_msgs/msg/JointState``       the targets being followed (ENGAGED); stamp 0
                                                                           (invalid) otherwise
  ``/<arm>/measured_cf``              ``geometry_msgs/msg/WrenchStamped``  single tendon: the estimated distal tension
                                                                           as force z [N] (+ = pulled toward the
                                                                           actuator)
  ``/<arm>/<joint>/measured_cf``      ``geometry_msgs/msg/WrenchStamped``  joint instrument: the estimated joint torque
                                                                           as torque z [N m] (+ turns toward tendon a)
  ``/<arm>/operating_state``          ``crtk_msgs/msg/OperatingState``     :data:`OPERATING` of the slave's state
  ``/<arm>/servo_jp`` (in)            ``sensor_msgs/msg/JointState``       targets, one per axis (:func:`servo_targets`)
  ``/<arm>/state_command`` (in)       ``crtk_msgs/msg/StringStamped``      enable / resume admit ``servo_jp``,
                                                                           disable / pause refuse it
  ==================================  ===================================  =============================================

* the master, arm ``<instrument>_master``: ``measured_js`` (the device position of each instrument
  axis [m] and the force rendered on it [N]) and ``operating_state``.

Data validity (CRTK): a value that is not valid carries a zero header stamp.
"""
from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from typing import Any

from teleop.config.kinds import instrument_kind
from teleop.errors import CodecError
from teleop.ros2.types import (
    JOINT_STATE,
    OPERATING_STATE,
    STRING_STAMPED,
    WRENCH_STAMPED,
    joint_state,
    operating_state,
    wrench_stamped,
)
from teleop.ros2.wire import ros_name
from teleop.wire.messages import Estimate, SideState

__all__ = ["OPERATING", "FAULT", "STATE_COMMANDS", "slave_arm", "master_arm", "axis_names", "tendon_names",
           "slave_topics", "command_topics", "master_topics", "slave_messages", "master_messages", "servo_targets"]

#: SideState -> (CRTK state, is_homed, is_busy). SAFE (no fresh command, or the link lost: the axes hold,
#: then relax) is PAUSED: powered, not moving on commands, left by the next valid command. A SAFE held by a
#: tension trip is FAULT instead (:data:`FAULT`): latched until the operator lets go (slave/node_base.py).
OPERATING: dict[SideState, tuple[str, bool, bool]] = {
    SideState.STARTING: ("DISABLED", False, False),
    SideState.CALIBRATING: ("ENABLED", False, True),
    SideState.READY: ("ENABLED", True, False),
    SideState.ENGAGED: ("ENABLED", True, True),
    SideState.SAFE: ("PAUSED", True, False),
    SideState.STOPPING: ("DISABLED", True, False),
}
#: The slave's state while a tension trip holds it SAFE: CRTK's FAULT, homed, not busy.
FAULT = ("FAULT", True, False)
#: state_command strings -> whether servo_jp is admitted afterwards
STATE_COMMANDS = {"enable": True, "resume": True, "disable": False, "pause": False}


def slave_arm(cfg: Any) -> str:
    """The slave's CRTK arm name: the instrument id as a ROS name."""
    return ros_name(cfg.instrument.id)


def master_arm(cfg: Any) -> str:
    """The master's CRTK arm name: ``<slave arm>_master``."""
    return f"{slave_arm(cfg)}_master"


def axis_names(cfg: Any) -> tuple[str, ...]:
    """One joint name per instrument axis: ``tendon`` for the single tendon, else the joints' names."""
    return tuple(j.name for j in cfg.instrument.joints) or ("tendon",)


def tendon_names(cfg: Any) -> tuple[str, ...]:
    """One actuator name per tendon: ``tendon``, or ``<joint>_a``, ``<joint>_b`` per joint."""
    return tuple(f"{j.name}_{s}" for j in cfg.instrument.joints for s in "ab") or ("tendon",)


def _cf_topics(cfg: Any) -> tuple[str, ...]:
    arm = slave_arm(cfg)
    return tuple(f"/{arm}/{j.name}/measured_cf" for j in cfg.instrument.joints) or (f"/{arm}/measured_cf",)


def slave_topics(cfg: Any) -> dict[str, str]:
    """Every topic the slave publishes -> its ROS 2 type (the table of the module docstring)."""
    arm = slave_arm(cfg)
    js = {f"/{arm}/{t}": JOINT_STATE for t in ("measured_js", "actuators/measured_js", "distal/measured_js",
                                                 "setpoint_js")}
    return {**js, **dict.fromkeys(_cf_topics(cfg), WRENCH_STAMPED), f"/{arm}/operating_state": OPERATING_STATE}


def command_topics(cfg: Any) -> dict[str, str]:
    """The topics the slave subscribes to -> their ROS 2 type (``servo_jp``, ``state_command``)."""
    arm = slave_arm(cfg)
    return {f"/{arm}/servo_jp": JOINT_STATE, f"/{arm}/state_command": STRING_STAMPED}


def master_topics(cfg: Any) -> dict[str, str]:
    """Every topic the master publishes -> its ROS 2 type."""
    arm = master_arm(cfg)
    return {f"/{arm}/measured_js": JOINT_STATE, f"/{arm}/operating_state": OPERATING_STATE}


def _operating(t_ns: int, state: SideState, fault: bool = False) -> bytes:
    name, homed, busy = FAULT if fault else OPERATING.get(state, ("FAULT", False, False))
    return operating_state(t_ns, name, homed, busy)


def _measured(cfg: Any, est: Estimate) -> tuple[list[float], list[float]]:
    if instrument_kind(cfg) == "tendon":
        t = est.axes[0].tendons[0]
        return [t.x_in], [t.T_in]
    radii = [j.pulley_radius for j in cfg.instrument.joints]
    return ([a.position_hat for a in est.axes],
            [r * (a.tendons[0].T_in - a.tendons[1].T_in) for a, r in zip(est.axes, radii, strict=False)])


def slave_messages(cfg: Any, t_ns: int, state: SideState, est: Estimate | None, targets: Sequence[float] | None,
                   fault: bool = False) -> Iterator[tuple[str, bytes]]:
    """(topic, CDR bytes) of every slave topic for one publication at ``t_ns`` [ns, UNIX epoch], one topic
    encoded per step of the iteration (the publisher thread encodes each in the loop's idle time).

    ``est``: the latest estimate (None before the first: only the operating state and an invalid
    setpoint); ``targets``: the targets followed, or None when not ENGAGED (setpoint stamp 0); ``fault``: a
    tension trip holds the slave SAFE (operating state FAULT).
    """
    arm = slave_arm(cfg)
    names = axis_names(cfg)
    yield f"/{arm}/operating_state", _operating(t_ns, state, fault)
    yield f"/{arm}/setpoint_js", joint_state(t_ns, names, targets) if targets is not None else joint_state(0, names)
    if est is None:
        return
    pos, eff = _measured(cfg, est)
    yield f"/{arm}/measured_js", joint_state(t_ns, names, pos, None, eff)
    yield f"/{arm}/actuators/measured_js", joint_state(t_ns, tendon_names(cfg), [t.x_in for t in est.tendons],
                                                      None, [t.T_in for t in est.tendons])
    yield f"/{arm}/distal/measured_js", joint_state(t_ns, names, [a.position_hat for a in est.axes], None,
                                                   [a.effort_hat for a in est.axes])
    single = instrument_kind(cfg) == "tendon"
    for topic, a in zip(_cf_topics(cfg), est.axes, strict=False):
        force, torque = ((0.0, 0.0, a.effort_hat), (0.0, 0.0, 0.0)) if single else \
            ((0.0, 0.0, 0.0), (0.0, 0.0, a.effort_hat))
        yield topic, wrench_stamped(t_ns, force, torque, f"{arm}_distal")


def master_messages(cfg: Any, t_ns: int, state: SideState, positions: Sequence[float] | None,
                    forces: Sequence[float] | None) -> Iterator[tuple[str, bytes]]:
    """(topic, CDR bytes) of the master's topics: the device position [m] and rendered force [N] per
    axis (stamp 0 and no values while a position is missing or not finite), and the operating state."""
    arm = master_arm(cfg)
    names = axis_names(cfg)
    valid = positions is not None and forces is not None and all(math.isfinite(v) for v in (*positions, *forces))
    yield f"/{arm}/measured_js", joint_state(t_ns, names, positions, None, forces) if valid else joint_state(0, names)
    yield f"/{arm}/operating_state", _operating(t_ns, state)


def servo_targets(msg: Any, names: Sequence[str]) -> tuple[float, ...]:
    """The targets of a decoded ``servo_jp`` JointState, one per axis in ``names`` order: by name when
    the message names its joints, else in order.

    Raises
    ------
    CodecError
        A missing or unknown joint name, a position count other than the axes', or a non-finite position.
    """
    pos = [float(v) for v in msg.position]
    given = list(msg.name)
    if given:
        if len(given) != len(pos) or set(given) != set(names) or len(set(given)) != len(given):
            raise CodecError(f"servo_jp: joints {given} with {len(pos)} positions, expected one for each of "
                             f"{list(names)}")
        pos = [pos[given.index(n)] for n in names]
    if len(pos) != len(names):
        raise CodecError(f"servo_jp: {len(pos)} positions, expected {len(names)} ({', '.join(names)})")
    if not all(math.isfinite(v) for v in pos):
        raise CodecError("servo_jp: a non-finite position")
    return tuple(pos)
