"""Markdown report with figures of a diagnosis (:func:`estimator.offline.diagnosis.selection.diagnose`).

``write_report(result, data, out_dir)`` writes ``out_dir/report.md`` and four PNG figures (matplotlib,
Agg canvas, no display needed):

* ``residuals_time.png``   residual of T_out and x_out vs time, base and extended model, split marked;
* ``residuals_by.png``     held-out residuals vs sliding speed |dx_in/dt|, vs T_in and by phase;
* ``loops.png``            T_out vs T_in and elongation x_in - x_out vs T_in, measured beside the base
                           and the extended model (held-out block);
* ``candidates.png``       validation score S of every extension and the price of its parameters.

The report names the cause, the physical explanation and the signature from the catalogue
(:mod:`estimator.offline.effects.catalogue`), the held-out errors, the gain and the fitted parameters with units.
"""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from estimator.data import MeasuredData
from estimator.offline.diagnosis.fit import predictions
from estimator.offline.diagnosis.result import Diagnosis, as_diagnosis
from estimator.offline.effects.catalogue import CATALOGUE
from estimator.phase import Phase

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["write_report", "format_summary", "split_text"]

_MAX_POINTS = 20000
_SIG = (("T_out", "N", 1.0, "N"), ("x_out", "m", 1e6, "um"))   # name, SI unit, plot scale, plot unit


def _figure(width: float, height: float, **margins: float) -> Figure:
    """A figure with fixed margins [share of the figure] (a layout engine would draw every figure twice: on a long
    recording that doubles the report's time, not its content)."""
    from matplotlib.figure import Figure  # lazy: `teleop analyze` without --report does not load matplotlib

    fig = Figure(figsize=(width, height))
    fig.subplots_adjust(**margins)
    return fig


def _save(fig: Figure, path: Path) -> str:
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig)
    fig.savefig(path, dpi=110)
    return path.name


