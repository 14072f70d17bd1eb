"""Importer for the MRD Lab da Vinci tool characterisation runs (``XY.TXT``, torque and angle at both ends).

Data: the MRD folder of the data folder (``mrd-davinci`` or a clone of the source repository,
``TSM_TELEOP_DATA``; :mod:`recorded.mrd_files` finds the runs in either layout, docs/how-to/get-the-data.md; MRD
Lab data repository, University of Minnesota; O'Neill, Stephens, Kowalewski, IEEE RA-L 3(4):3027-3034, 2018;
ODbL 1.0 / DbCL 1.0).
Lines starting with ``%`` are a header (hand-edited, not trusted); then comma-separated rows of 10
numbers at 1 kHz:

==== ==================================== ======================= ============================
col  meaning                              file unit               here
==== ==================================== ======================= ============================
0    time                                 s (header says ms)      ``time`` [s]
1    spindle (proximal) CUI encoder       counts, 8192 / rev      ``theta_p`` [rad]
2    spindle (proximal) Futek torque      counts, 3.9811e-5 N m   ``tau_p`` [N m]
4    jaw (distal) Maxon encoder           counts, 4000 / rev      ``theta_d`` [rad] (sign flipped)
5    jaw (distal) Futek torque            counts, 3.9811e-5 N m   ``tau_d`` [N m] (sign flipped)
6    front-end (load motor) command       A                       ``load_command`` [A]
==== ==================================== ======================= ============================

The front-end encoder and torque sensor face the jaw from the other side: their signs are flipped so
that a positive spindle rotation and torque give a positive jaw rotation and torque (the data show
theta_d = -0.92 theta_p + const before the flip). At BOTH ends a positive torque turns the shaft
towards negative angles (the spindle torque is lower while its angle rises: friction opposes the
motion), so the power into the tool is -tau_p omega_p; the model is driven by the torque and its
signed parameters absorb this (the cable stretch shows as lam < 0, see estimator.online.spindle). The sine frequency is
read from the spindle angle (:func:`sine_frequency`), the load level from the rank of the run's mean front-end command
(equal to the file name's Y on the shipped folder), not from the header.
"""
from __future__ import annotations

import fnmatch
import math
import os
import re
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from estimator.errors import DataError
from recorded.mrd_files import find_mrd_folder
from teleop.recording.text_files import read_text

__all__ = [
    "ATTRIBUTION", "MrdRun", "read_mrd", "load_mrd_dir", "sine_frequency", "N_COLUMNS", "TORQUE_NM_PER_COUNT",
    "PROXIMAL_COUNTS_PER_REV", "stroke_groups", "stroke_window", "runs_selection", "STROKE_OVERLAP",
    "DISTAL_COUNTS_PER_REV", "DISTAL_SIGN", "MAX_MAGNITUDE", "values_error",
]

#: Keep with every report (SOURCE.md: ODbL 1.0 / DbCL 1.0).
ATTRIBUTION = ("MRD Lab data repository, University of Minnesota; O'Neill, Stephens, Kowalewski, IEEE RA-L "
               "3(4):3027-3034, 2018 (ODbL 1.0 / DbCL 1.0)")
N_COLUMNS = 10
TORQUE_NM_PER_COUNT = 3.9811e-5
PROXIMAL_COUNTS_PER_REV = 8192.0
DISTAL_COUNTS_PER_REV = 4000.0
DISTAL_SIGN = -1.0
MIN_ROWS = 2000           # 2 s at 1 kHz: shorter files are truncated
#: Largest |value| of each column the analysis reads (SOURCE.md's units: s, counts, A): beyond it the value is
#: no time stamp, encoder angle (over a thousand turns), torque (over 400 N m) or motor current of the rig (a
#: corrupt row), and it would overflow the analysis' arithmetic.
MAX_MAGNITUDE = {0: (1e10, "s"), 1: (1e7, "counts"), 2: (1e7, "counts"), 4: (1e7, "counts"), 5: (1e7, "counts"),
                 6: (1e3, "A")}
_NAME = re.compile(r"^(\d)(\d)\.TXT$", re.IGNORECASE)


@dataclass(frozen=True, eq=False)
class MrdRun:
    """One run; arrays of shape (n,), float64, SI units (module docstring).

    name : the file stem ("00"); source : path read; frequency_hz : sine frequency from the data;
    load_command : mean front-end command [A]; load_level : rank of load_command in the folder
    (0 = lightest; -1 until :func:`load_mrd_dir` sets it).
    """

    name: str
    time: np.ndarray
    theta_p: np.ndarray
    tau_p: np.ndarray
    theta_d: np.ndarray
    tau_d: np.ndarray
    frequency_hz: float
    load_command: float
    source: str
    load_level: int = -1

    def __len__(self) -> int:
        return int(self.time.shape[0])

    @property
    def dt(self) -> float:
        """Median sample spacing [s]."""
        return float(np.median(np.diff(self.time)))

    @property
    def peak_speed(self) -> float:
        """2 pi f times half the spindle angle range [rad/s]."""
        return 2.0 * math.pi * self.frequency_hz * 0.5 * float(np.ptp(self.theta_p))


