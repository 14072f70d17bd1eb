"""The format of a recording, read from its first lines (``rig.recording.format: auto``, ``teleop demo --recording``).

A file's name says nothing here (a clone's ``optimization/selected/60.txt`` is a KAIST recording, and a file
named ``00.TXT`` or ``sine_config_0.txt`` may hold anything): :func:`detect_format` reads the head of the file.

* ``csv``: the project's measured-data CSV (docs/reference/formats.md): after ``#`` lines, a header line naming
  ``time``, ``x_in`` and ``T_in`` (:data:`teleop.recording.measured_csv.REQUIRED_COLUMNS`);
* ``kaist``: rows of 8 comma-separated numbers (a trailing comma allowed), no header (the KAIST robot's log);
* ``mrd``: rows of 10 comma-separated numbers, after ``%`` header lines when there are any (an MRD Lab run).

The first :data:`ROWS_CHECKED` data rows must agree. A file of none of these is one line naming it, what its
first data line holds and the formats tried.
"""
from __future__ import annotations

from pathlib import Path

from estimator.errors import DataError
from teleop.recording.measured_csv import REQUIRED_COLUMNS
from teleop.recording.text_files import HEAD_BYTES, text_problem

__all__ = ["ROWS_CHECKED", "TRIED", "detect_format"]

#: Data rows whose count of numbers must agree.
ROWS_CHECKED = 5
#: The formats tried, as the message of an unknown file names them.
TRIED = ("csv (a header line naming time, x_in, T_in, ...)", "kaist (8 comma-separated numbers per row)",
         "mrd (10 comma-separated numbers per row, after % header lines)")
_BY_COUNT = {8: "kaist", 10: "mrd"}


def _unknown(path: Path, what: str) -> DataError:
    return DataError(f"rig.recording.path: {path}: not a recording of a known format ({what}); tried "
                     f"{', '.join(TRIED)}")


def _head_lines(path: Path) -> list[str]:
    """The non-blank lines of the file's first :data:`HEAD_BYTES` bytes (the last one left out when cut)."""
    try:
        with path.open("rb") as f:
            data = f.read(HEAD_BYTES)
    except OSError as e:
        raise DataError(f"rig.recording.path: {path}: cannot read ({e.strerror})") from None
    problem = text_problem(data, final=len(data) < HEAD_BYTES)
    if problem is not None and problem[1] is None:         # UTF-16, UTF-32 or binary data, not a stray byte
        raise _unknown(path, problem[0])
    lines = data.decode("utf-8-sig", errors="replace").splitlines()
    if len(data) == HEAD_BYTES:
        lines = lines[:-1]
    return [ln.strip() for ln in lines if ln.strip()]


def _count(line: str) -> int | None:
    """How many comma-separated numbers ``line`` holds (a trailing comma allowed); None when one is no number."""
    fields = line.rstrip(",").split(",")
    try:
        for f in fields:
            float(f)
    except ValueError:
        return None
    return len(fields)


def detect_format(path: str | Path) -> str:
    """``"csv"``, ``"kaist"`` or ``"mrd"``: the format the head of ``path`` shows (module docstring).

    Raises
    ------
    DataError
        The file cannot be read, or it is of none of the formats: one line naming the file, what its first data
        line holds and the formats tried.
    """
    p = Path(path)
    body = [ln for ln in _head_lines(p) if not ln.startswith(("#", "%"))]
    if not body:
        raise _unknown(p, "no data line")
    first = body[0]
    if _count(first) is None:
        names = [c.strip() for c in first.split(",")]
        if set(REQUIRED_COLUMNS) <= set(names):
            return "csv"
        raise _unknown(p, f"first line {first[:60]!r} is neither numbers nor a header naming time, x_in, T_in")
    counts = [_count(ln) for ln in body[:ROWS_CHECKED]]
    if len(set(counts)) == 1 and counts[0] in _BY_COUNT:
        return _BY_COUNT[counts[0]]
    seen = ", ".join(str(n) if n is not None else "not numbers" for n in dict.fromkeys(counts))
    raise _unknown(p, f"its first data rows hold {seen} comma-separated numbers")
