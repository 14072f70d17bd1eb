"""The ``teleop`` program ends with main's exit code even when the interpreter's own exit would block."""
from __future__ import annotations

import subprocess
import sys

# a non-daemon thread that never ends holds the interpreter's exit (as a native runtime's teardown can):
# run() must end the process EXIT_GRACE_S after main returned, with main's code
SCRIPT = """
import threading
import teleop.app.cli as cli
threading.Thread(target=threading.Event().wait, name="stuck").start()
cli.EXIT_GRACE_S = {grace}
cli.main = lambda: 7
cli.run()
"""


def test_run_exits_with_mains_code_when_a_thread_would_hold_the_exit():
    proc = subprocess.run([sys.executable, "-c", SCRIPT.format(grace=0.3)], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 7, proc.stderr


def test_without_the_watchdog_that_thread_holds_the_exit():
    # the control: the same script with the grace beyond the wait is still running when the wait ends
    try:
        subprocess.run([sys.executable, "-c", SCRIPT.format(grace=600)], capture_output=True, text=True, timeout=3)
    except subprocess.TimeoutExpired:
        return
    raise AssertionError("the stuck thread did not hold the exit: the first test proves nothing")