def sine_frequency(t: np.ndarray, x: np.ndarray) -> float:
    """Dominant frequency [Hz] of ``x`` sampled at times ``t`` [s]: peak of the spectrum of the
    detrended signal, refined by a parabola through the three bins around it."""
    x = np.asarray(x, dtype=float) - np.mean(x)
    n = x.size
    dt = float(np.median(np.diff(t)))
    m = 1 << int(math.ceil(math.log2(max(n, 2))))
    spec = np.abs(np.fft.rfft(x * np.hanning(n), 4 * m))
    k = int(np.argmax(spec[1:]) + 1)
    peak = float(k)
    if 1 <= k < spec.size - 1:
        a, b, c = spec[k - 1], spec[k], spec[k + 1]
        den = a - 2 * b + c
        peak = k + (0.5 * (a - c) / den if den != 0 else 0.0)
    return float(peak / (4 * m * dt))


def _numbers(line: str) -> bool:
    try:
        [float(v) for v in line.split(",")]
    except ValueError:
        return False
    return True


def _table(p: Path) -> tuple[list[tuple[int, str]], np.ndarray]:
    """(line number, text) of every data row of a run's file and its numbers, shape (n, N_COLUMNS); DataError as
    :func:`read_mrd` for every check but the time's."""
    text = read_text(p, replace=True)
    lines = text.splitlines()
    first = next((i for i, ln in enumerate(lines) if ln.strip() and not ln.lstrip().startswith("%")), len(lines))
    rows = [(i + 1, ln.strip().rstrip(",")) for i, ln in enumerate(lines) if i >= first and ln.strip()]
    for lineno, ln in rows:
        if ln.count(",") != N_COLUMNS - 1:
            raise DataError(f"{p}:{lineno}: expected {N_COLUMNS} comma-separated numbers, got {ln.count(',') + 1}")
    if len(rows) < MIN_ROWS:
        raise DataError(f"{p}: {len(rows)} data rows, need at least {MIN_ROWS} (truncated file?)")
    try:
        a = np.array(",".join(ln for _, ln in rows).split(","), dtype=float).reshape(-1, N_COLUMNS)
    except ValueError:
        lineno, ln = next((k, ln) for k, ln in rows if not _numbers(ln))
        raise DataError(f"{p}:{lineno}: not a number in {ln[:60]!r}") from None
    if not np.all(np.isfinite(a)):
        r, c = (int(i) for i in np.argwhere(~np.isfinite(a))[0])
        raise DataError(f"{p}:{rows[r][0]}: column {c}: expected a finite number, got {float(a[r, c])!r}")
    for c, (limit, unit) in MAX_MAGNITUDE.items():
        big = np.flatnonzero(np.abs(a[:, c]) > limit)
        if big.size:
            raise DataError(f"{p}:{rows[big[0]][0]}: column {c}: {float(a[big[0], c])!r} {unit} is beyond anything "
                            f"the rig reads (|value| <= {limit:g} {unit}): a corrupt row; fix or remove that row")
    return rows, a


def read_mrd(path: str | Path) -> MrdRun:
    """Read one ``XY.TXT`` run.

    Raises
    ------
    DataError
        Missing file, a directory, a file that is not text (UTF-16, binary data: at which byte), a data row
        without 10 numbers, a value that is not a number, not finite or beyond :data:`MAX_MAGNITUDE`,
        non-increasing time, or fewer than MIN_ROWS rows (a truncated file); the message names the file, and the
        line and column (0-based, as in SOURCE.md) where there is one.
    """
    p = Path(path)
    rows, a = _table(p)
    t = a[:, 0]
    if np.any(np.diff(t) <= 0):
        k = int(np.argmax(np.diff(t) <= 0)) + 1
        raise DataError(f"{p}:{rows[k][0]}: column 0: time {float(t[k])!r} is not after the previous "
                        f"{float(t[k - 1])!r} (must be strictly increasing)")
    theta_p = a[:, 1] * 2 * math.pi / PROXIMAL_COUNTS_PER_REV
    return MrdRun(name=p.stem, time=t - t[0], theta_p=theta_p, tau_p=a[:, 2] * TORQUE_NM_PER_COUNT,
                  theta_d=DISTAL_SIGN * a[:, 4] * 2 * math.pi / DISTAL_COUNTS_PER_REV,
                  tau_d=DISTAL_SIGN * a[:, 5] * TORQUE_NM_PER_COUNT, frequency_hz=sine_frequency(t, theta_p),
                  load_command=float(np.mean(a[:, 6])), source=str(p))


#: A value farther than this many times its column's spread (median absolute deviation) from the column's median
#: is named by :func:`values_error` as the one to look at.
OUTLIER_SPREADS = 100.0


