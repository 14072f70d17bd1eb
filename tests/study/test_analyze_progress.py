"""`teleop analyze` draws its progress bar only on a terminal: a log file or a pipe gets no carriage-return frames."""
from __future__ import annotations

import argparse
import io

import pytest

from estimator.offline.diagnosis.fit import Progress
from study import analyze


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_the_bar_draws_frames_on_a_terminal_and_nothing_elsewhere(monkeypatch):
    for stream, frames in ((_Terminal(), True), (io.StringIO(), False)):
        monkeypatch.setattr("sys.stderr", stream)
        bar = Progress(3, True)
        bar("base model")
        bar.finish()
        assert ("\r" in stream.getvalue()) is frames, stream.getvalue()


def test_analyze_with_stderr_captured_writes_no_progress_frames(tmp_path, monkeypatch, capsys):
    from study.scenarios import record
    from teleop.recording.measured import write_measured_csv

    path = tmp_path / "run.csv"
    write_measured_csv(path, record("friction_offset", seed=3, level=1.0, duration=20.0, rate_hz=200.0).data)
    monkeypatch.setattr(analyze, "PROGRESS_SAMPLES", 1)      # a recording long enough for the bar
    p = argparse.ArgumentParser()
    analyze.add_arguments(p)
    assert analyze.main_analyze(p.parse_args([str(path)])) == 0
    out = capsys.readouterr()
    assert "cause:" in out.out
    assert "\r" not in out.err and "diagnose [" not in out.err, out.err


@pytest.mark.parametrize("calls", [1, 5])
def test_a_progress_callback_is_called_whatever_stderr_is(calls):
    seen = []
    bar = Progress(5, lambda done, total, label: seen.append((done, total, label)))
    for _ in range(calls):
        bar("fit")
    assert seen[-1][:2] == (calls, 5) and len(seen) == calls
