"""teleop.recording.text_files: a path that is no file, and bytes that are not UTF-8 text, named in one line."""
from __future__ import annotations

import codecs

import pytest

from estimator.errors import DataError
from teleop.recording.text_files import (
    HEAD_BYTES,
    check_text_head,
    not_text_error,
    read_text,
    require_file,
    text_problem,
)

CSV = "time,x_in,T_in\n0,0,1\n0.001,0,1\n"


@pytest.mark.parametrize("data, words", [
    (CSV.encode("utf-16"), "looks like UTF-16 text, byte-order mark at byte 0"),
    (CSV.encode("utf-16-be"), "looks like UTF-16 text, NUL bytes at every other byte from byte 0"),
    (CSV.encode("utf-16-le"), "looks like UTF-16 text, NUL bytes at every other byte from byte 1"),
    (CSV.encode("utf-32"), "looks like UTF-32 text, byte-order mark at byte 0"),
    (CSV.encode("utf-32-le"), "looks like UTF-32 text, NUL bytes at every fourth byte from byte 1"),
    (b"\x89PNG\r\n\x1a\n" + bytes(range(256)), "looks like binary data, byte 0x1a at byte 6"),
    (CSV.encode() + b"\x00\x00", f"looks like binary data, byte 0x00 at byte {len(CSV)}"),
])
def test_what_bytes_that_are_not_text_look_like(data, words):
    what, line = text_problem(data)
    assert what == words and line is None


def test_text_in_another_encoding_is_named_with_its_line():
    what, line = text_problem(("# rig: bench at 20\N{DEGREE SIGN}C\n" + CSV).encode("latin-1"))
    assert what == "byte 0xb0 at byte 18 is not UTF-8: text in another encoding such as Latin-1?" and line == 1
    assert text_problem(CSV.encode()) is None
    assert text_problem(codecs.BOM_UTF8 + CSV.encode()) is None                   # a UTF-8 byte-order mark is text
    assert text_problem("T [\N{DEGREE SIGN}]".encode()[:-2], final=False) is None    # a head cut inside a character


def test_require_file_tells_a_directory_from_a_missing_path(tmp_path):
    with pytest.raises(DataError, match=r"^.*/nope\.csv: no such file$"):
        require_file(tmp_path / "nope.csv")
    with pytest.raises(DataError, match=r": is a directory, not a file$"):
        require_file(tmp_path)
    (tmp_path / "a.csv").write_text(CSV)
    assert require_file(str(tmp_path / "a.csv")) == tmp_path / "a.csv"


def test_read_text_and_the_head_check_name_the_file(tmp_path):
    f = tmp_path / "r.csv"
    f.write_bytes(CSV.encode("utf-16"))
    for call in (read_text, check_text_head):
        with pytest.raises(DataError) as e:
            call(f)
        assert str(e.value) == (f"{f}: not a UTF-8 text file (looks like UTF-16 text, byte-order mark at byte 0); "
                                "save it as UTF-8")
    f.write_bytes(codecs.BOM_UTF8 + CSV.encode())
    assert read_text(f) == CSV
    f.write_bytes(b"% header at 20 \xb0C\n" + CSV.encode())
    with pytest.raises(DataError, match=r"r\.csv:1: not a UTF-8 text file \(byte 0xb0 at byte 15 is not UTF-8"):
        read_text(f)
    assert read_text(f, replace=True).startswith("% header at 20 \N{REPLACEMENT CHARACTER}C\n")
    f.write_bytes(b"\x00\x01binary")
    with pytest.raises(DataError, match=r"looks like binary data, byte 0x00 at byte 0\); the reader takes text$"):
        read_text(f, replace=True)                                              # replace is for text only


def test_a_bad_byte_past_the_head_is_found_when_decoding_fails(tmp_path):
    f = tmp_path / "long.csv"
    body = CSV.encode() + b"0.002,0,1\n" * (HEAD_BYTES // 10 + 10)
    f.write_bytes(body + b"0.5,0,1\xff\n")
    check_text_head(f)                                                          # the head is text
    line = body.count(b"\n") + 1
    assert str(not_text_error(f)) == (f"{f}:{line}: not a UTF-8 text file (byte 0xff at byte "
                                      f"{len(body) + 7} is not UTF-8: text in another encoding such as Latin-1?); "
                                      "save it as UTF-8")
