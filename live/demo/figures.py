"""The demo's figure: distal tension and elongation, true vs estimated, per experiment (matplotlib, PNG)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from estimator.capstan import phase_formula_batch
from teleop.recording.figures import pyplot, save_figure
from teleop.recording.measured_csv import read_measured_csv

__all__ = ["demo_figure"]

_COLORS = {"true": "#1f5fa8", "profile memory": "#e07b00", "paper formulas": "#7a7a7a"}


def demo_figure(csv_path: str | Path, calibration: dict, deadband: float, out_png: str | Path,
                experiments: dict[int, str]) -> Path:
    """Plot each experiment of a demo recording: T_out vs time, T_out vs T_in, elongation vs T_in.

    Parameters
    ----------
    csv_path : the slave's recording (truth columns x_out, T_out; estimate columns T_out_hat,
        elongation_hat; marker).
    calibration : ``calibration.json`` contents (``K``, ``compliance_m_per_N``) for the paper formulas.
    deadband : reversal deadband of the paper-formula baseline [N].
    out_png : where to write the PNG.
    experiments : marker -> experiment name.

    Returns
    -------
    Path of the PNG.
    """
    plt = pyplot()

    d = read_measured_csv(csv_path)
    marker = d.extra["marker"].astype(int)
    elong = d.extra.get("elongation", d.x_in - d.x_out)
    T_pf, e_pf, _ = phase_formula_batch(d.T_in, float(calibration["K"]), float(calibration["compliance_m_per_N"]),
                                        deadband=deadband)
    rows = [(m, n) for m, n in experiments.items() if np.any(marker == m)]
    assert d.T_out is not None, "demo_figure needs the truth column T_out"
    fig, axes = plt.subplots(len(rows), 3, figsize=(15, 4.2 * len(rows)), squeeze=False)
    for r, (m, name) in enumerate(rows):
        sel = marker == m
        t = d.time[sel] - d.time[sel][0]
        series = {"true": (d.T_out[sel], elong[sel]),
                  "profile memory": (d.extra["T_out_hat"][sel], d.extra["elongation_hat"][sel]),
                  "paper formulas": (T_pf[sel], e_pf[sel])}
        ax_t, ax_loop, ax_e = axes[r]
        ax_t.plot(t, d.T_in[sel], color="#bbbbbb", lw=1, label="T_in (proximal, measured)")
        for label, (T, e) in series.items():
            style = dict(color=_COLORS[label], lw=2.2 if label == "true" else 1.2,
                         ls="-" if label != "paper formulas" else "--")
            ax_t.plot(t, T, label=f"T_out {label}", **style)
            ax_loop.plot(d.T_in[sel], T, label=label, **style)
            ax_e.plot(d.T_in[sel], e * 1e3, label=label, **style)
        ax_t.set(title=f"{name} experiment: distal tension", xlabel="time [s]", ylabel="tension [N]")
        ax_loop.set(title="distal vs proximal tension", xlabel="T_in [N]", ylabel="T_out [N]")
        ax_e.set(title="tendon elongation", xlabel="T_in [N]", ylabel="elongation [mm]")
        # each legend where its panel has no data: in two columns in headroom above the tensions, below the pull line,
        # above the elongation loop's start
        ax_t.set_ylim(top=1.3 * ax_t.get_ylim()[1])
        for ax, where, cols in ((ax_t, "upper center", 2), (ax_loop, "lower right", 1), (ax_e, "upper left", 1)):
            ax.grid(alpha=0.3)
            ax.legend(fontsize=8, loc=where, ncol=cols)
    fig.suptitle("Distal estimates from proximal sensors: truth (simulated rig) vs profile memory vs paper formulas")
    return save_figure(fig, out_png, 90)
