"""The KAIST input of ``teleop analyze --kaist``: the recordings the command line names (``--kaist [DIR]``,
FILE, ``--bend``, ``--configs``, ``--columns``) and the prediction of every recording with a saved shared set
(``--shared-params``). The recordings are read by :mod:`recorded.kaist`.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

from estimator.errors import DataError
from estimator.offline.pair.fit import rmse
from estimator.offline.pair.general import predict_shared
from recorded.columns import parse_column_map
from recorded.kaist import KaistRecording, cycles, load_dir, read_kaist
from recorded.kaist_files import is_kaist_file
from teleop.errors import ConfigError
from teleop.recording.text_files import read_text

__all__ = ["parse_configs", "load_kaist_input", "predict_kaist", "format_prediction"]


def parse_configs(text: str | None) -> tuple[float, ...] | None:
    """The configurations [deg] of ``--configs N[,N...]`` (None: every one). Raises ConfigError when malformed."""
    if text is None:
        return None
    try:
        return tuple(float(v) for v in text.split(","))
    except ValueError:
        raise ConfigError(f"--configs {text}: expected bend angles N [deg] separated by commas, e.g. "
                          "0,60,120,180,240") from None


def load_kaist_input(args: argparse.Namespace) -> list[KaistRecording]:
    """The recordings of the KAIST mode: ``--kaist [DIR]`` (every configuration under DIR in either layout,
    :func:`recorded.kaist.load_dir`, or those of ``--configs``), a FILE whose name gives its configuration (its whole
    directory, :func:`recorded.kaist_files.config_of`) or another FILE with ``--bend DEG``; read with ``--columns``
    when given. Files that cannot be read get one line on stderr each and are left out.

    Raises
    ------
    DataError
        Nothing found or nothing readable (the problems named), a configuration of ``--configs`` absent, or
        FILE without ``--bend`` and not named for its configuration.
    ConfigError
        A malformed ``--columns`` map or ``--configs`` list.
    """
    cmap = parse_column_map(args.columns) if args.columns is not None else None
    if args.file is not None and (args.bend is not None or not is_kaist_file(args.file)):
        if args.bend is None:
            raise DataError(f"{args.file}: not named sine_config_<N>.txt: give its bend with --bend DEG")
        recs: list[KaistRecording] = [read_kaist(args.file, args.bend, cmap)]
        problems: list[str] = []
    else:
        directory = Path(args.file).parent if args.kaist is None else (args.kaist or None)
        recs, problems = load_dir(directory, cmap, configs=parse_configs(getattr(args, "configs", None)))
    if not recs:                     # the error names every problem, in one line
        raise DataError("no readable KAIST recording: " + "; ".join(problems))
    for line in problems:
        print(f"skipped {line}", file=sys.stderr)
    for r in recs:
        for note in r.notes:
            if note.startswith("WARNING") or "no column map" in note:
                print(f"{Path(r.source).name}: {note}", file=sys.stderr)
    return recs


def predict_kaist(recs: list[KaistRecording], params_path: str | Path) -> dict:
    """Predict every recording with the shared set saved by ``--json`` (``shared.params``); nothing
    is refitted (the pretension and the angle offset are the recording's first sample).

    Returns
    -------
    dict, JSON-ready: ``mode`` ("kaist-shared-prediction"), ``params_file``, ``model``,
    ``shared_prediction`` {str(N): {rmse_deg (every sample), rmse_cycle_deg [per complete command
    cycle], max_abs_deg, K_a, K_b, n_samples, source, import_notes}}.

    Raises
    ------
    DataError
        The parameter file is missing, a directory, not UTF-8 text, not JSON, or has no usable ``shared.params``.
    """
    path = Path(params_path)
    text = read_text(path)
    try:
        doc = json.loads(text)
        params = doc["shared"]["params"] if "shared" in doc else doc["params"]
    except (ValueError, KeyError, TypeError) as e:
        raise DataError(f"{path}: not a teleop analyze --kaist JSON with shared.params ({e})") from None
    out = {"mode": "kaist-shared-prediction", "params_file": str(path), "model": params.get("model"),
           "shared_prediction": {}}
    for rec in recs:
        try:
            th, v = predict_shared(params, rec, math.radians(rec.config_deg))
        except ValueError as e:
            raise DataError(f"{path}: {e}") from None
        err = th - rec.angle
        out["shared_prediction"][str(rec.config_deg)] = {
            "rmse_deg": math.degrees(rmse(err)), "max_abs_deg": math.degrees(float(np.max(np.abs(err)))),
            "rmse_cycle_deg": [math.degrees(rmse(err[c])) for c in cycles(rec)],
            "K_a": v.get("K_a"), "K_b": v.get("K_b"), "n_samples": len(rec), "source": rec.source,
            "import_notes": list(rec.notes)}
    return out


def format_prediction(s: dict) -> str:
    """The lines printed for ``--shared-params``: per configuration the RMSE over every sample and per
    command cycle [deg]."""
    lines = [f"shared parameter set {s['params_file']} ({(s.get('model') or {}).get('name')}): distal angle "
             "predicted from the command, the pretension and the bend alone (RMSE [deg])",
             f"{'config [deg]':>12}{'all':>7}{'max':>7}{'K_a':>6}{'K_b':>6}  per cycle"]
    for n, r in s["shared_prediction"].items():
        lines.append(f"{n:>12}{r['rmse_deg']:>7.2f}{r['max_abs_deg']:>7.2f}{r['K_a']:>6.2f}{r['K_b']:>6.2f}  "
                     + " ".join(f"{x:.2f}" for x in r["rmse_cycle_deg"]))
    return "\n".join(lines)