def values_error(runs: list[MrdRun], exc: BaseException) -> DataError:
    """The DataError for an analysis of ``runs`` that failed on their values (``exc``: a fit whose bounds or
    samples the values spoiled, an overflow): the folder, the failure, and the file, line and column of the value
    farthest out of its column (its distance from the column's median in column spreads) when it stands more
    than :data:`OUTLIER_SPREADS` out."""
    best: tuple[float, str] = (0.0, "")
    for r in runs:
        rows, a = _table(Path(r.source))
        for c, (_, unit) in MAX_MAGNITUDE.items():
            dev = np.abs(a[:, c] - np.median(a[:, c]))
            k = int(np.argmax(dev))
            score = float(dev[k]) / (float(np.median(dev)) or float(np.ptp(a[:, c])) or 1.0)
            if score > best[0]:
                best = (score, f"{r.source}:{rows[k][0]}: column {c} = {float(a[k, c]):g} {unit}, {score:.3g} "
                               "times the column's spread from its median")
    what = f"the analysis fails on the runs' values ({type(exc).__name__}: {' '.join(str(exc).split())})"
    folder = Path(runs[0].source).parent if runs else "MRD"
    hint = (f"the value farthest out is at {best[1]}: fix or remove that row" if best[0] > OUTLIER_SPREADS else
            "no value stands out of its column: plot the runs' signals (--figures DIR with fewer --runs)")
    return DataError(f"{folder}: {what}; {hint}")


def load_mrd_dir(directory: str | Path | None = None, select: str | None = None) -> tuple[list[MrdRun], list[str]]:
    """Every run of the folder ``directory`` means (a folder of runs, one ``Tool_`` folder, the project's MRD
    folder, a clone's root or its ``data/``: :func:`recorded.mrd_files.find_mrd_folder`; default the data
    folder's), sorted by name; ``select``: only those whose file stem matches this glob (``--runs``, e.g.
    ``"1*"``). A note naming the folder chosen among several goes to stderr.

    Returns the runs (with ``load_level`` set: rank of the distinct front-end commands, 0 =
    lightest) and one line per file that could not be read. Raises DataError when no run is found (what is
    expected, and where to get the data), no run could be read, or no run matches ``select``.
    """
    d, files, note = find_mrd_folder(directory)
    if note:
        print(note, file=sys.stderr)
    if select is not None:
        chosen = [f for f in files if fnmatch.fnmatchcase(f.stem, select)]
        if not chosen:
            raise DataError(f"{d}: no run matches --runs {select!r} (runs: {', '.join(f.stem for f in files)})")
        files = chosen
    runs, bad = [], []
    for f in files:
        try:
            runs.append(read_mrd(f))
        except DataError as e:
            bad.append(str(e))
    if not runs:
        raise DataError(f"{d}: no readable run (*.TXT)" + (f"; {bad[0]}" if bad else ""))
    levels = sorted({round(r.load_command, 3) for r in runs})
    runs = [MrdRun(**{**r.__dict__, "load_level": levels.index(round(r.load_command, 3))}) for r in runs]
    return runs, bad


#: Two runs share a stroke when their spindle-angle ranges overlap by this share of the shorter one.
STROKE_OVERLAP = 0.8


def stroke_window(run: MrdRun) -> tuple[float, float]:
    """(low, high) [rad]: the 5-95 % range of the run's spindle angle, the window its strokes cover."""
    lo, hi = np.percentile(run.theta_p, [5.0, 95.0])
    return float(lo), float(hi)


def runs_selection(group: list[str], names: list[str]) -> str:
    """How to pick ``group`` among the folder's run ``names``: ``--runs 'PREFIX*'`` when the group's common name
    prefix selects exactly it, else the names listed."""
    pre = os.path.commonprefix(group)
    if pre and all(n in group for n in names if n.startswith(pre)):
        return f"--runs '{pre}*'"
    return "runs " + ",".join(group)


def stroke_groups(runs: list[MrdRun]) -> list[list[str]]:
    """Names of the runs grouped by the spindle-angle window their strokes cover (:func:`stroke_window`): a run
    joins the group of the run before it (ordered by the window's middle) when the two windows overlap by at
    least STROKE_OVERLAP of the shorter one. One group on a folder of one protocol; a folder whose runs stop
    the jaw at several positions (the source's roll and pitch folders, ``ZXY.TXT``) gives one group per
    position."""
    win = {r.name: stroke_window(r) for r in runs}
    order = sorted(win, key=lambda n: (win[n][0] + win[n][1], n))
    groups: list[list[str]] = []
    for n in order:
        if groups:
            lo, hi = win[groups[-1][-1]]
            a, b = win[n]
            if min(hi, b) - max(lo, a) >= STROKE_OVERLAP * min(hi - lo, b - a):
                groups[-1].append(n)
                continue
        groups.append([n])
    return [sorted(g) for g in groups]

