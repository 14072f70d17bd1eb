"""Checks of the instrument's joints beyond one value's type and range
(:func:`teleop.config.load.load_config` runs them).

``error(path, message)`` builds the :class:`~teleop.errors.ConfigError` that names the file and line of ``path``.
"""
from __future__ import annotations

import ipaddress
import re
from collections.abc import Callable

from teleop.config.schema import Config
from teleop.errors import ConfigError

__all__ = ["MAX_JOINTS", "check_joints", "check_rerun_serve"]

MAX_JOINTS = 16                 # one axis of the wire per joint (teleop.wire.codec.MAX_AXES)
_JOINT_NAME = re.compile(r"[A-Za-z0-9_-]+")


def check_joints(cfg: Config, error: Callable[[str, str], ConfigError]) -> None:
    """instrument.joints: 0 (single tendon) or 1..MAX_JOINTS joints with unique names, limits [lower < 0 < upper],
    non-empty tendon routes; pair_control.axes empty or one distinct axis per joint."""
    joints = cfg.instrument.joints
    if len(joints) > MAX_JOINTS:
        raise error("instrument.joints", f"instrument.joints: {len(joints)} joints, an instrument has "
                                             f"1 to {MAX_JOINTS}")
    seen: dict[str, int] = {}
    for i, j in enumerate(joints):
        where = f"instrument.joints[{i}]"
        if not _JOINT_NAME.fullmatch(j.name):
            raise error(f"{where}.name", f"{where}.name: {j.name!r} is not a joint name (letters, digits, "
                                             f"'_' or '-' only)")
        if j.name in seen:
            raise error(f"{where}.name", f"{where}.name: {j.name!r} is already the name of "
                                             f"instrument.joints[{seen[j.name]}]")
        seen[j.name] = i
        lim = j.limits
        if len(lim) != 2 or not (lim[0] < 0.0 < lim[1]):
            raise error(f"{where}.limits", f"{where}.limits ({j.name}): expected [lower, upper] [rad] with "
                                               f"lower < 0 < upper (0 is the rest pose), got {list(lim)}")
        for t in ("a", "b"):
            if not getattr(j.tendons, t).runs:
                raise error(f"{where}.tendons.{t}.runs", f"{where}.tendons.{t}.runs ({j.name}): expected "
                                                             f"at least one run")
    for i, sj in enumerate(cfg.rig.simulated.joints):
        where = f"rig.simulated.joints[{i}].name"
        if sj.name not in seen or any(o.name == sj.name for o in cfg.rig.simulated.joints[:i]):
            raise error(where, f"{where}: {sj.name!r} must name a joint of instrument.joints once "
                                   f"(joints: {', '.join(seen) or 'none'})")
    axes = cfg.pair_control.axes
    if axes and (len(axes) != len(joints) or len(set(axes)) != len(axes)):
        raise error("pair_control.axes", f"pair_control.axes: expected one distinct device axis per joint "
                                             f"({len(joints)}), got {list(axes)}")


def check_rerun_serve(cfg: Config, error: Callable[[str, str], ConfigError]) -> None:
    """recording.rerun_serve: ``bind`` an IP address (not a host name), the ports of the streams and web viewers
    distinct (a web port of 0 serves no web viewer)."""
    serve = cfg.recording.rerun_serve
    try:
        ipaddress.ip_address(serve.bind)
    except ValueError:
        raise error("recording.rerun_serve.bind", f"recording.rerun_serve.bind: {serve.bind!r} is not an IP "
                                                  f"address (expected e.g. 127.0.0.1)") from None
    seen: dict[int, str] = {}
    for key in ("slave_port", "master_port", "slave_web_port", "master_web_port"):
        port = getattr(serve, key)
        if port == 0 and key.endswith("web_port"):
            continue
        if port in seen:
            raise error(f"recording.rerun_serve.{key}", f"recording.rerun_serve.{key}: port {port} is already "
                                                        f"recording.rerun_serve.{seen[port]}")
        seen[port] = key
