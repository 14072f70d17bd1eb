"""Figures and the Markdown report of ``teleop analyze --kaist`` (summary plots only, no data).

The base pair model against the baselines (docs/results/kaist.md; :mod:`study.kaist.figures`): ``kaist_rmse.png``,
``kaist_loops.png``, ``kaist_residuals.png``. The pair diagnosis and the shared fit (:mod:`study.kaist.pair_figures`):

* ``kaist_pair_loops.png``      distal angle against the command on the test cycle, per
  configuration: measured, seed model, extended model, shared fit;
* ``kaist_pair_residuals.png``  residual (predicted - measured) against the phase of the test
  cycle, seed and extended model, per configuration;
* ``kaist_pair_tensions.png``   measured proximal tensions beside the extended model's prediction
  (the capstan-joint model predicts them from the command; the test cycle's are never fitted, cycle 1's only
  for a ``/T`` model, whose angle-only fit the tension check refused);
* ``kaist_shared.png``          K against the bend angle (shared fit, per-configuration fits,
  model-free band) and the held-out RMSE of every model per configuration;
* ``kaist_tension_angle.png``   model-free: the proximal tension difference against the distal angle,
  per configuration (the friction band and the stall before each reversal).

The recordings have no licence: only these plots and summary numbers are written.
"""
from __future__ import annotations

import math
from pathlib import Path

from study.kaist.figures import loops_figure, residuals_figure, rmse_figure, tension_angle_figure
from study.kaist.pair_figures import pair_loops_figure, pair_residuals_figure, pair_tensions_figure, shared_figure
from teleop.recording.figures import output_dir, pyplot

__all__ = ["write_kaist_figures", "write_kaist_report", "FIGURES"]

FIGURES = ("kaist_rmse.png", "kaist_loops.png", "kaist_residuals.png", "kaist_pair_loops.png",
           "kaist_pair_residuals.png", "kaist_pair_tensions.png", "kaist_shared.png", "kaist_tension_angle.png")
#: the functions drawing FIGURES, in that order (each returns its path, or None when it has nothing to draw)
_DRAWS = (rmse_figure, loops_figure, residuals_figure, pair_loops_figure, pair_residuals_figure, pair_tensions_figure,
          shared_figure, tension_angle_figure)


def write_kaist_figures(recs, details: list[dict], summary: dict, directory: str | Path,
                        option: str = "--figures") -> list[Path]:
    """Write every ``kaist_*.png`` of :data:`FIGURES` into ``directory`` (created).

    Parameters
    ----------
    recs, details, summary : what :func:`study.analyze.analyze_kaist` read and returned
    directory : output directory

    Returns
    -------
    list of Path, the files written.

    Raises
    ------
    ConfigError
        ``directory`` exists and is not a directory, or cannot be created.
    """
    plt = pyplot()
    d = output_dir(directory, option)
    paths = [draw(recs, details, summary, d, plt) for draw in _DRAWS]
    return [p for p in paths if p is not None]


def write_kaist_report(recs, details: list[dict], summary: dict, directory: str | Path) -> Path:
    """Write ``report.md`` and the figures of the KAIST analysis into ``directory``; returns its path.

    Raises
    ------
    ConfigError
        ``directory`` cannot be created.
    """
    from estimator.offline.pair.models import PAIR_EFFECTS
    from study.kaist.summary import format_kaist

    figs = write_kaist_figures(recs, details, summary, directory, option="--report")
    d = figs[0].parent
    confs = summary["configurations"]
    md = ["# KAIST antagonistic pair: what the seed model gets wrong, and the extended model", "",
          "Every model is fitted on command cycle 1 and scored on the later cycles (distal-angle RMSE [deg]); "
          "model choice uses cycle 1 only.", "",
          "| N [deg] | seed | extended | gain | shared | shared, left out | causes | extended model |",
          "|---:|---:|---:|---:|---:|---:|---|---|"]
    for c in confs:
        g, s = c["diagnosis"], c.get("shared", {})
        md.append(f"| {c['config_deg']} | {g['seed']['rmse_test_deg']:.2f} | {g['extended']['rmse_test_deg']:.2f} | "
                  f"{g['gain']:.2f} | {s.get('rmse_test_deg', math.nan):.2f} | "
                  f"{s.get('leave_one_out_rmse_test_deg', math.nan):.2f} | {', '.join(g['causes']) or 'none'} | "
                  f"`{g['extended']['model']}` |")
    causes = sorted({e for c in confs for e in c["diagnosis"]["causes"] if e in PAIR_EFFECTS})
    md += ["", "## Causes", ""]
    md += [f"* **{e}** ({PAIR_EFFECTS[e].literature}): {PAIR_EFFECTS[e].cause}. Signature: "
           f"{PAIR_EFFECTS[e].signature}." for e in causes]
    if any("unknown" in c["diagnosis"]["causes"] for c in confs):
        md.append("* **unknown**: the extended model's test error is still above 3 times the tracker noise.")
    md += ["", "## Printed summary", "", "```", format_kaist(summary), "```", ""]
    md += [f"![{p.stem}]({p.name})\n" for p in figs]
    path = d / "report.md"
    path.write_text("\n".join(md), encoding="utf-8")
    return path
