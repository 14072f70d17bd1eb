"""The diagnosed single-tendon model's gain, measured live: for every catalogue effect with a rig switch and a
per-cycle form, a simulated session with that effect switched on (``rig.simulated.effects``), ``teleop analyze
--model-out`` on its recording, then the same session with the model.

Per effect: :func:`study.scenarios.record` runs the simulated rig (quasi-static distributed Coulomb tendon, 100
elements, tissue load) through its motion protocol at 1 kHz with the effect's switch on at ``--level`` of its
realistic range, and writes the recording (measured-data CSV: T_in, x_in and the distal load cell's T_out and
position x_out, with their noise). ``teleop analyze FILE --model-out OUT.yaml --json OUT.json`` diagnoses it (a
subprocess: the command a lab runs). The session is then run again through the slave's per-cycle path, the rig's
proximal readings sample by sample into three estimators:

* the slave's base estimator, what it runs without a model file (:class:`estimator.online.distal.DistalEstimator` on
  the raw readings, on the base model the diagnosis refitted on the training block);
* the model file's estimator (:class:`slave.tendon_model.ModelRunner`, the tendon axis's code; its fallbacks
  counted);
* the model's base form: the same model file with every extension removed (its K, L/EA, route and node grid, the
  same averaging of the readings, the same :class:`~estimator.online.extended.ExtendedEstimator` and runner).

The session is position commanded: the estimate is not in the rig's loop, so the same command gives the same
readings.

Scored on the diagnosis's test block (the last ~40 % of the session, never fitted on), against the measured distal
load cell, like the offline held-out errors: distal-tension RMSE [N] live of the three; the gain over the slave's
base estimator (what the operator's hand feels); the extension's gain over its own base form, live and offline (the
base form's batch prediction, :func:`offline_form`, against the diagnosis's extended held-out error), and their ratio
on the effect's primary signal (the distal position RMSE [um] for the effects whose primary signal it is). The ratio
compares like with like: both sides run the same parameters with and without the extension, where the slave's base
estimator differs from the model's form in more than the extension (raw 1 kHz readings, its own fit) and the
diagnosis's held-out gain (beside it in brackets) is over a base refitted without the extension, whose K and L/EA
absorb part of the effect.
Prints a Markdown table and the command line with its conditions; never fails on the figures.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import math
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from estimator.data import noise_level
from estimator.offline.diagnosis.fit import prepare
from estimator.offline.effects.catalogue import predict, rig_switches
from estimator.offline.effects.types import route_shape, route_values
from estimator.online.distal import DistalEstimator
from estimator.sheath import SheathModel
from slave.tendon_model import ModelRunner, check_tendon, tendon_model_estimator
from study.scenarios import record
from teleop.config.model_file import load_model
from teleop.recording.measured import write_measured_csv

#: the velocity smoothing of the live estimators [s] (the default config's estimator.rate_time_constant)
RATE_TIME_CONSTANT = 0.02


def _rmse(a: np.ndarray) -> float:
    return float(np.sqrt(np.mean(a * a)))


def live_run(rec, diagnosis: dict, model_path: Path) -> dict:
    """The session through the slave's base estimator, the model file's and the model's base form, per cycle:
    test-block RMSE [N], [m] of each, fallbacks of the two model runners."""
    d = rec.data
    sigma = noise_level(np.asarray(d.T_in))
    mf = load_model(model_path)
    check_tendon(mf, sigma)
    rate = (len(d.time) - 1) / float(d.time[-1] - d.time[0])
    runner = ModelRunner(mf, tendon_model_estimator(mf, sigma, RATE_TIME_CONSTANT, rate), "bench")
    bare = dataclasses.replace(mf, extensions=())          # the model's base form: every extension removed
    form = ModelRunner(bare, tendon_model_estimator(bare, sigma, RATE_TIME_CONSTANT, rate), "bench base form")
    b = diagnosis["base_model"]
    r = route_values(b["values"])
    shape = route_shape(257, *r) if r else None
    base = DistalEstimator(SheathModel(K=b["values"]["K"], compliance=b["compliance"], wrap_shape=shape),
                           n_nodes=int(mf.base.get("n_nodes", 32)), tension_noise=sigma,
                           rate_time_constant=RATE_TIME_CONSTANT)
    n = len(d.time)
    out = np.empty((n, 6))
    t0 = time.perf_counter()
    for k in range(n):
        T, x, t = float(d.T_in[k]), float(d.x_in[k]), float(d.time[k])
        s = base.step(T, x, t)
        m = runner.step(T, x, t, s)
        f = form.step(T, x, t, s)
        out[k] = (s.T_out, f.T_out, m.T_out, s.x_out, f.x_out, m.x_out)
    per_step = (time.perf_counter() - t0) / n
    test = np.asarray(d.time) >= diagnosis["split"]["time_s"]
    T_out, x_out = np.asarray(d.T_out)[test], np.asarray(d.x_out)[test]
    return {"T_base": _rmse(out[test, 0] - T_out), "T_form": _rmse(out[test, 1] - T_out),
            "T_ext": _rmse(out[test, 2] - T_out), "x_base": _rmse(out[test, 3] - x_out),
            "x_form": _rmse(out[test, 4] - x_out), "x_ext": _rmse(out[test, 5] - x_out),
            "fallbacks": runner.fallbacks, "form_fallbacks": form.fallbacks, "cycles": runner.cycles,
            "us_per_step": 1e6 * per_step}


def offline_form(rec, diagnosis: dict, model_path: Path) -> dict:
    """The model's base form run offline, as ``teleop analyze`` scores a model: the batch prediction on the recording
    block-averaged to the model's fitted rate, interpolated to the measured samples, RMSE [N], [m] on the test block
    (the same call with the model's extensions gives the diagnosis's extended held-out errors); and the base form and
    the model on the proximal readings alone (``prox_*``): the batch prediction without the rule that starts a
    whole-tendon slide where the measured distal end is seen moving, the inputs the live loop has."""
    mf = load_model(model_path)
    d = rec.data
    s = prepare(d, n_nodes=int(mf.base.get("n_nodes", 32)), target_rate=float(mf.base["rate_hz"]))
    values = mf.values()
    compliance = values.pop("compliance")
    test = np.asarray(d.time) >= diagnosis["split"]["time_s"]

    def scored(effects: list[str], series) -> tuple[float, float]:
        p = predict(effects, values, series, compliance=compliance)
        return (_rmse(np.interp(d.time, series.time, p.T_out)[test] - np.asarray(d.T_out)[test]),
                _rmse(np.interp(d.time, series.time, p.x_out)[test] - np.asarray(d.x_out)[test]))

    out = dict(zip(("off_T_form", "off_x_form"), scored([], s), strict=True))
    alone = dataclasses.replace(s, slide=None, slide_travel=0.0)     # no measured distal end: the live loop's inputs
    out.update(zip(("prox_T_form", "prox_x_form"), scored([], alone), strict=True))
    out.update(zip(("prox_T_ext", "prox_x_ext"), scored([e.id for e in mf.extensions], alone), strict=True))
    return out


def one(key: str, seed: int, level: float, duration: float, work: Path) -> dict:
    """One effect: record, analyze --model-out, run live. Returns the row."""
    rec = record(key, seed=seed, level=level, duration=duration)
    csv, yaml_out, js = work / f"{key}.csv", work / f"{key}.model.yaml", work / f"{key}.json"
    write_measured_csv(csv, rec.data, overwrite=True)
    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, "-m", "live.cli", "analyze", str(csv), "--model-out", str(yaml_out),
                        "--json", str(js)], capture_output=True, text=True)
    row = {"effect": key, "truth": rec.truth["parameters"], "analyze_s": time.perf_counter() - t0}
    if p.returncode != 0:
        return {**row, "error": (p.stderr.strip().splitlines() or ["?"])[-1]}
    diag = json.loads(js.read_text())
    row.update({"cause": diag["cause"], "effects": diag["model"]["effects"], "primary": diag["primary_signal"],
                "off_T_base": diag["base"]["rmse_T_out_N"], "off_T_ext": diag["extended"]["rmse_T_out_N"],
                "off_x_base": diag["base"]["rmse_x_out_m"], "off_x_ext": diag["extended"]["rmse_x_out_m"]})
    try:
        row.update(live_run(rec, diag, yaml_out))
        row.update(offline_form(rec, diag, yaml_out))
    except Exception as e:          # a model the slave refuses: reported in the table, never hidden
        row["error"] = f"{type(e).__name__}: {e}"
    return row


def _ratio(live: float, off: float) -> str:
    return f"{live / off:.2f}" if off > 0 else "-"


def table(rows: list[dict]) -> str:
    """The Markdown table of the rows (module docstring): RMSE of the slave's base estimator, the model's base form
    and the model; the gain over the slave's base; the gain over the base form live and offline and their ratio."""
    lines = ["| effect (rig switch) | diagnosis names | T_out RMSE live: slave base / base form / extended [N] | "
             "gain over slave base [N] | gain over base form live / offline (offline over the refitted base) [N] | "
             "live / offline (primary signal): as the diagnosis scores / proximal readings alone | "
             "x_out RMSE live: slave base / base form / extended [um] | x_out gain over base form live / offline "
             "[um] | fallbacks extended / base form |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if "T_base" not in r:
            lines.append(f"| `{r['effect']}` | {'+'.join(r.get('effects', [])) or r.get('cause', '-')} | "
                         f"not run: {r.get('error', '-')} | | | | | | |")
            continue
        g_live, g_off = r["T_form"] - r["T_ext"], r["off_T_form"] - r["off_T_ext"]
        gx_live, gx_off = 1e6 * (r["x_form"] - r["x_ext"]), 1e6 * (r["off_x_form"] - r["off_x_ext"])
        gp, gxp = r["prox_T_form"] - r["prox_T_ext"], 1e6 * (r["prox_x_form"] - r["prox_x_ext"])
        ratio = (f"{_ratio(gx_live, gx_off)} / {_ratio(gx_live, gxp)} (x_out)" if r["primary"] == "x_out"
                 else f"{_ratio(g_live, g_off)} / {_ratio(g_live, gp)}")
        refit = r["off_T_base"] - r["off_T_ext"]
        lines.append(f"| `{r['effect']}` | {'+'.join(r['effects']) or 'none'} | "
                     f"{r['T_base']:.4f} / {r['T_form']:.4f} / {r['T_ext']:.4f} | {r['T_base'] - r['T_ext']:+.4f} | "
                     f"{g_live:+.4f} / {g_off:+.4f} ({refit:+.4f}) | {ratio} | "
                     f"{1e6 * r['x_base']:.2f} / {1e6 * r['x_form']:.2f} / {1e6 * r['x_ext']:.2f} | "
                     f"{gx_live:+.2f} / {gx_off:+.2f} | {r['fallbacks']} / {r['form_fallbacks']} of {r['cycles']} |")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--level", type=float, default=0.7, help="position in each effect's realistic range [0, 1]")
    ap.add_argument("--duration", type=float, default=60.0, help="session length [s]")
    ap.add_argument("--effects", default=None, help="comma-separated rig switch keys (default: every one)")
    ap.add_argument("--json", default=None, help="write the rows as JSON here")
    a = ap.parse_args()
    switches = rig_switches()
    keys = a.effects.split(",") if a.effects else list(switches)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for key in keys:
            has, why = switches[key].per_cycle
            if not has:
                print(f"{key}: no per-cycle form ({why}); not run", flush=True)
                continue
            rows.append(r := one(key, a.seed, a.level, a.duration, Path(tmp)))
            print(json.dumps({k: v for k, v in r.items() if k != "truth"}, default=float), flush=True)
    print(f"\n`python benchmarks/bench_model_live.py --seed {a.seed} --level {a.level} --duration {a.duration:g}`: "
          f"one {a.duration:g} s simulated session per effect (study.scenarios protocol, 1 kHz, effect at level "
          f"{a.level} of its realistic range), scored on the diagnosis's held-out test block against the measured "
          "distal load cell and position sensor\n")
    print(table(rows))
    if a.json:
        Path(a.json).write_text(json.dumps(rows, indent=1, default=float) + "\n")
    if any(math.isnan(r.get("T_ext", 0.0)) for r in rows):
        print("a live estimate was not finite", file=sys.stderr)


if __name__ == "__main__":
    main()
