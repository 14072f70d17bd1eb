"""``teleop analyze --mrd DIR --tool NAME``: the tool file's constants where one calibration run cannot give them.

One run at one load shows the load only through the load gain times the load (docs/how-to/tools.md), so the
one-run calibration of the centre map takes the load gain from the tool (:mod:`teleop.config.tools`): ``--tool NAME``
is ``--calibration gain=G:RULE`` with G the tool's ``load_gain.value`` and RULE the ``--calibration`` given, else
the tool's ``calibration.runs``.
"""
from __future__ import annotations

from typing import Any

from teleop.config.tools import Tool
from teleop.errors import ConfigError

__all__ = ["add_tool_argument", "tool_calibration", "tool_entry"]


def add_tool_argument(parser) -> None:
    """``--tool NAME|PATH`` of ``teleop analyze`` (an argparse parser)."""
    parser.add_argument("--tool", metavar="NAME|PATH",
                        help="MRD mode: the instrument's tool file (configs/tools/NAME.yaml or a path, "
                             "docs/how-to/tools.md); its load gain serves the one-run calibration, so no "
                             "--calibration gain=G is needed")


def tool_calibration(calibration: str | None, tool: Tool | None) -> str | None:
    """The ``--calibration`` spec the analysis runs with: ``calibration`` unchanged without a tool, else
    ``gain=G:RULE`` (module docstring).

    Raises ConfigError when ``calibration`` gives a load gain of its own (``gain=``) beside the tool's, or is a
    segment calibration (the tool's gain serves the one-run calibration of the centre map).
    """
    if tool is None:
        return calibration
    if calibration and calibration.startswith("gain="):
        raise ConfigError(f"--calibration {calibration}: the load gain comes from --tool {tool.name}; give it once")
    if calibration and calibration.startswith("segment:"):
        raise ConfigError(f"--calibration {calibration}: --tool {tool.name} gives a load gain for a run "
                          "calibration, not for segment:")
    return f"gain={tool.load_gain.value!r}:{calibration or tool.calibration.runs}"


def tool_entry(tool: Tool) -> dict[str, Any]:
    """The summary's ``tool`` entry (JSON-ready): the tool's name, axis and every constant with its source."""
    def measured(m) -> dict[str, Any]:
        return {"value": m.value, "uncertainty": m.uncertainty, "unit": m.unit, "measured_on": m.measured_on,
                "by": m.by}
    return {"name": tool.name, "instrument": tool.instrument, "axis": tool.axis,
            "load_gain": measured(tool.load_gain), "pulley_radii_ratio": measured(tool.pulley_radii_ratio),
            "friction_exponents": {"a": measured(tool.friction_exponents.a),
                                   "b": measured(tool.friction_exponents.b)},
            "calibration": tool.calibration.runs, "attribution": tool.source.attribution,
            "used": "load_gain (the centre map's one-run calibration)"}
