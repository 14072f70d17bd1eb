"""Tool definitions: the design constants of one instrument axis and where each was measured.

A tool is a YAML file under ``configs/tools/`` (``configs/tools/<name>.yaml``). It holds what one run of the
instrument cannot give an estimator, each with its uncertainty and its source:

* ``load_gain`` [-]: the axis' output torque per N m of shift of the input spindle's friction-band centre
  (about 1 / (r cosh K) for a cable pair of radii ratio r and capstan exponent K). One calibration run at one
  load shows the load only through this gain times the load, so the centre map of ``teleop analyze --mrd``
  takes it from the tool (docs/how-to/tools.md);
* ``pulley_radii_ratio`` [rad/rad]: output angle per input-spindle angle in full motion (n_k);
* ``friction_exponents.a`` / ``.b`` [-]: capstan exponents K = mu phi of the two cables of the pair;
* ``limits``: the input-spindle angle and output torque ranges the constants were measured over;
* ``calibration``: the one-run calibration rule the constants go with, and how they were measured;
* ``source``: the data, its licence and attribution.

Loading is strict like every config (:mod:`teleop.config.load`): unknown keys, wrong types and out-of-range values
are refused with one :class:`ConfigError` line naming the file, its line and the dotted key.
"""
from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from teleop.config.effects import in_range
from teleop.config.files import configs_dir, tool_file
from teleop.config.load import ErrorContext, merge_dataclass
from teleop.config.reader import read_yaml
from teleop.errors import ConfigError

__all__ = ["Measured", "FrictionExponents", "ToolLimits", "ToolCalibration", "ToolSource", "Tool", "TOOL_RANGES",
           "tools_dir", "tool_path", "load_tool", "tool_names"]


@dataclass(frozen=True)
class Measured:
    """One constant: ``value`` in ``unit``, one standard error ``uncertainty`` (same unit, >= 0), the data it was
    ``measured_on`` and ``by`` what (a command and the JSON key it reads)."""

    value: float
    uncertainty: float
    unit: str
    measured_on: str
    by: str


@dataclass(frozen=True)
class FrictionExponents:
    """Capstan exponents K = mu phi [-] of cable a (pulling it turns the output to + angles) and cable b."""

    a: Measured
    b: Measured


@dataclass(frozen=True)
class ToolLimits:
    """Ranges the constants hold on: input-spindle angle [rad] and output torque [N m], each [lower, upper]."""

    spindle_angle: tuple[float, ...]
    output_torque: tuple[float, ...]


@dataclass(frozen=True)
class ToolCalibration:
    """``runs``: the one-run calibration rule the constants go with (``--calibration`` syntax: ``mid`` or a run
    name); ``protocol``: how the constants were measured."""

    runs: str
    protocol: str


@dataclass(frozen=True)
class ToolSource:
    """Where the measurements come from: ``data`` (repository, folders, commit), ``licence``, ``attribution``."""

    data: str
    licence: str
    attribution: str


@dataclass(frozen=True)
class Tool:
    """One instrument axis (module docstring); ``path`` is the file it was read from (not a key)."""

    name: str
    instrument: str
    axis: str
    load_gain: Measured
    pulley_radii_ratio: Measured
    friction_exponents: FrictionExponents
    limits: ToolLimits
    calibration: ToolCalibration
    source: ToolSource


#: Valid range of each numeric key (the rules of :func:`teleop.config.effects.in_range`) and its unit.
TOOL_RANGES: dict[str, tuple[str, str]] = {
    "load_gain.value": ("> 0", "-"), "load_gain.uncertainty": (">= 0", "-"),
    "pulley_radii_ratio.value": ("> 0", "rad/rad"), "pulley_radii_ratio.uncertainty": (">= 0", "rad/rad"),
    **{f"friction_exponents.{c}.{k}": (">= 0", "-") for c in "ab" for k in ("value", "uncertainty")},
}
_NAME = re.compile(r"[A-Za-z0-9_-]+")          # a tool's name, as configs/tools/<NAME>.yaml
_CALIBRATION_RUNS = re.compile(r"mid|[A-Za-z0-9_-]+")


def tools_dir() -> Path:
    """``configs/tools/`` of the project (:func:`teleop.config.files.configs_dir`)."""
    return configs_dir() / "tools"


def tool_names() -> list[str]:
    """Names of the shipped tools (the stems of ``configs/tools/*.yaml``), sorted."""
    return sorted(p.stem for p in tools_dir().glob("*.yaml"))


def tool_path(name_or_path: str | Path) -> Path:
    """The file of a tool: ``configs/tools/<NAME>.yaml`` for a bare name, else the path itself
    (:func:`teleop.config.files.tool_file`). Raises ConfigError when neither exists, listing the shipped tools."""
    return tool_file(name_or_path)


def _check(tool: Tool, error: Callable[[str, str], ConfigError]) -> None:
    """Ranges of :data:`TOOL_RANGES`, the name, the limits' order and the calibration rule."""
    for key, (rule, unit) in TOOL_RANGES.items():
        obj: object = tool
        for part in key.split("."):
            obj = getattr(obj, part)
        if not in_range(float(obj), rule):  # type: ignore[arg-type]
            raise error(key, f"{key}: {obj!r} is out of range: expected {rule} [{unit}]")
    if not _NAME.fullmatch(tool.name):
        raise error("name", f"name: {tool.name!r} is not a tool name (letters, digits, '_' or '-' only)")
    for key in ("spindle_angle", "output_torque"):
        lim = getattr(tool.limits, key)
        if len(lim) != 2 or not lim[0] < lim[1]:
            raise error(f"limits.{key}", f"limits.{key}: expected [lower, upper] with lower < upper, got {list(lim)}")
    if not _CALIBRATION_RUNS.fullmatch(tool.calibration.runs):
        raise error("calibration.runs", f"calibration.runs: {tool.calibration.runs!r} is not 'mid' or a run name")


def load_tool(name_or_path: str | Path) -> Tool:
    """Read and check a tool file (:func:`tool_path` resolves a bare name under ``configs/tools/``).

    Returns
    -------
    Tool

    Raises
    ------
    ConfigError
        No such tool; YAML syntax error; duplicate, unknown or missing key; wrong type; value out of range
        (:data:`TOOL_RANGES`); limits not [lower, upper]; a name or calibration rule that is not one. The message
        starts with ``<file>:<line>:`` and names the dotted key.
    """
    path = tool_path(name_or_path)
    data, lines = read_yaml(path)
    ctx = ErrorContext(str(path), lines)
    tool = merge_dataclass(Tool, None, data, "", ctx)
    _check(tool, ctx.error)
    return tool

