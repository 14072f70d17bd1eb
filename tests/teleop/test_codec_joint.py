"""JointCommand / JointEstimate on the wire: round trips, pinned layout, every rejection named."""
from __future__ import annotations

import math
import struct

import numpy as np
import pytest

from estimator.phase import Phase
from teleop.codec import MAGIC, MAX_JOINTS, WIRE_VERSION, decode, encode
from teleop.errors import CodecError
from teleop.messages import JointCommand, JointEstimate, JointState, TendonState


def _joint(rng, phases=(Phase.PULL, Phase.HOLD)):
    f = lambda: float(rng.normal())   # noqa: E731
    return JointState(f(), f(), (TendonState(f(), f(), f(), f(), phases[0]), TendonState(f(), f(), f(), f(), phases[1])))


def test_random_round_trips_keep_every_field_and_type():
    rng = np.random.default_rng(0)
    for _ in range(300):
        n = int(rng.integers(1, MAX_JOINTS + 1))
        cmd = JointCommand(int(rng.integers(0, 2**32)), float(rng.normal()), tuple(rng.normal(size=n)),
                           bool(rng.integers(0, 2)), int(rng.integers(0, 2**32)))
        assert decode(encode(cmd)) == cmd
        points = int(rng.integers(0, 4))
        profiles = tuple(tuple(float(np.float32(v)) for v in rng.uniform(0, 20, points)) for _ in range(2 * n)) \
            if points else ()
        phases = tuple(Phase(int(p)) for p in rng.integers(0, 5, 2))
        est = JointEstimate(int(rng.integers(0, 2**32)), int(rng.integers(0, 2**32)), float(rng.normal()),
                            tuple(_joint(rng, phases) for _ in range(n)), profiles)
        out = decode(encode(est))
        assert out == est and isinstance(out.joints[0].tendons[1].phase, Phase)


def test_layout_is_pinned():
    cmd = struct.pack("<BBBIdBIB2d", MAGIC, WIRE_VERSION, 4, 7, 1.5, 1, 3, 2, 0.25, -0.5)
    assert encode(JointCommand(7, 1.5, (0.25, -0.5), True, 3)) == cmd and len(cmd) == 3 + 18 + 16
    j = JointState(0.01, 0.2, (TendonState(5.0, 1e-3, 3.0, 1e-4, Phase.PULL), TendonState(0.3, -1e-3, 0.4, 1e-6, Phase.HOLD)))
    est = (struct.pack("<BBBIIdBH", MAGIC, WIRE_VERSION, 5, 9, 7, 2.5, 1, 1)
           + struct.pack("<dd4dB4dB", 0.01, 0.2, 5.0, 1e-3, 3.0, 1e-4, 1, 0.3, -1e-3, 0.4, 1e-6, 0)
           + struct.pack("<2f", 1.5, 0.5))
    assert decode(est) == JointEstimate(9, 7, 2.5, (j,), ((1.5,), (0.5,)))
    assert len(encode(JointEstimate(0, 0, 0.0, (j,) * 3))) == 3 + 19 + 82 * 3


GOOD_CMD = encode(JointCommand(1, 0.0, (0.1, 0.2)))
J = JointState(0.0, 0.0, (TendonState(1.0, 0.0, 1.0, 0.0, Phase.HOLD), TendonState(1.0, 0.0, 1.0, 0.0, Phase.HOLD)))
GOOD_EST = encode(JointEstimate(1, 1, 0.0, (J, J), ((1.0, 2.0),) * 4))


@pytest.mark.parametrize("buf, match", [
    (GOOD_CMD[:10], "JointCommand message truncated"),
    (GOOD_CMD[:-1], "JointCommand message truncated"),
    (GOOD_CMD + b"\x00", "JointCommand message too long"),
    (GOOD_CMD[:20] + b"\x00" + GOOD_CMD[21:], "JointCommand has 0 joints: expected 1 to 4"),
    (GOOD_CMD[:20] + b"\x05" + GOOD_CMD[21:], "JointCommand has 5 joints"),
    (GOOD_CMD[:15] + b"\x02" + GOOD_CMD[16:], "JointCommand.engaged byte is 2"),
    (GOOD_EST[:15], "JointEstimate message truncated"),
    (GOOD_EST[:-1], "JointEstimate with 2 joints and 2 profile points needs"),
    (GOOD_EST + b"\x00" * 4, "needs"),
    (GOOD_EST[:22 + 48] + b"\x09" + GOOD_EST[22 + 49:], r"JointEstimate.joints\[0\] phase 9 is not a Phase"),
    (GOOD_CMD[:1] + bytes([WIRE_VERSION - 1]) + GOOD_CMD[2:], f"message version {WIRE_VERSION - 1}, this build speaks"),
])
def test_decode_rejects(buf, match):
    with pytest.raises(CodecError, match=match):
        decode(buf)


@pytest.mark.parametrize("bad", [math.nan, math.inf])
def test_non_finite_floats_are_named_both_ways(bad):
    with pytest.raises(CodecError, match=r"JointCommand.angles\[1\] is"):
        encode(JointCommand(1, 0.0, (0.1, bad)))
    raw = bytearray(GOOD_CMD)
    struct.pack_into("<d", raw, 3 + 18 + 8, bad)
    with pytest.raises(CodecError, match=r"JointCommand.angles\[1\] is"):
        decode(bytes(raw))
    names = ("torque_hat", "angle_hat", "a.T_in", "a.x_in", "a.T_out_hat", "a.elongation_hat")
    for k, name in enumerate(names):
        raw = bytearray(GOOD_EST)
        struct.pack_into("<d", raw, 3 + 19 + 82 + 8 * k, bad)     # joint 1
        with pytest.raises(CodecError, match=rf"JointEstimate.joints\[1\].{name} is"):
            decode(bytes(raw))
    raw = bytearray(GOOD_EST)
    struct.pack_into("<f", raw, len(raw) - 4, bad)
    with pytest.raises(CodecError, match=r"JointEstimate.profiles\[3\].profile\[1\] is"):
        decode(bytes(raw))


def test_encode_rejects_what_decode_would():
    with pytest.raises(CodecError, match="JointCommand has 0 joints"):
        encode(JointCommand(1, 0.0, ()))
    with pytest.raises(CodecError, match="JointEstimate has 5 joints"):
        encode(JointEstimate(1, 1, 0.0, (J,) * 5))
    with pytest.raises(CodecError, match="JointCommand.seq is -1"):
        encode(JointCommand(-1, 0.0, (0.0,)))
    with pytest.raises(CodecError, match="JointEstimate.cmd_seq is 4294967296"):
        encode(JointEstimate(0, 2**32, 0.0, (J,)))
    with pytest.raises(CodecError, match="none or 4 profiles"):
        encode(JointEstimate(0, 0, 0.0, (J, J), ((1.0,),) * 3))
    bad = JointState(0.0, 0.0, (J.tendons[0], TendonState(1.0, 0.0, 1.0, 0.0, "pull")))
    with pytest.raises(CodecError, match=r"joints\[0\] phase is 'pull'"):
        encode(JointEstimate(0, 0, 0.0, (bad,)))
    with pytest.raises(CodecError, match=r"JointEstimate.joints\[0\].b.T_out_hat is nan"):
        encode(JointEstimate(0, 0, 0.0, (JointState(0.0, 0.0, (J.tendons[0], TendonState(1.0, 0.0, math.nan, 0.0,
                                                                                          Phase.HOLD))),)))
