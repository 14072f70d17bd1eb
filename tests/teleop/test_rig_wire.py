"""The rig interface's byte format (teleop.wire.rig): round trip, and every refusal named."""
from __future__ import annotations

import math

import pytest

from teleop.errors import CodecError
from teleop.wire.codec import encode
from teleop.wire.messages import Command
from teleop.wire.rig import MAX_TENDONS, RigSample, RigSetpoint, decode_rig, encode_rig


def test_round_trip_with_and_without_truth():
    sp = RigSetpoint(7, 1.25, (0.001, -0.002), tissue=0)
    assert decode_rig(encode_rig(sp)) == sp and len(encode_rig(sp)) == 3 + 14 + 16
    s = RigSample(8, 7, 2.5, (0.001,), (10.0,), (0.0011,), ((10.1, 9.0, 0.00101, 0.0002, 0.0008),))
    assert decode_rig(encode_rig(s)) == s and len(encode_rig(s)) == 3 + 18 + 24 + 40
    bare = RigSample(9, 8, 2.6, (0.001, 0.002), (10.0, 11.0), (0.0, 0.0))
    assert decode_rig(encode_rig(bare)) == bare


@pytest.mark.parametrize("msg, match", [
    (RigSetpoint(1, 0.0, ()), "0 tendons"),
    (RigSetpoint(1, 0.0, (math.nan,)), "finite"),
    (RigSetpoint(1, 0.0, (0.0,) * (MAX_TENDONS + 1)), "tendons"),
    (RigSample(1, 0, 0.0, (0.0,), (0.0, 1.0), (0.0,)), "one entry per tendon"),
    (RigSample(1, 0, 0.0, (0.0,), (math.inf,), (0.0,)), "finite"),
    (RigSetpoint(-1, 0.0, (0.0,)), "does not fit"),
])
def test_bad_messages_are_refused_when_encoding(msg, match):
    with pytest.raises(CodecError, match=match):
        encode_rig(msg)


def test_bad_buffers_are_refused_when_decoding():
    good = encode_rig(RigSetpoint(1, 0.0, (0.0,)))
    with pytest.raises(CodecError, match="not a rig message"):
        decode_rig(encode(Command(1, 0.0, (0.0,))))                # a teleop message is not a rig message
    with pytest.raises(CodecError, match="version"):
        decode_rig(good[:1] + bytes([9]) + good[2:])
    with pytest.raises(CodecError, match="expected 25"):
        decode_rig(good + b"\0")
    with pytest.raises(CodecError, match="truncated"):
        decode_rig(good[:2])
    with pytest.raises(CodecError, match="type 3"):
        decode_rig(good[:2] + bytes([3]) + good[3:])
