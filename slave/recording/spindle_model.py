"""The recorded spindle axis's model (:class:`slave.recording.spindle.RecordedModel`) as a model file and back
(:mod:`teleop.config.model_file`; ``teleop analyze --mrd DIR --tool T --model-out OUTDIR`` writes one,
:mod:`study.mrd.model_file`).

A spindle model file: structure ``spindle``, its ``base`` the spindle pair model's parameters
(:class:`estimator.online.spindle.SpindleParams`, with the ranges of the torque fit,
:data:`estimator.offline.spindle.fit.BOUNDS`, where it has them), the spindle angle its elastic terms start from
(``theta_ref`` [rad]) and the middle of the calibration run's spindle torque band (``band_centre`` [N m], the batch
model's initial branch); when the calibration chose the centre map for the jaw torque, the extension ``centre_map``
with its constants (:class:`estimator.online.spindle_centre.CentreParams`: ``coef_<row><power>`` of (SC2), rows a, b,
c, e; the window, half-width, fallback centre, edge slopes and the held shape's range). The calibration run and the
tool are the provenance's recording and the per-cycle text's.
"""
from __future__ import annotations

import datetime as _dt
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from estimator.offline.spindle.fit import BOUNDS
from estimator.online.spindle import SpindleParams
from estimator.online.spindle_centre import CentreParams
from recorded.mrd_centre import CENTRE
from teleop.config.model_file import ModelExtension, ModelFile, ModelParameter, file_sha256, project_version

if TYPE_CHECKING:
    from slave.recording.spindle import RecordedModel

__all__ = ["SPINDLE_UNITS", "CENTRE_ROWS", "spindle_model_file", "recorded_model_dict"]

#: Units of the spindle model's parameters (estimator.online.spindle's docstring; torques at the spindle, N m).
SPINDLE_UNITS = {"rho": "-", "rho_1": "1/rad", "rho_2": "1/rad^2", "Q": "N m", "K_a": "-", "K_b": "-", "b": "N m",
                 "k_p": "N m/rad", "k_d": "N m/rad", "f": "N m", "f_s": "N m", "theta_s": "rad", "c_v": "N m s/rad",
                 "theta_c": "rad", "n_k": "-", "lam": "rad/(N m)", "theta0": "rad", "beta": "rad",
                 "theta_ref": "rad", "band_centre": "N m"}
#: The rows of the centre map's coefficients (SC2) and their units per power of d [rad^-k].
CENTRE_ROWS = (("a", "N m"), ("b", "-"), ("c", "N m"), ("e", "-"))
_SCALARS = (("theta_ref", "rad"), ("theta_z", "rad"), ("window_lo", "rad"), ("window_hi", "rad"),
            ("half_width_w0", "N m"), ("half_width_w1", "-"), ("centre0", "N m"), ("edge_slope_high", "N m/rad"),
            ("edge_slope_low", "N m/rad"), ("shape_rise_lo", "rad"), ("shape_rise_hi", "rad"),
            ("shape_fall_lo", "rad"), ("shape_fall_hi", "rad"))
_INF = float("inf")


def _centre_values(c: CentreParams) -> dict[str, float]:
    """The centre map's constants by name (module docstring); the held shape's range only when the map has one."""
    rng = c.notes.get("shape_range")
    out = {f"coef_{row}{k}": float(v) for (row, _), vals in zip(CENTRE_ROWS, np.asarray(c.coef), strict=True)
           for k, v in enumerate(vals)}
    values = (c.theta_ref, c.theta_z, *c.window, *c.half_width, c.centre0, *c.edge_slope)
    out.update((n, float(v)) for (n, _), v in zip(_SCALARS, values, strict=False))
    if rng is not None:
        out.update((n, float(v)) for (n, _), v in zip(_SCALARS[-4:], (*rng[0], *rng[1]), strict=True))
    return out


def spindle_model_file(model: RecordedModel, instrument: str, gain: dict, span_s: list[float]) -> ModelFile:
    """The model file of a recorded spindle model (module docstring); ``gain``: held-out {base, extended, unit} of
    the analysis, ``span_s`` [s]: the part of the calibration run fitted on."""
    base = {**model.pair.as_dict(), "theta_ref": float(model.theta_ref), "band_centre": float(model.band_centre)}
    ranges = {n: (SPINDLE_UNITS[n], BOUNDS[n][0], BOUNDS[n][1]) if n in BOUNDS else (SPINDLE_UNITS[n], -_INF, _INF)
              for n in base}
    exts: tuple[ModelExtension, ...] = ()
    if model.chosen == CENTRE and model.centre_map is not None:
        deg = np.asarray(model.centre_map.coef).shape[1]
        units = {f"coef_{row}{k}": u for row, u in CENTRE_ROWS for k in range(deg)}
        units.update(_SCALARS)
        exts = (ModelExtension("centre_map", tuple(ModelParameter(n, v, units[n], -_INF, _INF)
                                                   for n, v in _centre_values(model.centre_map).items())),)
    torque = "the centre map (its load level read from the spindle band centre)" if exts else \
        f"the spindle pair model ({model.pair_name})"
    return ModelFile(
        axis="spindle", instrument=instrument, structure="spindle", base=base, base_ranges=ranges, extensions=exts,
        per_cycle=f"estimator.online.spindle_estimator.SpindleEstimator (jaw angle, cables) and jaw torque from "
                  f"{torque}{', estimator.online.centre_estimator.CentreEstimator' if exts else ''}; one-run "
                  f"calibration on {Path(model.run).name}" + (f", tool {model.tool}" if model.tool else ""),
        gain=gain, provenance={"recording": Path(model.run).name, "sha256": file_sha256(model.run),
                               "span_s": [float(x) for x in span_s], "project_version": project_version(),
                               "written": _dt.datetime.now(_dt.UTC).date().isoformat()})


def recorded_model_dict(mf: ModelFile, run_dir: str | Path, tool: str = "") -> dict:
    """The recorded spindle model of a checked spindle model file, as
    :meth:`slave.recording.spindle.RecordedModel.from_dict` reads it (the inverse of :func:`spindle_model_file`);
    ``run_dir``: the folder of the played run, where the calibration run (``provenance.recording``) lies; ``tool``:
    the instrument's tool file name."""
    v = mf.base
    cmap, chosen = None, mf.model_id
    for e in mf.extensions:
        if e.id == "centre_map":
            c = e.values()
            deg = sum(1 for n in c if n.startswith("coef_a"))
            notes: dict = {"degree": deg - 1, "load_gain": "from the model file"}
            if "shape_rise_lo" in c:
                notes["shape_range"] = [[c["shape_rise_lo"], c["shape_rise_hi"]],
                                        [c["shape_fall_lo"], c["shape_fall_hi"]]]
            cmap = {"coef": [[c[f"coef_{row}{k}"] for k in range(deg)] for row, _ in CENTRE_ROWS],
                    "theta_ref": c["theta_ref"], "theta_z": c["theta_z"], "window": [c["window_lo"], c["window_hi"]],
                    "half_width": [c["half_width_w0"], c["half_width_w1"]], "centre0": c["centre0"],
                    "edge_slope": [c["edge_slope_high"], c["edge_slope_low"]], "notes": notes}
            chosen = CENTRE
    return {"chosen": chosen, "pair_name": mf.model_id,
            "pair": {k: float(v[k]) for k in SpindleParams().as_dict()}, "centre_map": cmap,
            "theta_ref": float(v["theta_ref"]), "run": str(Path(run_dir) / mf.provenance["recording"]), "tool": tool,
            "band_centre": float(v["band_centre"])}
