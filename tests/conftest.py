"""Every test, and every process a test starts, uses installation credentials of its own
(teleop/session/credentials.py): a folder per test worker, never the user's ``~/.config/tsm-teleop/keys``."""
from __future__ import annotations

import atexit
import os
import shutil
import tempfile
from pathlib import Path

from teleop.session.credentials import KEYS_ENV

_ROOT = Path(tempfile.mkdtemp(prefix="tsm-teleop-test-keys-"))
os.environ[KEYS_ENV] = str(_ROOT / "keys")
atexit.register(shutil.rmtree, _ROOT, True)
