"""The ``teleop`` program ends with main's exit code even when the interpreter's own exit would block, and
SIGINT stops it even when it was started with SIGINT ignored."""
from __future__ import annotations

import signal
import subprocess
import sys
import time

# a non-daemon thread that never ends holds the interpreter's exit (as a native runtime's teardown can):
# run() must end the process EXIT_GRACE_S after main returned, with main's code
SCRIPT = """
import threading
import live.cli as cli
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


STOPPABLE = """
import time
import live.cli as cli
def fake():
    print("ready", flush=True)
    try:
        time.sleep(60)
    except KeyboardInterrupt:
        return 130
    return 0
cli.main = fake
cli.run()
"""


def test_sigint_stops_the_program_even_when_started_with_sigint_ignored():
    # a non-interactive shell starts background jobs with SIGINT ignored, and Python then installs no
    # KeyboardInterrupt handler: the recorder and the router never saw the tests' SIGINT
    proc = subprocess.Popen([sys.executable, "-c", STOPPABLE], stdout=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))
    try:
        assert proc.stdout is not None and proc.stdout.readline().strip() == "ready"
        time.sleep(0.1)
        proc.send_signal(signal.SIGINT)
        assert proc.wait(20) == 130
    finally:
        proc.kill()
        proc.wait()
