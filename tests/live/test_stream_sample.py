"""The recorder's thinned in-memory copy of a stream without a CSV (live/record_files.StreamSample): every
SAMPLE_EVERY-th message, halved and its stride doubled at SAMPLE_ROWS rows, in one array sized at the start."""
from __future__ import annotations

import numpy as np

from live.record import files as record_files
from live.record.files import StreamSample


def test_rows_are_evenly_thinned_in_one_array_of_fixed_size(monkeypatch):
    monkeypatch.setattr(record_files, "SAMPLE_ROWS", 8)
    monkeypatch.setattr(record_files, "SAMPLE_EVERY", 2)
    sample = StreamSample("estimate", ("a", "b"))
    buffer = sample.data
    for i in range(40):
        sample.write(0.001 * i, lambda i=i: [float(i), -float(i)])
    stream = sample.stream()
    assert sample.data is buffer and buffer.shape == (8, 3)      # no growth: the same array throughout
    kept = stream.data[:, 1]
    assert list(kept) == sorted(kept) and len(set(np.diff(kept))) == 1   # evenly spaced, in order
    assert kept[0] == 0.0 and stream.data.shape[1] == 3
    np.testing.assert_array_equal(stream.data[:, 2], -kept)
    np.testing.assert_allclose(stream.data[:, 0], 0.001 * kept)
    assert sample.every == 8 and len(kept) == 5                  # 0, 8, 16, 24, 32


def test_an_empty_stream_has_no_rows():
    assert StreamSample("command", ("x",)).stream().data.size == 0
