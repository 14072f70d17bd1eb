"""The measured-data CSV of one tendon (docs/reference/formats.md, "Measured-data CSV"): its columns and
units, and the reader.

``# key: value`` lines above the header are metadata (``# units: time=s, x_in=m, T_in=N``), other
``#`` lines and blank lines are skipped, then a header line of column names, then comma-separated
plain numbers (no quoting). Columns ``time`` [s], ``x_in`` [m], ``T_in`` [N] are required, ``x_out``
[m] and ``T_out`` [N] optional, others kept in :attr:`MeasuredData.extra`. Every problem raises
:class:`~estimator.errors.DataError` with a one-line message naming file, line (1-based) and column; a path that
is no file and a file that is not UTF-8 text are named as such (:mod:`teleop.recording.text_files`).
The writer is :class:`teleop.recording.measured.CsvRecorder`.
"""
from __future__ import annotations

import re
import warnings
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import IO

import numpy as np

from estimator.data import MeasuredData  # the data type lives in the estimator (floor 0)
from estimator.errors import DataError
from teleop.recording.text_files import check_text_head, not_text_error, require_file

__all__ = [
    "REQUIRED_COLUMNS", "OPTIONAL_COLUMNS", "SI_UNITS", "MAX_MAGNITUDE", "META_LINE", "COLUMN_NAME",
    "parse_units", "read_measured_csv", "values_error",
]

REQUIRED_COLUMNS = ("time", "x_in", "T_in")
OPTIONAL_COLUMNS = ("x_out", "T_out")
#: SI unit of each standard column, written as ``# units:`` metadata and checked on load.
SI_UNITS = {"time": "s", "x_in": "m", "T_in": "N", "x_out": "m", "T_out": "N"}

#: Largest |value| of each standard column, in its SI unit, that ``teleop analyze`` takes (``limits`` of
#: :func:`read_measured_csv`): beyond it the value is no time stamp, tendon position or tension of an instrument
#: (another unit, a corrupt row), and it would overflow the diagnosis' arithmetic.
MAX_MAGNITUDE = {"time": 1e10, "x_in": 10.0, "T_in": 1e6, "x_out": 10.0, "T_out": 1e6}
_KIND = {"s": "time stamp", "m": "tendon position", "N": "tension"}

#: a ``# key: value`` metadata line
META_LINE = re.compile(r"#\s*([A-Za-z_][\w.\-]*)\s*:\s?(.*)$")
#: a column name
COLUMN_NAME = re.compile(r"[A-Za-z_][\w.\-\[\]]*$")


def parse_units(text: str, where: str) -> dict[str, str]:
    """The ``column=unit, ...`` of a ``# units:`` line as a dict; DataError naming ``where`` for a malformed item."""
    units: dict[str, str] = {}
    for item in filter(None, (p.strip() for p in text.split(","))):
        name, eq, unit = item.partition("=")
        if not eq or not name.strip() or not unit.strip():
            raise DataError(f"{where}: units: expected 'column=unit', got '{item}'")
        units[name.strip()] = unit.strip()
    return units


def _read_head(fh: IO[str], src: str) -> tuple[dict[str, str], list[str], int]:
    """Read metadata and the header line; return (metadata, column names, header line number)."""
    metadata: dict[str, str] = {}
    lineno = 0
    for raw in iter(fh.readline, ""):
        lineno += 1
        line = raw.strip()
        if not line:
            continue
        if line.startswith("#"):
            m = META_LINE.match(line)
            if m:
                key, value = m.group(1), m.group(2).strip()
                if key in metadata:
                    raise DataError(f"{src}:{lineno}: metadata key '{key}' given twice")
                metadata[key] = value
            continue
        names = [c.strip() for c in line.split(",")]
        try:
            float(names[0])
        except ValueError:
            pass
        else:
            raise DataError(f"{src}:{lineno}: expected a header line of column names, got numbers")
        for j, name in enumerate(names):
            if not name:
                raise DataError(f"{src}:{lineno}: header column {j + 1} is empty")
            if names.index(name) != j:
                raise DataError(f"{src}:{lineno}: header column {j + 1}: '{name}' appears twice")
        return metadata, names, lineno
    raise DataError(f"{src}: empty file (expected a header line of column names)")


