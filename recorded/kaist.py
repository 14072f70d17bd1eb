"""Importer for the KAIST flexible-endoscope recordings (antagonistic tendon pair) and similar data.

The files (``sine_config_N.txt`` in the project's folder ``kaist-tsm``, ``optimization/selected/N.txt`` in a
clone of the source repository; N the tube configuration in degrees) are described in the folder's
``SOURCE.md`` and in docs/how-to/get-the-data.md; :mod:`recorded.kaist_files` finds them in either layout. They
have **no licence**: this module reads them where they lie (the data folder, ``TSM_TELEOP_DATA``, or a
directory the user gives) and the project never copies them or per-sample data derived from them.

The 8-column files are comma separated, no header, with a trailing comma, logged at 40 Hz with each
time stamp repeated several times; as the source says, every row whose time equals the previous
row's is dropped, which leaves about 510 rows. The reader is :func:`recorded.columns.read_table`: the
same importer reads the longer 10-column KAIST recordings (about 2 kHz, repeated stamps, all-zero
columns, a time reset) and other labs' CSV files through a column map
(:func:`recorded.columns.parse_column_map`). Recordings faster than twice :data:`RATE_HZ` are
averaged in blocks down to :data:`RATE_HZ` (the pair models are rate-independent).

==== ============================================ =============== ============================
col  meaning (8-column KAIST map)                 file unit       here
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
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from estimator.errors import DataError
from recorded.columns import ColumnMap, read_table
from recorded.kaist_files import config_of, find_configs, find_kaist_dir, kaist_path

__all__ = [
    "CONFIGS_DEG", "RATE_HZ", "KaistRecording", "read_kaist", "read_kaist_recording", "load_all", "load_dir",
    "resample", "cycles", "split",
]

#: Insertion-tube configurations [deg] of the project's folder kaist-tsm and of the results pages (a clone of the
#: source repository holds these and five more: 30, 90, 150, 210, 270).
CONFIGS_DEG = (0, 60, 120, 180, 240)
#: Rate [Hz] the recordings are analysed at (the 40 Hz of the shipped files).
RATE_HZ = 40.0


@dataclass(frozen=True, eq=False)
class KaistRecording:
    """One configuration's recording; every array has shape (n_samples,), float64.

    Attributes
    ----------
    config_deg : float, insertion-tube configuration N [deg] (file name or ``--bend``); an int when whole.
    time : ndarray [s], strictly increasing.
    command : ndarray [rad], commanded joint angle on the motor side (the proximal reference).
    velocity_cmd : ndarray, commanded velocity, raw file value (scale unknown; nan when not mapped).
    angle : ndarray [rad], measured distal bending angle.
    T_a, T_b : ndarray [N], proximal tensions of tendons A (rises with + angle) and B.
    motor_a, motor_b : ndarray, raw motor signals (probably mA; nan when not mapped).
    source : str, the file read.
    notes : tuple of str, what the importer did (columns used, rows dropped, resets, resampling).
    """

    config_deg: float
    time: np.ndarray
    command: np.ndarray
    velocity_cmd: np.ndarray
    angle: np.ndarray
    T_a: np.ndarray
    T_b: np.ndarray
    motor_a: np.ndarray
    motor_b: np.ndarray
    source: str
    notes: tuple = field(default=())

    def __len__(self) -> int:
        return int(self.time.shape[0])

    @property
    def pretension(self) -> tuple[float, float]:
        """Tensions of tendons A and B at the first sample [N] (the preload, about 5 N)."""
        return float(self.T_a[0]), float(self.T_b[0])

    @property
    def rate_hz(self) -> float:
        """Median sample rate [Hz]."""
        return float(1.0 / np.median(np.diff(self.time)))


def resample(rec: KaistRecording, rate_hz: float = RATE_HZ) -> KaistRecording:
    """Block means over bins of 1 / ``rate_hz`` seconds (empty bins dropped); ``rec`` itself when it
    is not faster than twice ``rate_hz``. The note records the rates."""
    if len(rec) < 3 or rec.rate_hz <= 2.0 * rate_hz:
        return rec
    b = np.floor((rec.time - rec.time[0]) * rate_hz).astype(np.int64)
    starts = np.flatnonzero(np.r_[True, b[1:] != b[:-1]])
    counts = np.diff(np.r_[starts, b.size])

    def mean(x):
        return np.add.reduceat(x, starts) / counts

    names = ("time", "command", "velocity_cmd", "angle", "T_a", "T_b", "motor_a", "motor_b")
    arrays = {n: mean(getattr(rec, n)) for n in names}
    arrays["time"][0], arrays["command"][0], arrays["angle"][0] = rec.time[0], rec.command[0], rec.angle[0]
    arrays["T_a"][0], arrays["T_b"][0] = rec.T_a[0], rec.T_b[0]       # the rest state stays the first sample
    note = f"resampled from {rec.rate_hz:.0f} Hz to {rate_hz:.0f} Hz (block means; first sample kept)"
    return KaistRecording(rec.config_deg, **arrays, source=rec.source, notes=rec.notes + (note,))


def read_kaist(path: str | Path, config_deg: float | None = None, column_map: ColumnMap | None = None,
               rate_hz: float | None = RATE_HZ) -> KaistRecording:
    """Read one recording; degrees become radians (unless the map says rad), tensions stay in N.

    Parameters
    ----------
    path : str or Path
    config_deg : float, optional
        Configuration [deg]; default: the N of the file's name (``sine_config_<N>.txt``, or ``<N>.txt`` in a
        clone's ``optimization/selected``; :func:`recorded.kaist_files.config_of`).
    column_map : default the 8-column KAIST map (:data:`recorded.columns.KAIST_MAP`)
    rate_hz : resample faster recordings to this rate (:func:`resample`); None keeps every sample

    Raises
    ------
    DataError
        Missing file; a malformed row (file:line, column); a required column all zero; fewer than 2
        distinct time stamps; no N in the name and ``config_deg`` not given.
    """
    path = Path(path)
    if config_deg is None:
        config_deg = config_of(path)
        if config_deg is None:
            raise DataError(f"{path}: file name is not sine_config_<N>.txt and no bend was given (--bend DEG); a "
                            "clone's optimization/selected/<N>.txt names it too")
    tab = read_table(path, column_map)
    k = math.pi / 180.0 if tab.column_map.units == "deg" else 1.0
    d = tab.data
    nan = np.full(d["time"].size, np.nan)
    rec = KaistRecording(config_deg=config_deg, time=d["time"], command=d["command"] * k,
                         velocity_cmd=d.get("velocity_cmd", nan), angle=d["angle"] * k, T_a=d["T_a"], T_b=d["T_b"],
                         motor_a=d.get("motor_a", nan), motor_b=d.get("motor_b", nan), source=str(path),
                         notes=tuple(tab.notes))
    return resample(rec, rate_hz) if rate_hz else rec


def read_kaist_recording(path: str | Path) -> KaistRecording:
    """A KAIST recording whose format its content showed (the recording rig): :func:`read_kaist` with the
    configuration its name gives (:func:`recorded.kaist_files.config_of`), else nan (the rig needs none)."""
    n = config_of(path)
    return read_kaist(path, math.nan if n is None else n)


def load_dir(path: str | Path | None = None, column_map: ColumnMap | None = None,
             rate_hz: float | None = RATE_HZ, configs: tuple[float, ...] | None = None
             ) -> tuple[list[KaistRecording], list[str]]:
    """Every configuration under a directory (either layout, :func:`recorded.kaist_files.kaist_files`), sorted by
    N, or only those of ``configs``; and one line per file that could not be read (``"<file>: <why>"``), which
    is left out.

    Raises
    ------
    DataError
        The directory does not exist or holds no configuration (:func:`find_kaist_dir`), or a configuration of
        ``configs`` is not there (the ones there named).
    """
    d = find_kaist_dir(path)
    found = find_configs(d)
    if configs is not None:
        absent = [n for n in configs if n not in {m for m, _ in found}]
        if absent:
            raise DataError(f"{d}: no configuration {', '.join(f'{n:g}' for n in absent)} (--configs); the folder "
                            f"holds {', '.join(f'{n:g}' for n, _ in found)}")
        found = [(n, p) for n, p in found if n in configs]
    recs, problems = [], []
    for n, p in found:
        try:
            recs.append(read_kaist(p, n, column_map, rate_hz))
        except DataError as e:
            problems.append(str(e) if str(e).startswith(str(p)) else f"{p}: {e}")
    return recs, problems


def load_all(path: str | Path | None = None) -> list[KaistRecording]:
    """Every configuration of :data:`CONFIGS_DEG`, in that order (the shipped set; strict).

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
    return [slice(a, b) for a, b in zip(starts[:-1], starts[1:], strict=False)]


def split(rec: KaistRecording) -> tuple[slice, slice, str]:
    """Training and test samples of a recording, and how they were chosen.

    With >= 2 complete command cycles (:func:`cycles`): training = from the first sample to the end of
    cycle 1, test = the later complete cycles. Otherwise the first half of the samples and the rest
    (a recording whose command is not a repeated cycle).

    Raises
    ------
    DataError
        Fewer than 16 samples.
    """
    n = len(rec)
    if n < 16:
        raise DataError(f"{rec.source}: {n} samples, too few to split into training and test")
    cs = cycles(rec)
    if len(cs) >= 2:
        return slice(0, cs[0].stop), slice(cs[1].start, cs[-1].stop), \
            f"train: command cycle 1 (t < {rec.time[cs[0].stop]:.2f} s); test: cycles 2-{len(cs)}"
    h = n // 2
    return slice(0, h), slice(h, n), \
        f"{len(cs)} complete command cycle(s): train on t < {rec.time[h]:.2f} s, test after"
