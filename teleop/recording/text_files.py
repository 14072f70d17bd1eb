"""The input files of the offline readers, checked before they are parsed: a path that is no file, and a file
that is not UTF-8 text, end in one line naming the file (docs/reference/formats.md).

:func:`require_file` tells a missing path from a directory. :func:`text_problem` says what bytes that are not
UTF-8 text look like: UTF-16 or UTF-32 (a byte-order mark, or NUL bytes at every other or every fourth byte, as
text saved by some spreadsheet and Windows tools is), binary data (a NUL or another control byte) or text in
another encoding (a byte that is not UTF-8, with its line), each with the byte offset where it shows.
:func:`read_text` reads a whole file through these checks (or lets a stray byte of another encoding through as
U+FFFD, for the readers that skip a header line); a streaming reader calls :func:`check_text_head` on
the file's first bytes and turns a later ``UnicodeDecodeError`` into :func:`not_text_error`.
"""
from __future__ import annotations

import codecs
import re
from pathlib import Path

from estimator.errors import DataError

__all__ = ["require_file", "text_problem", "not_text_error", "check_text_head", "read_text", "HEAD_BYTES"]

#: bytes a streaming reader checks before parsing (:func:`check_text_head`)
HEAD_BYTES = 1 << 16

_BOMS = ((codecs.BOM_UTF32_LE, "UTF-32"), (codecs.BOM_UTF32_BE, "UTF-32"),
         (codecs.BOM_UTF16_LE, "UTF-16"), (codecs.BOM_UTF16_BE, "UTF-16"))
#: control bytes, which no text file of numbers holds (tab, line feed, form feed and carriage return are text)
_CONTROL = re.compile(rb"[\x00-\x08\x0b\x0e-\x1f\x7f]")


def require_file(path: str | Path) -> Path:
    """``path`` as a Path when it is a regular file.

    Raises
    ------
    DataError
        ``"<path>: no such file"``, ``"<path>: is a directory, not a file"`` or ``"<path>: not a regular
        file"`` (a device, a pipe).
    """
    p = Path(path)
    if p.is_dir():
        raise DataError(f"{p}: is a directory, not a file")
    if not p.exists():
        raise DataError(f"{p}: no such file")
    if not p.is_file():
        raise DataError(f"{p}: not a regular file")
    return p


def _nul_stride(data: bytes) -> int:
    """2 or 4 when the NUL bytes of ``data`` fall at every other or every fourth byte (UTF-16 / UTF-32 text of
    ASCII characters without a byte-order mark); 0 otherwise."""
    sample = data[:4096]
    for stride, share in ((4, 3), (2, 1)):
        n = len(sample) // stride
        if n >= 4 and sample.count(0) >= 0.9 * share * n:
            lanes = [sample[k::stride].count(0) for k in range(stride)]
            if sum(1 for c in lanes if c >= 0.9 * n) == share:
                return stride
    return 0


def text_problem(data: bytes, final: bool = True) -> tuple[str, int | None] | None:
    """What ``data``, a file's bytes from its first, looks like when it is not UTF-8 text; None when it is.

    Parameters
    ----------
    data : the file's bytes, or its first bytes
    final : False when ``data`` is only the head of the file (a character cut at its end is not an error)

    Returns
    -------
    (str, int or None) or None
        What the bytes look like, e.g. ``"looks like UTF-16 text, byte-order mark at byte 0"``, ``"looks like
        binary data, byte 0x00 at byte 128"``, ``"byte 0xb0 at byte 37 is not UTF-8: text in another encoding
        such as Latin-1?"``, and the line (1-based) of a byte that is not UTF-8 in text (None for the others).
        A UTF-8 byte-order mark is text.
    """
    for bom, name in _BOMS:
        if data.startswith(bom):
            return f"looks like {name} text, byte-order mark at byte 0", None
    stride = _nul_stride(data)
    if stride:
        return (f"looks like UTF-{8 * stride} text, NUL bytes at every {'other' if stride == 2 else 'fourth'} "
                f"byte from byte {data.index(0)}", None)
    ctrl = _CONTROL.search(data)
    if ctrl is not None:
        return f"looks like binary data, byte 0x{data[ctrl.start()]:02x} at byte {ctrl.start()}", None
    try:
        codecs.getincrementaldecoder("utf-8")().decode(data, final)
    except UnicodeDecodeError as e:
        return (f"byte 0x{data[e.start]:02x} at byte {e.start} is not UTF-8: text in another encoding such as "
                "Latin-1?", data.count(b"\n", 0, e.start) + 1)
    return None


def _message(path: Path, problem: tuple[str, int | None]) -> DataError:
    what, line = problem
    hint = "the reader takes text" if "binary" in what else "save it as UTF-8"
    return DataError(f"{path}{'' if line is None else f':{line}'}: not a UTF-8 text file ({what}); {hint}")


def check_text_head(path: str | Path) -> None:
    """Check the first :data:`HEAD_BYTES` bytes of ``path`` (:func:`text_problem`).

    Raises
    ------
    DataError
        ``"<path>: not a UTF-8 text file (<what it looks like>); save it as UTF-8"`` (or, for binary data,
        ``"...; the reader takes text"``), or the file cannot be read.
    """
    p = Path(path)
    try:
        with open(p, "rb") as fh:
            head = fh.read(HEAD_BYTES)
    except OSError as e:
        raise DataError(f"{p}: cannot read ({e.strerror})") from None
    problem = text_problem(head, final=len(head) < HEAD_BYTES)
    if problem is not None:
        raise _message(p, problem)


def not_text_error(path: str | Path) -> DataError:
    """The DataError for a file that failed to decode as UTF-8 (a ``UnicodeDecodeError`` in a streaming reader):
    the whole file is read to name what it looks like and where."""
    p = Path(path)
    data = p.read_bytes()
    return _message(p, text_problem(data) or ("a byte that is not UTF-8", None))


def read_text(path: str | Path, *, replace: bool = False) -> str:
    """The whole of a UTF-8 text file (:func:`require_file`, :func:`text_problem`; a UTF-8 byte-order mark is
    skipped). ``replace``: a byte that is not UTF-8 in a file that is otherwise text (a Latin-1 degree sign in a
    logger's header line) reads as U+FFFD instead of raising; UTF-16, UTF-32 and binary data raise all the same.

    Raises
    ------
    DataError
        No such file, a directory, a file that cannot be read, or one that is not UTF-8 text (what it looks
        like, at which byte).
    """
    p = require_file(path)
    try:
        data = p.read_bytes()
    except OSError as e:
        raise DataError(f"{p}: cannot read ({e.strerror})") from None
    problem = text_problem(data)
    if problem is not None and not (replace and problem[1] is not None):
        raise _message(p, problem)
    return data.decode("utf-8-sig", errors="replace" if replace else "strict")