def _data_lines(path: Path, header_line: int) -> Iterator[tuple[int, str]]:
    """(line number, stripped text) of every data line after the header (slow path, errors only)."""
    with open(path, encoding="utf-8-sig", errors="replace") as fh:
        for lineno, raw in enumerate(fh, start=1):
            line = raw.strip()
            if lineno > header_line and line and not line.startswith("#"):
                yield lineno, line


def _locate_parse_error(path: Path, src: str, header_line: int, names: list[str]) -> DataError:
    for lineno, line in _data_lines(path, header_line):
        fields = line.split(",")
        if len(fields) != len(names):
            return DataError(f"{src}:{lineno}: expected {len(names)} values "
                             f"({', '.join(names)}), found {len(fields)}")
        for j, text in enumerate(fields):
            try:
                float(text.replace("_", "x"))  # numpy rejects 1_000, Python accepts it
            except ValueError:
                return DataError(f"{src}:{lineno}: column {j + 1} ('{names[j]}'): expected a "
                                 f"number, got '{text.strip()}'")
    return DataError(f"{src}: could not parse the data rows")


def _line_of_row(path: Path, header_line: int, row: int) -> int:
    return next((ln for k, (ln, _) in enumerate(_data_lines(path, header_line)) if k == row), -1)


def read_measured_csv(path: str | Path, limits: Mapping[str, float] | None = None) -> MeasuredData:
    """Read one tendon's measured-data CSV.

    Parameters
    ----------
    path : str or Path
        The CSV file (format in the module docstring), UTF-8 text (a UTF-8 byte-order mark is skipped).
    limits : mapping of column name -> largest |value| [SI], optional
        Values beyond are refused with their line (:data:`MAX_MAGNITUDE`, for the analysis); None: any finite
        value.

    Returns
    -------
    MeasuredData
        Arrays of shape (n_samples,), n_samples >= 2, all finite (and within ``limits``), ``time`` strictly
        increasing.

    Raises
    ------
    DataError
        Missing file, a directory, a file that is not UTF-8 text (what it looks like: UTF-16, binary data; at
        which byte), an empty file, no header, missing required column, non-SI ``# units:`` for a
        standard column, wrong field count or non-numeric value (file:line, column), NaN or inf
        (file:line, column), a value beyond ``limits`` (file:line, column),
        time not strictly increasing (file:line, both values), fewer than two rows.
    """
    path, src = require_file(path), str(path)
    check_text_head(path)
    try:
        metadata, names, header_line, table = _read_table(path, src)
    except UnicodeDecodeError:
        raise not_text_error(path) from None
    n_rows = table.shape[0]
    if n_rows and table.shape[1] != len(names):
        raise _locate_parse_error(path, src, header_line, names)
    if n_rows < 2:
        raise DataError(f"{src}: {n_rows} data row(s), need at least 2")
    _check_values(table, names, path, src, header_line, limits or {})
    cols = {name: np.ascontiguousarray(table[:, j]) for j, name in enumerate(names)}
    t = cols["time"]
    step = np.diff(t)
    if not (step > 0).all():
        row = int(np.argmax(~(step > 0))) + 1
        line = _line_of_row(path, header_line, row)
        raise DataError(f"{src}:{line}: column {names.index('time') + 1} ('time'): time "
                        f"{float(t[row])!r} s is not after the previous {float(t[row - 1])!r} s "
                        f"(must be strictly increasing)")
    known = set(REQUIRED_COLUMNS + OPTIONAL_COLUMNS)
    return MeasuredData(time=t, x_in=cols["x_in"], T_in=cols["T_in"],
                        x_out=cols.get("x_out"), T_out=cols.get("T_out"),
                        extra={k: v for k, v in cols.items() if k not in known},
                        metadata=metadata, source=src)