def _every(n: int) -> slice:
    return slice(None, None, max(1, n // _MAX_POINTS))


def _fig_time(data, pred, t_split, path) -> str:
    sigs = [s for s in _SIG if getattr(data, s[0]) is not None]
    h = 2.6 * len(sigs) + 0.6
    fig = _figure(11, h, left=0.08, right=0.98, top=1 - 0.2 / h, bottom=0.55 / h, hspace=0.25)
    ev = _every(len(data))
    for i, (name, _, k, unit) in enumerate(sigs):
        ax = fig.add_subplot(len(sigs), 1, i + 1)
        y = getattr(data, name)
        ax.plot(data.time[ev], k * (pred[f"{name}_base"] - y)[ev], lw=0.5, label="base model")
        ax.plot(data.time[ev], k * (pred[f"{name}_ext"] - y)[ev], lw=0.5, label="extended model")
        ax.axvline(t_split, color="k", ls="--", lw=1)
        ax.text(t_split, ax.get_ylim()[1], "  held out ->", va="top", fontsize=8)
        ax.set_ylabel(f"{name} residual [{unit}]")
        ax.legend(loc="lower left", fontsize=8)
    ax.set_xlabel("time [s]")
    return _save(fig, path)


def _fig_by(data, pred, held, path) -> str:
    sigs = [s for s in _SIG if getattr(data, s[0]) is not None]
    h = 2.8 * len(sigs) + 0.6
    fig = _figure(12, h, left=0.07, right=0.99, top=1 - 0.45 / h, bottom=0.75 / h, hspace=0.55, wspace=0.3)
    ev = _every(int(held.sum()))
    speed = np.abs(pred["velocity"][held])[ev] * 1e3
    T_in = data.T_in[held][ev]
    phase = pred["phase"][held][ev]
    codes = [int(p) for p in Phase]
    for i, (name, _, k, unit) in enumerate(sigs):
        y = getattr(data, name)[held][ev]
        rb = k * (pred[f"{name}_base"][held][ev] - y)
        re = k * (pred[f"{name}_ext"][held][ev] - y)
        for j, (x, label) in enumerate(((speed, "sliding speed |dx_in/dt| [mm/s]"), (T_in, "T_in [N]"))):
            ax = fig.add_subplot(len(sigs), 3, 3 * i + j + 1)
            ax.plot(x, rb, ".", ms=1, alpha=0.4, label="base")
            ax.plot(x, re, ".", ms=1, alpha=0.4, label="extended")
            ax.set_xlabel(label)
            ax.set_ylabel(f"{name} residual [{unit}]")
        ax = fig.add_subplot(len(sigs), 3, 3 * i + 3)
        for off, r, lab in ((-0.18, rb, "base"), (0.18, re, "extended")):
            rms = [np.sqrt(np.mean(r[phase == c] ** 2)) if np.any(phase == c) else 0.0 for c in codes]
            ax.bar(np.arange(len(codes)) + off, rms, width=0.36, label=lab)
        ax.set_xticks(range(len(codes)), [Phase(c).label for c in codes], rotation=30, fontsize=7)
        ax.set_ylabel(f"rms {name} residual [{unit}]")
        ax.set_ylim(top=1.3 * ax.get_ylim()[1])         # headroom: the legend sits above the bars, not over one
        ax.legend(fontsize=7, ncol=2, loc="upper center")
    fig.suptitle("held-out residuals by sliding speed, tension and phase")
    return _save(fig, path)


def _fig_loops(data, pred, held, path) -> str:
    panels = []
    if data.T_out is not None:
        panels.append(("T_out [N]", data.T_out, pred["T_out_base"], pred["T_out_ext"]))
    if data.x_out is not None:
        e = data.x_in - data.x_out
        panels.append(("elongation x_in - x_out [mm]", 1e3 * e, 1e3 * (data.x_in - pred["x_out_base"]),
                       1e3 * (data.x_in - pred["x_out_ext"])))
    h = 3.6 * len(panels)
    fig = _figure(12, h, left=0.07, right=0.99, top=1 - 0.6 / h, bottom=0.5 / h, hspace=0.45, wspace=0.3)
    ev = _every(int(held.sum()))
    T_in = data.T_in[held][ev]
    for i, (label, meas, base, ext) in enumerate(panels):
        for j, (y, title) in enumerate(((meas, "measured"), (base, "base model"), (ext, "extended model"))):
            ax = fig.add_subplot(len(panels), 3, 3 * i + j + 1)
            ax.plot(T_in, y[held][ev], lw=0.4)
            ax.set_title(title, fontsize=9)
            ax.set_xlabel("T_in [N]")
            ax.set_ylabel(label)
    fig.suptitle("loops on the held-out block: measured beside simulated")
    return _save(fig, path)


def _fig_candidates(result: Diagnosis, path) -> str:
    """Each candidate's validation score S (log axis, base = 1) and the price of its parameters, best at the top;
    the axis starts below the best score, so every bar, the best included, has a visible length."""
    c = result.candidates
    ids = sorted(c, key=lambda k: c[k].score, reverse=True)
    scores = np.array([max(c[k].score, 1e-6) for k in ids])
    h = 1.3 + 0.22 * len(ids)
    fig = _figure(10, h, left=0.2, right=0.74, top=1 - 0.35 / h, bottom=0.6 / h)
    ax = fig.add_subplot(1, 1, 1)
    left = float(scores.min()) / 3.0 if scores.size else 0.1
    ax.barh(ids, scores - left, left=left, color=["C2" if c[k].accepted else "C0" for k in ids],
            label="score S (green: accepted)")
    ax.barh(ids, [c[k].penalised_score - c[k].score for k in ids], left=scores, color="0.8",
            label="price of the parameters")
    ax.axvline(1.0, color="k", lw=1)
    ax.set_xscale("log")
    ax.set_xlim(left, max(2.0, float(max((c[k].penalised_score for k in ids), default=1.0)) * 1.2))
    ax.set_xlabel("validation score S (base = 1; training block only), accepted below 1 with the price")
    ax.set_title(f"candidate extensions: cause {result.cause}")
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    return _save(fig, path)


def _fmt(v, unit: str) -> str:
    if v is None:
        return "-"
    if unit == "m":
        return f"{v * 1e6:.2f} um"
    return f"{v:.4g} {unit}"


def split_text(result: Diagnosis | dict) -> str:
    """One sentence on which samples were used for what (fit/validation folds, training, test)."""
    sp = as_diagnosis(result).split
    tr, te = sp["train"], sp["test"]
    dur = te["time_s"][1] - te["time_s"][0]
    f0, f1 = sp["folds"]
    return (f"Model choice on the training block (samples {tr['index'][0]}-{tr['index'][1] - 1}, t = "
            f"{tr['time_s'][0]:.2f}-{tr['time_s'][1]:.2f} s, {sp['train_fraction']:.0%} of the recording) by two "
            f"time-blocked folds (fit t < {f0['fit']['time_s'][1]:.1f} s, validate after; fit t > "
            f"{f1['fit']['time_s'][0]:.1f} s, validate before); held out for the reported errors: the "
            f"{te['n_samples']} samples from t = {te['time_s'][0]:.2f} s ({dur:.1f} s), used once."
            + ("" if len(sp.get("judged_folds", ())) != 1 else f" Judged on the {sp['judged_folds'][0]}."))


def _stick_slip_line(r: Diagnosis) -> str:
    """Why the stick-slip reading named stiction (docs/concepts/diagnosis.md, the stick-slip rule)."""
    slip, st = r.stick_slip, r.settings
    if slip.weak:
        why = (f"below the bound {st['stick_slip_ratio']:g} but at least {st['stick_slip_weak']:g}, and the "
               f"stiction extension scores {r.candidates['stiction'].score:.2f} (below "
               f"{st['stick_slip_weak_score']:g}: two weak signs together)")
    else:
        why = f"bound {st['stick_slip_ratio']:g}"
    models = ("the models alone named nothing" if not slip.overruled else
              f"the models named {', '.join(slip.overruled)}, which left structure it does not explain "
              "and has no stick-slip")
    return (f"named by the stick-slip check: the proximal tension is {slip.ratio:.2f} x rougher in "
            f"steady moves than in holds ({why}); {models}; r_s below is the quasi-static extension's fit, which "
            "reads a stick-slip's static peak low (docs/concepts/diagnosis.md)")


def format_summary(result: Diagnosis | dict) -> str:
    """A few plain-text lines: cause, gain, held-out errors (for a terminal)."""
    r = as_diagnosis(result)
    b, e = r.base, r.extended
    more = f"  (all: {', '.join(r.causes)})" if len(r.causes) > 1 else ""
    eq = f"  (or equivalently: {', '.join(r.equivalent)})" if r.equivalent else ""
    lines = [f"cause: {r.cause}{more}{eq}", f"held-out gain on {r.primary_signal}: {r.gain:.2f}"]
    if r.stick_slip.named:
        lines.append(_stick_slip_line(r))
    if r.settings.get("pair_rule"):
        lines.append(f"two causes at once: named by the step {r.settings['pair_rule']} after the forward selection "
                     "(docs/concepts/diagnosis.md)")
    rest = r.rest_offset
    if rest.named and rest.reads is not None:
        ch = rest.reads.split(":")[1]
        lines.append(f"named by the initial rest: {ch} reads {_fmt(getattr(rest, f'{ch}_m'), 'm')} there, where "
                     "positions are zeroed and no physical effect moves them; the models alone named nothing "
                     "(docs/concepts/diagnosis.md)")
    for name, unit in (("T_out", "N"), ("x_out", "m")):
        key = f"rmse_{name}_{unit}"
        if b.get(key) is not None:
            lines.append(f"held-out rmse {name}: base {_fmt(b[key], unit)} -> extended {_fmt(e[key], unit)}")
    return "\n".join(lines)


def write_report(result: Diagnosis | dict, data: MeasuredData, out_dir: str | Path) -> Path:
    """Write ``report.md`` and its figures for one diagnosis into ``out_dir`` (created if needed).

    Parameters
    ----------
    result : Diagnosis or dict
        What :func:`estimator.offline.diagnosis.selection.diagnose_recording` (or, as JSON,
        :func:`estimator.offline.diagnosis.selection.diagnose`) returned for ``data``.
    data : MeasuredData
        The recording that was diagnosed.
    out_dir : str or Path

    Returns
    -------
    Path of report.md.

    Raises
    ------
    OSError
        ``out_dir`` cannot be created or written.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    r = as_diagnosis(result)
    pred = predictions(r.to_json(), data)
    t_split = r.split["time_s"]
    held = data.time >= t_split
    figs = {"residuals over time": _fig_time(data, pred, t_split, out / "residuals_time.png"),
            "residuals by speed, tension and phase": _fig_by(data, pred, held, out / "residuals_by.png"),
            "loops, measured beside simulated": _fig_loops(data, pred, held, out / "loops.png"),
            "candidates": _fig_candidates(r, out / "candidates.png")}
    md = [f"# Diagnosis of {data.source}", "", "```", format_summary(r), "```", "", *_cause_text(r.cause)]
    md += _tables(r)
    md += ["", split_text(r), "Score S: validation (rmse / noise floor)^2 summed over the measured distal "
           "signals, relative to the base model, the worse of the two folds; an extension is accepted when S plus "
           f"{r.settings['penalty_per_parameter']} per parameter stays below 1.", ""]
    for title, name in figs.items():
        md += [f"## {title.capitalize()}", "", f"![{title}]({name})", ""]
    path = out / "report.md"
    path.write_text("\n".join(md), encoding="utf-8")
    return path


def _cause_text(cause: str) -> list[str]:
    """The paragraph on the cause: the catalogue's explanation and signature, or what none and unknown mean."""
    md: list[str] = []
    if cause in CATALOGUE:
        e = CATALOGUE[cause]
        md += [f"**{cause}** ({e.literature}): {e.cause}.", "", f"Signature in data: {e.signature}.", ""]
    elif cause == "none":
        md += ["**none**: the base model (profile memory, K and L/EA) explains the held-out data within the "
               "noise; no extension earns its parameters.", ""]
    else:
        md += ["**unknown**: structure is left in the held-out residual (rmse well above the noise floor) "
               "that no extension of the catalogue explains.", ""]
    return md


def _tables(r: Diagnosis) -> list[str]:
    """The fitted parameters and the candidates as markdown tables."""
    md = ["## Fitted parameters", "", "| parameter | value | unit | from |", "|---|---|---|---|"]
    md += [f"| {k} | {p['value']:.6g} | {p['unit']} | {p['effect']} |" for k, p in r.parameters.items()]
    md += ["", "## Candidates (model choice on the training block)", "",
           "| extension | score S | S + price | validation rmse T_out [N] | validation rmse x_out [um] | accepted |",
           "|---|---|---|---|---|---|"]
    g = (lambda v: "-" if v is None else f"{v:.3f}")  # noqa: E731
    for k, c in sorted(r.candidates.items(), key=lambda kv: kv[1].score):
        x = c.validation.get("rmse_x_out_m")
        md.append(f"| {k} | {c.score:.3f} | {c.penalised_score:.3f} | {g(c.validation.get('rmse_T_out_N'))} | "
                  f"{'-' if x is None else f'{x * 1e6:.2f}'} | {'yes' if c.accepted else ''} |")
    if r.screened:
        listed = ", ".join(f"{k} (share {v['share']:.4f}, price {v['price']:.2f})"
                           for k, v in sorted(r.screened.items()))
        md += ["", "Screened at the base, not fitted (their linearised share of the base's residual is below "
               f"{r.settings['screen_share']:.2f} of their price): {listed}."]
    if r.equivalent:
        md += ["", f"Equivalent explanations (the same outputs, not separable from these signals): "
               f"{', '.join(r.equivalent)}."]
    return md
