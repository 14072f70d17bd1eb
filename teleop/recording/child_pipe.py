"""The parent's end of a child process's stdin pipe (the CSV and Rerun processes of a side:
teleop/recording/csv_proc.py, teleop/rerun/process.py): pickles written whole, and a child that is gone reported as
False, never raised."""
from __future__ import annotations

import pickle
import subprocess
from typing import Any

__all__ = ["write_bytes", "write_pickle", "close_stdin"]


def write_bytes(proc: subprocess.Popen, data: bytes) -> bool:
    """``data`` onto ``proc``'s stdin; False once the child is gone (its pipe broken or closed)."""
    if proc.stdin is None:
        return False
    try:
        proc.stdin.write(data)
        proc.stdin.flush()
        return True
    except (BrokenPipeError, OSError, ValueError):
        return False


def write_pickle(proc: subprocess.Popen, obj: Any) -> bool:
    """``obj`` pickled (highest protocol) onto ``proc``'s stdin; False once the child is gone."""
    return write_bytes(proc, pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL))


def close_stdin(proc: subprocess.Popen) -> None:
    """Close ``proc``'s stdin (the child reads its end); an error closing it is ignored."""
    try:
        if proc.stdin is not None:
            proc.stdin.close()
    except OSError:
        pass