def _check_values(table: np.ndarray, names: list[str], path: Path, src: str, header_line: int,
                  limits: Mapping[str, float]) -> None:
    """DataError naming the line and column of the first value that is not finite, or beyond its column's entry
    of ``limits``."""
    limit = np.array([limits.get(n, np.inf) for n in names])
    bad = ~np.isfinite(table) | (np.abs(table) > limit)
    if not bad.any():
        return
    r, c = (int(i) for i in np.argwhere(bad)[0])
    v, name = float(table[r, c]), names[c]
    where = f"{src}:{_line_of_row(path, header_line, r)}: column {c + 1} ('{name}')"
    if not np.isfinite(v):
        raise DataError(f"{where}: expected a finite number, got {v!r}")
    unit = SI_UNITS[name]
    raise DataError(f"{where}: {v!r} {unit} is beyond any {_KIND[unit]} (|{name}| <= {limit[c]:g} {unit}): a value "
                    "in other units or a corrupt row; fix or remove that row")


def _read_table(path: Path, src: str) -> tuple[dict[str, str], list[str], int, np.ndarray]:
    """(metadata, column names, header line number, the numbers (n_rows, n_columns)) of the file; DataError for
    the head, the units and a row that does not parse; ``UnicodeDecodeError`` for bytes that are not UTF-8."""
    with open(path, encoding="utf-8-sig") as fh:
        metadata, names, header_line = _read_head(fh, src)
        missing = [c for c in REQUIRED_COLUMNS if c not in names]
        if missing:
            raise DataError(f"{src}: missing column '{missing[0]}' (have: {', '.join(names)})")
        if "units" in metadata:
            units = parse_units(metadata["units"], src)
            for col, unit in units.items():
                if col in SI_UNITS and col in names and unit != SI_UNITS[col]:
                    raise DataError(f"{src}: units: column '{col}' is in '{unit}', expected "
                                    f"'{SI_UNITS[col]}' (convert to SI before loading)")
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)  # "input contained no data"
                table = np.loadtxt(fh, delimiter=",", comments="#", ndmin=2, dtype=np.float64)
        except UnicodeDecodeError:
            raise
        except ValueError:
            raise _locate_parse_error(path, src, header_line, names) from None
    return metadata, names, header_line, table


def values_error(data: MeasuredData, exc: BaseException) -> DataError:
    """The DataError for a recording whose values make a computation on it fail (``exc``: an overflow, a division
    by zero, an inf where a finite number was needed), naming the file and the line and column of the value
    farthest out of its column (distance from the column's median in units of its median absolute deviation, or
    of its range where that is 0), as the value to look at."""
    cols = {k: np.asarray(a) for k, a in data.columns().items() if k in SI_UNITS and k != "time"}
    what = f"the diagnosis fails on this file's values ({type(exc).__name__}: {' '.join(str(exc).split())})"
    if not cols:
        return DataError(f"{data.source}: {what}")
    score, row, name = max((*_outlier(a), k) for k, a in cols.items())
    v, unit = float(cols[name][row]), SI_UNITS[name]
    try:
        with open(data.source, encoding="utf-8-sig", errors="replace") as fh:
            _, names, header_line = _read_head(fh, data.source)
        where = f"{data.source}:{_line_of_row(Path(data.source), header_line, row)}: column {names.index(name) + 1}"
    except (OSError, ValueError):
        where = f"{data.source}: data row {row + 1}, column"
    return DataError(f"{where} ('{name}'): {what}; {name} = {v:g} {unit} here stands {score:.3g} times the "
                     "column's spread from its median: fix or remove that row")


def _outlier(a: np.ndarray) -> tuple[float, int]:
    """(how far out, row) of the value of ``a`` farthest from its median, in units of the column's spread."""
    dev = np.abs(a - np.median(a))
    spread = float(np.median(dev)) or float(np.ptp(a)) or 1.0
    row = int(np.argmax(dev))
    return float(dev[row]) / spread, row
