"""The printed summary of ``teleop analyze --kaist``: the tables, one string (used by the CLI and the report)."""
from __future__ import annotations

import math

import numpy as np

__all__ = ["format_kaist"]


def _fmt_causes(causes: list[str]) -> str:
    return ", ".join(causes) if causes else "none"


def _pm(row: dict) -> str:
    """' +- std [lo-hi]' of a figure's bootstrap (``rmse_test_bootstrap``), '' when there is none."""
    b = row.get("rmse_test_bootstrap")
    return "" if not b else f" +- {b['std_deg']:.2f} [{b['ci95_deg'][0]:.2f}-{b['ci95_deg'][1]:.2f}]"


def format_kaist(s: dict) -> str:
    """The tables printed for the KAIST analysis: the pair diagnosis per configuration (held-out
    angle RMSE [deg] of the seed model, the extended model, the shared fit and its leave-one-out
    prediction; the causes), the shared parameters, then the Finding 1 baselines."""
    lines = ["KAIST antagonistic pair: distal angle, calibrated on command cycle 1, tested on cycle 2 (RMSE [deg])",
             f"{'config [deg]':>12}{'seed':>7}{'extended':>10}{'gain':>6}{'shared':>8}{'LOCO':>7}"
             f"{'T_in [N]':>9}  causes (extended model)"]
    for c in s["configurations"]:
        d, sh = c["diagnosis"], c.get("shared", {})
        t = d["extended"]["rmse_T_in_N"]
        lines.append(f"{c['config_deg']:>12}{d['seed']['rmse_test_deg']:>7.2f}{d['extended']['rmse_test_deg']:>10.2f}"
                     f"{d['gain']:>6.2f}{sh.get('rmse_test_deg', math.nan):>8.2f}"
                     f"{sh.get('leave_one_out_rmse_test_deg', math.nan):>7.2f}{t if t is not None else math.nan:>9.2f}"
                     f"  {_fmt_causes(d['causes'])} ({d['extended']['model']})")
    lines.append("extended: the model the diagnosis chose; shared: one parameter set for all configurations with "
                 "K = K0 + mu N; LOCO: refitted without that configuration; T_in: the extended model's prediction "
                 "of the proximal tensions on the test cycle (fitted on cycle 1 only for '/T' models, whose angle-only "
                 "fit the tension check refused)")
    unc = [(c["config_deg"], _pm(c["diagnosis"]["extended"])) for c in s["configurations"]]
    if any(u for _, u in unc):
        lines.append("extended, test RMSE +- bootstrap std [95 % interval] (training blocks redrawn, refitted): "
                     + "; ".join(f"{n}: {c['diagnosis']['extended']['rmse_test_deg']:.2f}{u}"
                                 for (n, u), c in zip(unc, s["configurations"], strict=False)))
    if "shared" in s:
        sh = s["shared"]
        for name, m in sh["models"].items():
            p = ", ".join(f"{k} {v['value']:.3g}" for k, v in m["params"].items())
            rows = " ".join(f"{r['rmse_test_deg']:.2f}" for r in m["configurations"])
            lines.append(f"shared {name:<28} test RMSE {m['rmse_test_deg']:.2f} (per configuration {rows}): {p}")
        for name, rows in sh["leave_one_out"].items():
            lines.append(f"leave one out, {name:<20} " + " ".join(f"{r['rmse_test_deg']:.2f}{_pm(r)}" for r in rows))
        e6 = sh["E6"]
        lines.append(f"E6 (K grows with the bend): score {e6['score']:.3f} against mu = 0, price {e6['price']:.3f} -> "
                     f"{'accepted' if e6['accepted'] else 'rejected'}; mu = {sh['mu']:.3f} /rad")
        for name, c in sh["choice"]["candidates"].items():
            per = " ".join(f"{x:.2f}" for x in c["loco_train_rmse_deg"])
            pr = "" if c.get("price") is None else f", price {c['price']:.3f}"
            lines.append(f"choice (leave one out, training cycles) {name:<28} {per} (rms {c['rms_deg']:.2f}{pr})"
                         f"{' <- chosen' if name == sh['chosen'] else ''}")
        lines.append("shared set for new configurations (" + sh["params"]["model"]["name"] + ", refitted on every "
                     "sample; bootstrap std over cycles):")
        lines.append("  " + ", ".join(f"{k} {v['value']:.4g}" + (f" +- {v['std']:.2g}" if "std" in v else "")
                                      + ("" if v["unit"] in ("", "-") else f" {v['unit']}")
                                      for k, v in sh["params"]["values"].items()))
        bc = (sh["uncertainty"]["bootstrap"] or {}).get("correlation") or sh["uncertainty"]["local_correlation"]
        strong = [f"{a}/{b} {bc['matrix'][i][j]:+.2f}" for i, a in enumerate(bc["names"])
                  for j, b in enumerate(bc["names"]) if j > i and abs(bc["matrix"][i][j]) >= 0.8]
        lines.append("  correlations |r| >= 0.8: " + (", ".join(strong) if strong else "none"))
    lines += ["", "Finding 1 baselines (RMSE [deg]; dead zone after a reversal [deg of command]; K_release: capstan "
              "band from tension ratios; K_force: K of the force-path fit)",
              f"{'config [deg]':>12}{'force path':>12}{'linear':>9}{'lin+play':>10}{'dead zone':>11}{'K_release':>11}"
              f"{'K_force':>9}"]
    for c in s["configurations"]:
        m = {k: v["rmse_test_deg"] for k, v in c["models"].items()}
        dz = [z["command_travel_deg"] for z in c["dead_zones"] if z["command_travel_deg"] is not None]
        kr = [z["K_release"] for z in c["dead_zones"] if z["K_release"] is not None]
        lines.append(f"{c['config_deg']:>12}{m['force path']:>12.2f}{m['linear map']:>9.2f}"
                     f"{m['linear map + play']:>10.2f}"
                     f"{np.mean(dz) if dz else math.nan:>11.1f}{np.mean(kr) if kr else math.nan:>11.2f}"
                     f"{c['models']['force path']['params']['K']:>9.2f}")
    if "trend" in s:
        lines.append(f"K_release = {s['trend']['K_release_at_0']:.2f} + {s['trend']['K_release_per_rad']:.3f} "
                     "* configuration angle [rad]")
    return "\n".join(lines)
