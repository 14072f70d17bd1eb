"""A side's files on a full disk: the CSV writing process (teleop/recording/csv_proc.py) and the write-ahead
journal (teleop/recording/journal.py) keep what they handed to the OS, drop and count the rest, and never raise
into the caller (the control loop). Run in a subprocess under a file-size limit (RLIMIT_FSIZE, SIGXFSZ
ignored: a write past it fails with EFBIG, as a write to a full disk fails with ENOSPC)."""
from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import pytest

LIMIT = 20_000      # [B] largest file the subprocess may write

SCRIPT = textwrap.dedent("""
    import json, resource, signal, sys
    from pathlib import Path
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, ({limit}, {limit}))
    from teleop.recording.csv_proc import ProcessCsvRecorder
    from teleop.recording.journal import Journal, JournalReader
    d = Path(sys.argv[1])
    rec = ProcessCsvRecorder(d / "side.csv", ["time", "x_in"], flush_interval=0.001)
    j = Journal(d, "slave")
    for k in range(2000):                      # the loop's calls: none may raise
        rec.write((1e-3 * k, 1e-5 * k))
        j.append("teleop/x/slave/estimate", k.to_bytes(4, "little") * 8)
    rec.close()
    j.close()
    kept = [int.from_bytes(p[:4], "little") for _, _, p in JournalReader(d, "slave").new_records()]
    print(json.dumps({{"csv": [rec.rows_written, rec.dropped, rec.error], "journal": [j.records, j.lost, j.error],
                      "kept": kept}}))
""")


def test_a_full_disk_under_a_side_keeps_what_was_written_and_counts_the_rest(tmp_path):
    out = subprocess.run([sys.executable, "-c", SCRIPT.format(limit=LIMIT), str(tmp_path)], capture_output=True,
                         text=True, timeout=60)
    assert out.returncode == 0, out.stderr[-2000:]
    r = json.loads(out.stdout.strip().splitlines()[-1])
    rows, dropped, error = r["csv"]
    assert "File too large" in error and dropped > 0
    lines = (tmp_path / "side.csv").read_text().splitlines()
    data = [ln for ln in lines if ln and not ln.startswith(("#", "time,"))]
    whole = [ln for ln in data if ln.count(",") == 1]
    assert len(whole) >= len(data) - 1                        # at most the last line is cut
    assert [float(ln.split(",")[0]) for ln in whole] == pytest.approx([1e-3 * k for k in range(len(whole))])
    assert len(whole) + dropped >= 2000 - 1
    records, lost, jerror = r["journal"]
    assert ("File too large" in jerror or "short write" in jerror) and records + lost == 2000
    assert r["kept"] == list(range(records))                  # every journaled record reads back, in order
