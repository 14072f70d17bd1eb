"""Numeric tables with a column map: the KAIST recordings (8- and 10-column) and other labs' CSV files.

A *column map* names which column holds which signal of an antagonistic-pair recording:

==============  ========  ====================================================================
field           required  meaning
==============  ========  ====================================================================
``time``        yes       time stamp [s]
``command``     yes       commanded joint angle on the motor side (deg, or rad with units=rad)
``angle``       yes       measured distal bending angle (same unit as the command)
``T_a, T_b``    yes       proximal tensions of tendons A (rises with + angle) and B [N]
``velocity_cmd``  no      commanded velocity (raw)
``motor_a/_b``  no        motor signals (raw)
==============  ========  ====================================================================

Written ``time=0,command=1,angle=3,T_a=4,T_b=5`` (0-based columns), optionally with ``units=rad``
(default ``deg``, the KAIST files). :data:`KAIST_MAP` is the map of the 8-column KAIST files
(:mod:`recorded.kaist`, docs/how-to/get-the-data.md); files with more columns and no map given are read with it
(a note says so).

:func:`read_table` is robust to what long logger files carry, and says what it did in ``notes``:

* a header line (first line not all numbers) is skipped; separators: comma (a trailing comma is
  allowed), semicolon or white space; a last line cut short (a logger stopped mid-write) is dropped
  with a warning, a malformed line anywhere else is an error naming file, line and column;
* rows whose time stamp equals the previous row's are dropped (the KAIST logger writes each stamp
  several times; the later repeats carry values that reappear in the next stamp's first row);
* a *time reset* (time going back) splits the file into segments: a last segment holding at most
  :data:`CUT_FRACTION` of the rows is cut off, otherwise every later segment is stitched on, its
  time shifted to continue one median step after the previous segment;
* all-zero columns are reported and ignored; a mapped required column that is all zero is an error.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from estimator.errors import DataError
from teleop.errors import ConfigError
from teleop.recording.text_files import read_text

__all__ = ["REQUIRED", "OPTIONAL", "KAIST_MAP", "ColumnMap", "parse_column_map", "Table", "read_table",
           "CUT_FRACTION"]

REQUIRED = ("time", "command", "angle", "T_a", "T_b")
OPTIONAL = ("velocity_cmd", "motor_a", "motor_b")
#: A trailing segment after a time reset is cut off when it holds at most this share of the rows.
CUT_FRACTION = 0.2
#: Largest |value| of each required field (angles in degrees; a ``units=rad`` map's are converted): beyond it the
#: value is no time stamp [s], joint angle or tension [N] of an instrument (a corrupt row), and it would overflow
#: the analysis' arithmetic.
MAX_MAGNITUDE = {"time": 1e10, "command": 1e4, "angle": 1e4, "T_a": 1e6, "T_b": 1e6}
_KIND = {"time": "time stamp", "command": "joint angle", "angle": "joint angle", "T_a": "tension", "T_b": "tension"}


@dataclass(frozen=True)
class ColumnMap:
    """Field name -> 0-based column index, and the angle unit of command and angle (deg or rad)."""

    columns: dict = field(default_factory=dict)
    units: str = "deg"

    def describe(self) -> str:
        """``time=0,command=1,...`` (the form :func:`parse_column_map` reads)."""
        return ",".join(f"{k}={v}" for k, v in self.columns.items()) + ("" if self.units == "deg" else ",units=rad")


KAIST_MAP = ColumnMap({"time": 0, "command": 1, "velocity_cmd": 2, "angle": 3, "T_a": 4, "T_b": 5,
                       "motor_a": 6, "motor_b": 7})


def parse_column_map(text: str) -> ColumnMap:
    """Read ``time=0,command=1,angle=3,T_a=4,T_b=5[,units=rad]`` into a :class:`ColumnMap`.

    Raises
    ------
    ConfigError
        An entry without '=', an unknown field, a column that is not a non-negative integer, a
        column used twice, a required field missing, units other than deg / rad.
    """
    cols: dict[str, int] = {}
    units = "deg"
    for item in filter(None, (s.strip() for s in str(text).split(","))):
        name, sep, value = (s.strip() for s in item.partition("="))
        if not sep:
            raise ConfigError(f"--columns: '{item}' is not name=column")
        if name == "units":
            if value not in ("deg", "rad"):
                raise ConfigError(f"--columns: units must be deg or rad, got '{value}'")
            units = value
            continue
        if name not in REQUIRED + OPTIONAL:
            raise ConfigError(f"--columns: unknown field '{name}'; known: {', '.join(REQUIRED + OPTIONAL)}, units")
        if not re.fullmatch(r"\d+", value):
            raise ConfigError(f"--columns: {name}={value}: the column must be a 0-based integer")
        if int(value) in cols.values():
            raise ConfigError(f"--columns: column {value} is mapped twice")
        cols[name] = int(value)
    missing = [f for f in REQUIRED if f not in cols]
    if missing:
        raise ConfigError(f"--columns: missing {', '.join(missing)} (need {', '.join(REQUIRED)})")
    return ColumnMap(cols, units)


@dataclass
class Table:
    """What :func:`read_table` returns: ``data`` field -> ndarray (n,) in file units (time [s]),
    the column map used, the source path and human-readable ``notes`` on what was done."""

    data: dict
    column_map: ColumnMap
    source: str
    notes: list


def _split(line: str, sep: str | None) -> list[str]:
    fields = line.split(sep) if sep else line.split()
    if sep and fields and not fields[-1].strip():
        fields = fields[:-1]                                   # trailing separator
    return fields


def _to_floats(fields: list[str], src: str, lineno: int) -> list[float]:
    try:
        vals = [float(f) for f in fields]
    except ValueError:
        for j, f in enumerate(fields):
            try:
                float(f)
            except ValueError:
                raise DataError(f"{src}:{lineno}: column {j}: expected a number, got '{f.strip()}'") from None
        raise
    for j, v in enumerate(vals):
        if not math.isfinite(v):
            raise DataError(f"{src}:{lineno}: column {j}: expected a finite number, got '{fields[j].strip()}'")
    return vals


def _rows(path: Path) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """All numeric rows (n, m), their 1-based line numbers, notes (header skipped)."""
    src = str(path)
    text = read_text(path, replace=True)
    notes: list[str] = []
    sep: str | None = None
    width = None
    rows: list[list[float]] = []
    linenos: list[int] = []
    lines = text.splitlines()
    last = max((i for i, raw in enumerate(lines, start=1) if raw.strip()), default=0)
    for lineno, raw in enumerate(lines, start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        if width is None:
            sep = "," if "," in line else ";" if ";" in line else None
            fields = _split(line, sep)
            try:
                [float(f) for f in fields]
            except ValueError:
                if rows or notes:
                    raise DataError(f"{src}:{lineno}: expected numbers, got '{line[:60]}'") from None
                notes.append(f"line {lineno} read as a header and skipped")
                continue
            width = len(fields)
        fields = _split(line, sep)
        try:
            if len(fields) != width:
                raise DataError(f"{src}:{lineno}: expected {width} {'comma-' if sep == ',' else ''}separated "
                                f"numbers (as the first data row), found {len(fields)}")
            rows.append(_to_floats(fields, src, lineno))
        except DataError as e:
            if lineno != last or len(rows) < 2:
                raise
            notes.append(f"WARNING the last line ({lineno}) is cut short or malformed: dropped ({e})")
            break
        linenos.append(lineno)
    if not rows:
        raise DataError(f"{src}: no numeric rows")
    return np.asarray(rows, dtype=np.float64), np.asarray(linenos), notes


def _clean_time(a: np.ndarray, lines: np.ndarray, src: str, notes: list[str]) -> np.ndarray:
    """Drop repeated stamps; cut or stitch time resets (module docstring)."""
    t = a[:, 0]
    keep = np.ones(t.size, dtype=bool)
    keep[1:] = t[1:] != t[:-1]
    dropped = int(t.size - keep.sum())
    if dropped:
        notes.append(f"{dropped} of {t.size} rows repeat the previous time stamp: dropped")
    a, lines = a[keep], lines[keep]
    t = a[:, 0].copy()
    back = np.flatnonzero(np.diff(t) < 0) + 1
    if back.size:
        bounds = [0, *back.tolist(), t.size]
        segs = [slice(b0, b1) for b0, b1 in zip(bounds[:-1], bounds[1:], strict=False)]
        steps = np.diff(t)
        dt = float(np.median(steps[steps > 0])) if np.any(steps > 0) else 1.0
        last = segs[-1]
        if len(segs) == 2 and (last.stop - last.start) <= CUT_FRACTION * t.size:
            notes.append(f"WARNING time reset at line {lines[last.start]} ({t[last.start - 1]:.4g} s -> "
                         f"{t[last.start]:.4g} s): the {last.stop - last.start} rows from there on are cut off")
            a = a[:last.start]
        else:
            for s in segs[1:]:
                shift = t[s.start - 1] + dt - t[s.start]
                t[s.start:] += shift
            notes.append(f"WARNING {len(segs) - 1} time reset(s) (first at line {lines[segs[1].start]}): later "
                         f"segments stitched on, their time shifted to continue at the median step {dt:.4g} s")
            a = a.copy()
            a[:, 0] = t
    if a.shape[0] < 2:
        raise DataError(f"{src}: {a.shape[0]} distinct time stamp(s), need at least 2")
    if np.any(np.diff(a[:, 0]) <= 0):
        raise DataError(f"{src}: time is not increasing after the cleaning")
    return a


def _check_magnitude(a: np.ndarray, lines: np.ndarray, cmap: ColumnMap, src: str) -> None:
    """DataError naming the line and column of the first value of a required field beyond :data:`MAX_MAGNITUDE`."""
    for name in REQUIRED:
        col, unit = cmap.columns[name], {"time": "s", "T_a": "N", "T_b": "N"}.get(name, cmap.units)
        limit = MAX_MAGNITUDE[name] * (math.pi / 180.0 if unit == "rad" else 1.0)
        big = np.flatnonzero(np.abs(a[:, col]) > limit)
        if big.size:
            raise DataError(f"{src}:{lines[big[0]]}: column {col} ({name}): {float(a[big[0], col])!r} {unit} is "
                            f"beyond any {_KIND[name]} (|{name}| <= {limit:g} {unit}): a corrupt row or another unit; "
                            "fix or remove that row")


def read_table(path: str | Path, column_map: ColumnMap | None = None) -> Table:
    """Read a numeric table of an antagonistic-pair recording with a column map.

    Parameters
    ----------
    path : the file
    column_map : default :data:`KAIST_MAP` (files with exactly 8 columns need nothing more; wider
        files are read with it and a note says so)

    Returns
    -------
    Table
        ``data``: every mapped field, shape (n,), file units (command and angle in the map's unit,
        tensions [N], time [s]); optional fields whose column is all zero are left out.

    Raises
    ------
    DataError
        Missing or unreadable file, a directory, a file that is not text (UTF-16, binary data: at which byte),
        a malformed row (file:line, column), a mapped column beyond the row width, a required field's value
        beyond :data:`MAX_MAGNITUDE` (file:line, column), a required column all zero, fewer than 2 distinct
        time stamps.
    """
    path = Path(path)
    src = str(path)
    a, lines, notes = _rows(path)
    width = a.shape[1]
    cmap = column_map or KAIST_MAP
    if column_map is None and width != 8:
        if width < 8:
            raise DataError(f"{src}: {width} columns; the KAIST layout has 8: give the column map "
                            "(--columns time=0,command=1,angle=3,T_a=4,T_b=5)")
        notes.append(f"{width} columns, no column map given: read with the 8-column KAIST map "
                     f"({KAIST_MAP.describe()}); columns {', '.join(map(str, range(8, width)))} not used")
    too_far = {k: v for k, v in cmap.columns.items() if v >= width}
    if too_far:
        raise DataError(f"{src}: the rows have {width} columns; the column map asks for "
                        + ", ".join(f"{k}={v}" for k, v in too_far.items()))
    _check_magnitude(a, lines, cmap, src)
    a = _clean_time(a, lines, src, notes)
    zero = [j for j in range(width) if not np.any(a[:, j])]
    if zero:
        notes.append(f"all-zero column(s) {', '.join(map(str, zero))}: ignored")
    bad = [f"{k} (column {v})" for k, v in cmap.columns.items() if k in REQUIRED[1:] and v in zero]
    if bad:
        raise DataError(f"{src}: {', '.join(bad)} all zero: wrong column map? (--columns)")
    data = {k: a[:, v].copy() for k, v in cmap.columns.items() if k in REQUIRED or v not in zero}
    notes.insert(0, f"columns used: {cmap.describe()}")
    return Table(data, cmap, src, notes)
