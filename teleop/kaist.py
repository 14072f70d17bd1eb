"""Importer for the KAIST flexible-endoscope sine recordings (antagonistic tendon pair).

The files (``sine_config_N.txt``, N = 0, 60, 120, 180, 240) are described in
``../shared/data/kaist-tsm/SOURCE.md``. They have **no licence**: this module reads them where they
lie (or from a directory the user gives) and the project never copies them or per-sample data
derived from them.

File format: comma separated, no header, 8 numeric columns and a trailing comma, logged at 40 Hz
with each time stamp repeated several times (later repeats carry updated sensor values that reappear
in the next time stamp's first row). As the source says, every row whose time equals the previous
row's is dropped, which leaves about 510 rows.

==== ============================================ =============== ============================
col  meaning                                      file unit       here
==== ============================================ =============== ============================
0    time                                         s               ``time`` [s]
1    commanded joint angle (motor side)           deg             ``command`` [rad]
2    commanded velocity                           unknown scale   ``velocity_cmd`` (raw)
3    measured distal bending angle (EM tracker)   deg             ``angle`` [rad]
4    tendon A tension, proximal load cell         N               ``T_a`` [N]
5    tendon B tension, proximal load cell         N               ``T_b`` [N]
6, 7 motor signals (probably mA)                  unknown         ``motor_a``, ``motor_b`` (raw)
==== ============================================ =============== ============================
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from teleop.errors import DataError

__all__ = ["CONFIGS_DEG", "KaistRecording", "default_kaist_dir", "find_kaist_dir", "is_kaist_file",
           "kaist_path", "read_kaist", "load_all", "cycles"]

#: Insertion-tube configurations recorded (most likely the accumulated bend angle [deg]).
CONFIGS_DEG = (0, 60, 120, 180, 240)
N_COLUMNS = 8
_NAME = re.compile(r"sine_config_(\d+)\.txt$")
_MISSING_HINT = "these tests need the unlicensed measurements, see docs/findings.md"


@dataclass(frozen=True, eq=False)
class KaistRecording:
    """One configuration's recording; every array has shape (n_samples,), float64.

    Attributes
    ----------
    config_deg : int, insertion-tube configuration N [deg] from the file name.
    time : ndarray [s], strictly increasing (40 Hz).
    command : ndarray [rad], commanded joint angle on the motor side (the proximal reference).
    velocity_cmd : ndarray, commanded velocity, raw file value (scale unknown).
    angle : ndarray [rad], measured distal bending angle.
    T_a, T_b : ndarray [N], proximal tensions of tendons A (rises with + angle) and B.
    motor_a, motor_b : ndarray, raw motor signals (probably mA).
    source : str, the file read.
    """

    config_deg: int
    time: np.ndarray
    command: np.ndarray
    velocity_cmd: np.ndarray
    angle: np.ndarray
    T_a: np.ndarray
    T_b: np.ndarray
    motor_a: np.ndarray
    motor_b: np.ndarray
    source: str

    def __len__(self) -> int:
        return int(self.time.shape[0])

    @property
    def pretension(self) -> tuple[float, float]:
        """Tensions of tendons A and B at the first sample [N] (the preload, about 5 N)."""
        return float(self.T_a[0]), float(self.T_b[0])


def default_kaist_dir() -> Path:
    """``<repo>/../shared/data/kaist-tsm``, where the project expects the data by default."""
    return Path(__file__).resolve().parents[1].parent / "shared" / "data" / "kaist-tsm"


def kaist_path(directory: str | Path, config_deg: int) -> Path:
    """Path of configuration ``config_deg`` [deg] inside ``directory``."""
    return Path(directory) / f"sine_config_{int(config_deg)}.txt"


def find_kaist_dir(path: str | Path | None = None) -> Path:
    """The directory holding the KAIST files.

    Parameters
    ----------
    path : str or Path, optional
        A directory given by the user; default :func:`default_kaist_dir`.

    Raises
    ------
    DataError
        The directory does not exist or holds none of the ``sine_config_N.txt`` files.
    """
    d = Path(path) if path is not None else default_kaist_dir()
    if not d.is_dir() or not any(kaist_path(d, n).is_file() for n in CONFIGS_DEG):
        raise DataError(f"KAIST data not found at {d}: {_MISSING_HINT}")
    return d


def is_kaist_file(path: str | Path) -> bool:
    """True when the file name is ``sine_config_<N>.txt`` (the name alone decides)."""
    return _NAME.search(Path(path).name) is not None


def _parse_rows(path: Path) -> tuple[np.ndarray, list[int]]:
    """Numeric rows (n_rows, 8) with duplicate time stamps dropped, and their 1-based line numbers."""
    src = str(path)
    rows: list[list[float]] = []
    lines: list[int] = []
    prev_time: float | None = None
    try:
        fh = open(path, encoding="utf-8", errors="replace")
    except FileNotFoundError:
        raise DataError(f"{src}: no such file") from None
    except OSError as exc:
        raise DataError(f"{src}: cannot read ({exc.strerror})") from None
    with fh:
        for lineno, raw in enumerate(fh, start=1):
            line = raw.strip()
            if not line:
                continue
            fields = line.split(",")
            if len(fields) == N_COLUMNS + 1 and not fields[-1].strip():
                fields = fields[:-1]                     # the trailing comma
            if len(fields) != N_COLUMNS:
                raise DataError(f"{src}:{lineno}: expected {N_COLUMNS} comma-separated numbers "
                                f"(and a trailing comma), found {len(fields)}")
            values = []
            for j, text in enumerate(fields):
                try:
                    v = float(text)
                except ValueError:
                    raise DataError(f"{src}:{lineno}: column {j}: expected a number, "
                                    f"got '{text.strip()}'") from None
                if not math.isfinite(v):
                    raise DataError(f"{src}:{lineno}: column {j}: expected a finite number, "
                                    f"got '{text.strip()}'")
                values.append(v)
            t = values[0]
            if prev_time is not None and t == prev_time:
                continue                                 # repeated time stamp: drop (SOURCE.md)
            if prev_time is not None and t < prev_time:
                raise DataError(f"{src}:{lineno}: column 0: time {t} s goes back "
                                f"(previous row {prev_time} s)")
            prev_time = t
            rows.append(values)
            lines.append(lineno)
    if len(rows) < 2:
        raise DataError(f"{src}: {len(rows)} distinct time stamp(s), need at least 2")
    return np.asarray(rows, dtype=np.float64), lines


def read_kaist(path: str | Path, config_deg: int | None = None) -> KaistRecording:
    """Read one ``sine_config_N.txt`` file; degrees become radians, tensions stay in N.

    Parameters
    ----------
    path : str or Path
    config_deg : int, optional
        Configuration [deg]; default: the N of the file name.

    Raises
    ------
    DataError
        Missing file; a row without 8 numbers, a non-number or non-finite value (file:line,
        column); time going back; fewer than 2 distinct time stamps; no N in the name and
        ``config_deg`` not given.
    """
    path = Path(path)
    if config_deg is None:
        m = _NAME.search(path.name)
        if m is None:
            raise DataError(f"{path}: file name is not sine_config_<N>.txt and no configuration was given")
        config_deg = int(m.group(1))
    a, _ = _parse_rows(path)
    deg = math.pi / 180.0
    return KaistRecording(config_deg=int(config_deg), time=a[:, 0].copy(), command=a[:, 1] * deg,
                          velocity_cmd=a[:, 2].copy(), angle=a[:, 3] * deg, T_a=a[:, 4].copy(),
                          T_b=a[:, 5].copy(), motor_a=a[:, 6].copy(), motor_b=a[:, 7].copy(),
                          source=str(path))


def load_all(path: str | Path | None = None) -> list[KaistRecording]:
    """Every configuration of :data:`CONFIGS_DEG`, in that order.

    Raises
    ------
    DataError
        Directory not found (see :func:`find_kaist_dir`), a configuration file missing (all missing
        ones named), or a malformed file.
    """
    d = find_kaist_dir(path)
    missing = [kaist_path(d, n).name for n in CONFIGS_DEG if not kaist_path(d, n).is_file()]
    if missing:
        raise DataError(f"{d}: missing KAIST file(s) {', '.join(missing)}")
    return [read_kaist(kaist_path(d, n), n) for n in CONFIGS_DEG]


def cycles(rec: KaistRecording, arm_fraction: float = 0.5) -> list[slice]:
    """Split a recording into its complete sine cycles of the command.

    A cycle starts where the command crosses zero upward (the first one at sample 0 when the
    recording starts at rest near zero, as the KAIST runs do); a crossing counts only after the
    command went below ``-arm_fraction`` of its amplitude, so noise near zero cannot split a cycle.
    The tail after the last crossing (an incomplete cycle) is left out.

    Parameters
    ----------
    rec : KaistRecording
    arm_fraction : float, in (0, 1)

    Returns
    -------
    list of slice
        Sample ranges of the complete cycles, in time order (2 for the KAIST runs, ~6.28 s each).
    """
    c = rec.command
    amp = float(np.max(np.abs(c)))
    if amp == 0.0:
        return []
    starts: list[int] = []
    if abs(c[0]) < 0.05 * amp and c[min(len(c) - 1, 5)] >= c[0]:
        starts.append(0)
    armed = not starts and c[0] < 0
    for k in range(1, len(c)):
        if c[k] < -arm_fraction * amp:
            armed = True
        elif armed and c[k - 1] < 0 <= c[k]:
            starts.append(k)
            armed = False
    return [slice(a, b) for a, b in zip(starts[:-1], starts[1:])]
