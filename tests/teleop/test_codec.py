"""Wire codec: round trips over random messages, the pinned layout, every rejection."""
from __future__ import annotations

import math
import random
import struct

import numpy as np
import pytest

from teleop import codec
from teleop.codec import MAGIC, WIRE_VERSION, decode, encode, next_seq
from teleop.errors import CodecError
from teleop.messages import Command, Estimate, Heartbeat, Phase, Side, SideState

N_RANDOM = 300


def _f(rng: random.Random) -> float:
    """A finite float64 over many magnitudes and both signs (and exact zeros)."""
    if rng.random() < 0.05:
        return 0.0
    return rng.choice((-1.0, 1.0)) * 10.0 ** rng.uniform(-12, 12)


def _u32(rng: random.Random) -> int:
    return rng.choice((0, 1, 2**32 - 1, rng.randrange(2**32)))


def test_command_round_trip_random():
    rng = random.Random(1)
    for _ in range(N_RANDOM):
        msg = Command(_u32(rng), _f(rng), _f(rng), rng.random() < 0.5, _u32(rng))
        out = decode(encode(msg))
        assert out == msg
        assert type(out.engaged) is bool


def test_estimate_round_trip_random_profile_in_float32():
    rng = random.Random(2)
    for _ in range(N_RANDOM):
        n = rng.choice((0, 1, 50, rng.randrange(300)))
        profile = tuple(rng.uniform(-1e3, 1e3) for _ in range(n))
        msg = Estimate(_u32(rng), _u32(rng), _f(rng), _f(rng), _f(rng), _f(rng), _f(rng), _f(rng),
                       rng.choice(list(Phase)), profile)
        out = decode(encode(msg))
        assert out.profile == tuple(float(x) for x in np.asarray(profile, dtype=np.float32))
        assert out == Estimate(**{**msg.__dict__, "profile": out.profile})
        assert isinstance(out.phase, Phase)


def test_estimate_accepts_numpy_profile():
    prof = np.linspace(10.0, 2.0, 50)
    msg = Estimate(1, 2, 0.5, 10.0, 0.01, 2.0, 1e-4, 0.0099, Phase.PULL, tuple(prof))
    assert decode(encode(msg)).profile == pytest.approx(tuple(prof), rel=1e-6)


def test_heartbeat_round_trip_random():
    rng = random.Random(3)
    for _ in range(N_RANDOM):
        msg = Heartbeat(rng.choice(list(Side)), _u32(rng), _f(rng), rng.choice(list(SideState)))
        out = decode(encode(msg))
        assert out == msg and isinstance(out.side, Side) and isinstance(out.state, SideState)


def test_layout_is_pinned():
    """The documented layout, built by hand, decodes; a change of layout must change WIRE_VERSION."""
    assert (MAGIC, WIRE_VERSION) == (0xA7, 2)
    cmd = struct.pack("<BBBIddBI", 0xA7, 2, 1, 7, 1.5, -0.002, 1, 3)
    assert encode(Command(7, 1.5, -0.002, True, 3)) == cmd
    assert len(cmd) == 28
    est = struct.pack("<BBBIIddddddBH2f", 0xA7, 2, 2, 5, 4, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 2, 2, 0.5, 0.25)
    assert decode(est) == Estimate(5, 4, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, Phase.RELEASE, (0.5, 0.25))
    assert len(encode(Estimate(0, 0, 0, 0, 0, 0, 0, 0, Phase.HOLD, (1.0,) * 50))) == 62 + 4 * 50
    hb = struct.pack("<BBBBIdB", 0xA7, 2, 3, 2, 9, 0.25, 3)
    assert decode(hb) == Heartbeat(Side.SLAVE, 9, 0.25, SideState.ENGAGED)


def test_next_seq_wraps_at_uint32():
    assert next_seq(0) == 1
    assert next_seq(2**32 - 1) == 0


# ---- rejections on decode ------------------------------------------------------------------------

GOOD_CMD = encode(Command(1, 2.0, 3.0))
GOOD_EST = encode(Estimate(1, 1, 0.0, 1.0, 0.0, 1.0, 0.0, 0.0, Phase.HOLD, (1.0, 2.0, 3.0)))
GOOD_HB = encode(Heartbeat(Side.MASTER, 1, 0.0, SideState.READY))


@pytest.mark.parametrize("buf, match", [
    (b"", "truncated: 0 bytes"),
    (b"\xa7\x01", "truncated: 2 bytes"),
    (GOOD_CMD[:-1], "Command message truncated"),
    (GOOD_CMD + b"\x00", "Command message too long"),
    (GOOD_HB[:10], "Heartbeat message truncated"),
    (GOOD_EST[:20], "Estimate message truncated"),
    (b"\x00" + GOOD_CMD[1:], "magic byte 0x00"),
    (GOOD_CMD[:1] + b"\x03" + GOOD_CMD[2:], r"message version 3, this build speaks 2"),
    (GOOD_CMD[:2] + b"\x09" + GOOD_CMD[3:], "unknown message type 9"),
    (GOOD_EST[:-4], "profile count 3 needs"),
    (GOOD_EST + b"\x00\x00\x80\x3f", "profile count 3 needs"),
])
def test_decode_rejects(buf, match):
    with pytest.raises(CodecError, match=match):
        decode(buf)


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_decode_rejects_non_finite_in_every_float_field(bad):
    cmd = struct.Struct("<BBBIddBI")
    for i, name in ((4, "t_master"), (5, "x_in_cmd")):
        fields = [0xA7, WIRE_VERSION, 1, 1, 0.0, 0.0, 1, 0]
        fields[i] = bad
        with pytest.raises(CodecError, match=f"Command.{name} is"):
            decode(cmd.pack(*fields))
    est = struct.Struct("<BBBIIddddddBH2f")
    for i, name in enumerate(("t_slave", "T_in", "x_in", "T_out_hat", "elongation_hat", "x_out_hat")):
        fields = [0xA7, WIRE_VERSION, 2, 1, 1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0, 2, 1.0, 1.0]
        fields[5 + i] = bad
        with pytest.raises(CodecError, match=f"Estimate.{name} is"):
            decode(est.pack(*fields))
    fields = [0xA7, WIRE_VERSION, 2, 1, 1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0, 2, 1.0, bad]
    with pytest.raises(CodecError, match=r"Estimate.profile\[1\] is"):
        decode(est.pack(*fields))
    with pytest.raises(CodecError, match="Heartbeat.t_sender is"):
        decode(struct.pack("<BBBBIdB", 0xA7, WIRE_VERSION, 3, 1, 0, bad, 0))


def test_decode_rejects_bad_enums_and_bools():
    with pytest.raises(CodecError, match="Estimate.phase 7 is not a Phase"):
        decode(struct.pack("<BBBIIddddddBH", 0xA7, WIRE_VERSION, 2, 0, 0, 0, 0, 0, 0, 0, 0, 7, 0))
    with pytest.raises(CodecError, match="Heartbeat.side 0 is not a Side"):
        decode(struct.pack("<BBBBIdB", 0xA7, WIRE_VERSION, 3, 0, 0, 0.0, 0))
    with pytest.raises(CodecError, match="Heartbeat.state 9 is not a SideState"):
        decode(struct.pack("<BBBBIdB", 0xA7, WIRE_VERSION, 3, 1, 0, 0.0, 9))
    with pytest.raises(CodecError, match="Command.engaged byte is 2"):
        decode(struct.pack("<BBBIddBI", 0xA7, WIRE_VERSION, 1, 0, 0.0, 0.0, 2, 0))


def test_decode_accepts_bytearray_and_memoryview():
    assert decode(bytearray(GOOD_CMD)) == decode(memoryview(GOOD_CMD)) == Command(1, 2.0, 3.0)


# ---- rejections on encode ------------------------------------------------------------------------

def test_encode_rejects_what_decode_would():
    with pytest.raises(CodecError, match="Command.x_in_cmd is nan"):
        encode(Command(1, 0.0, math.nan))
    with pytest.raises(CodecError, match="Estimate.T_out_hat is inf"):
        encode(Estimate(1, 1, 0.0, 1.0, 0.0, math.inf, 0.0, 0.0, Phase.HOLD))
    with pytest.raises(CodecError, match=r"Estimate.profile\[2\] is nan"):
        encode(Estimate(1, 1, 0.0, 1.0, 0.0, 1.0, 0.0, 0.0, Phase.HOLD, (1.0, 2.0, math.nan)))
    with pytest.raises(CodecError, match="float32 range"):
        encode(Estimate(1, 1, 0.0, 1.0, 0.0, 1.0, 0.0, 0.0, Phase.HOLD, (1e39,)))
    with pytest.raises(CodecError, match="Heartbeat.t_sender is"):
        encode(Heartbeat(Side.SLAVE, 1, math.nan, SideState.SAFE))


def test_encode_rejects_out_of_range_integers_and_sizes():
    with pytest.raises(CodecError, match=r"Command.seq is 4294967296: expected an integer in \[0, 2\*\*32\)"):
        encode(Command(2**32, 0.0, 0.0))
    with pytest.raises(CodecError, match="Command.marker is -1"):
        encode(Command(0, 0.0, 0.0, True, -1))
    with pytest.raises(CodecError, match="Estimate.cmd_seq is -1"):
        encode(Estimate(0, -1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, Phase.HOLD))
    with pytest.raises(CodecError, match="65536 points: at most 65535"):
        encode(Estimate(0, 0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, Phase.HOLD, (0.0,) * 65536))
    with pytest.raises(CodecError, match="Estimate.phase is 'pull': expected a Phase"):
        encode(Estimate(0, 0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, "pull"))
    with pytest.raises(CodecError, match="Heartbeat.side is 5: expected a Side"):
        encode(Heartbeat(5, 0, 0.0, SideState.READY))
    with pytest.raises(CodecError, match="Heartbeat.state is None: expected a SideState"):
        encode(Heartbeat(Side.MASTER, 0, 0.0, None))
    with pytest.raises(CodecError, match="cannot encode a dict"):
        encode({"seq": 1})


def test_overflowing_sum_of_finite_floats_is_not_rejected():
    msg = Estimate(0, 0, 1e308, 1e308, 1e308, 0.0, 0.0, 0.0, Phase.PULL)
    assert decode(encode(msg)) == msg


def test_max_profile_points_matches_wire_count():
    assert codec.MAX_PROFILE_POINTS == 2**16 - 1
