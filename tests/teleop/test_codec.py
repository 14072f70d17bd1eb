"""Wire codec (version 3): round trips over random instruments of one to MAX_AXES (16) axes (single tendons and
pairs), the pinned layout, every rejection named, older versions refused."""
from __future__ import annotations

import math
import random
import struct

import numpy as np
import pytest

from estimator.phase import Phase
from teleop.errors import CodecError
from teleop.wire import codec
from teleop.wire.codec import MAGIC, MAX_AXES, WIRE_VERSION, decode, encode, next_seq
from teleop.wire.messages import AxisState, Command, Estimate, Heartbeat, Side, SideState, TendonState, tendon_estimate

N_RANDOM = 300


def _f(rng: random.Random) -> float:
    """A finite float64 over many magnitudes and both signs (and exact zeros)."""
    if rng.random() < 0.05:
        return 0.0
    return rng.choice((-1.0, 1.0)) * 10.0 ** rng.uniform(-12, 12)


def _u32(rng: random.Random) -> int:
    return rng.choice((0, 1, 2**32 - 1, rng.randrange(2**32)))


def _tendon(rng: random.Random) -> TendonState:
    return TendonState(_f(rng), _f(rng), _f(rng), _f(rng), rng.choice(list(Phase)))


def _axis(rng: random.Random, k: int) -> AxisState:
    return AxisState(_f(rng), _f(rng), tuple(_tendon(rng) for _ in range(k)))


def test_command_round_trip_random():
    rng = random.Random(1)
    for _ in range(N_RANDOM):
        n = rng.randint(1, MAX_AXES)
        msg = Command(_u32(rng), _f(rng), tuple(_f(rng) for _ in range(n)), rng.random() < 0.5, _u32(rng))
        out = decode(encode(msg))
        assert out == msg
        assert type(out.engaged) is bool and type(out.targets) is tuple


def test_estimate_round_trip_random_axes_of_one_or_two_tendons_profiles_in_float32():
    rng = random.Random(2)
    for _ in range(N_RANDOM):
        axes = tuple(_axis(rng, rng.choice((1, 2))) for _ in range(rng.randint(1, MAX_AXES)))
        m = sum(len(a.tendons) for a in axes)
        p = rng.choice((0, 1, 50, rng.randrange(300)))
        profiles = tuple(tuple(rng.uniform(-1e3, 1e3) for _ in range(p)) for _ in range(m)) if p else ()
        msg = Estimate(_u32(rng), _u32(rng), _f(rng), axes, profiles)
        out = decode(encode(msg))
        assert out.profiles == tuple(tuple(float(x) for x in np.asarray(q, dtype=np.float32)) for q in profiles)
        assert out == Estimate(msg.seq, msg.cmd_seq, msg.t_slave, axes, out.profiles)
        assert all(isinstance(t.phase, Phase) for t in out.tendons) and len(out.tendons) == m


def test_tendon_estimate_is_one_axis_of_one_tendon_and_accepts_numpy_profile():
    prof = np.linspace(10.0, 2.0, 50)
    msg = tendon_estimate(1, 2, 0.5, 10.0, 0.01, 2.0, 1e-4, 0.0099, Phase.PULL, tuple(prof))
    assert len(msg.axes) == 1 and msg.axes[0].effort_hat == 2.0 and msg.axes[0].position_hat == 0.0099
    assert msg.tendons == (TendonState(10.0, 0.01, 2.0, 1e-4, Phase.PULL),)
    out = decode(encode(msg))
    assert out.profiles[0] == pytest.approx(tuple(prof), rel=1e-6)
    assert tendon_estimate(1, 2, 0.5, 10.0, 0.01, 2.0, 1e-4, 0.0099, Phase.PULL).profiles == ()


def test_heartbeat_round_trip_random():
    rng = random.Random(3)
    for _ in range(N_RANDOM):
        msg = Heartbeat(rng.choice(list(Side)), _u32(rng), _f(rng), rng.choice(list(SideState)))
        out = decode(encode(msg))
        assert out == msg and isinstance(out.side, Side) and isinstance(out.state, SideState)


def test_layout_is_pinned():
    """The documented layout, built by hand, decodes; a change of layout must change WIRE_VERSION."""
    assert (MAGIC, WIRE_VERSION) == (0xA7, 3)
    cmd = struct.pack("<BBBIdBIBd", 0xA7, 3, 1, 7, 1.5, 1, 3, 1, -0.002)
    assert encode(Command(7, 1.5, (-0.002,), True, 3)) == cmd and len(cmd) == 3 + 18 + 8
    cmd2 = struct.pack("<BBBIdBIB2d", 0xA7, 3, 1, 7, 1.5, 1, 3, 2, 0.25, -0.5)
    assert decode(cmd2) == Command(7, 1.5, (0.25, -0.5), True, 3)
    # one single-tendon axis, then one pair, one profile point per tendon
    est = (struct.pack("<BBBIIdBH", 0xA7, 3, 2, 5, 4, 1.0, 2, 1)
           + struct.pack("<Bdd4dB", 1, 4.0, 6.0, 2.0, 3.0, 4.0, 5.0, 2)
           + struct.pack("<Bdd4dB4dB", 2, 0.01, 0.2, 5.0, 1e-3, 3.0, 1e-4, 1, 0.3, -1e-3, 0.4, 1e-6, 0)
           + struct.pack("<3f", 0.5, 1.5, 0.25))
    single = AxisState(4.0, 6.0, (TendonState(2.0, 3.0, 4.0, 5.0, Phase.RELEASE),))
    pair = AxisState(0.01, 0.2, (TendonState(5.0, 1e-3, 3.0, 1e-4, Phase.PULL),
                                 TendonState(0.3, -1e-3, 0.4, 1e-6, Phase.HOLD)))
    assert decode(est) == Estimate(5, 4, 1.0, (single, pair), ((0.5,), (1.5,), (0.25,)))
    assert encode(Estimate(5, 4, 1.0, (single, pair), ((0.5,), (1.5,), (0.25,)))) == est
    assert len(encode(tendon_estimate(0, 0, 0, 0, 0, 0, 0, 0, Phase.HOLD, (1.0,) * 50))) == 3 + 19 + 17 + 33 + 4 * 50
    assert len(encode(Estimate(0, 0, 0.0, (pair,) * 3))) == 3 + 19 + 3 * (17 + 66)
    hb = struct.pack("<BBBBIdB", 0xA7, 3, 3, 2, 9, 0.25, 3)
    assert decode(hb) == Heartbeat(Side.SLAVE, 9, 0.25, SideState.ENGAGED)


def test_next_seq_wraps_at_uint32():
    assert next_seq(0) == 1
    assert next_seq(2**32 - 1) == 0


# ---- rejections on decode ------------------------------------------------------------------------

GOOD_CMD = encode(Command(1, 2.0, (3.0, 0.1)))
T = TendonState(1.0, 0.0, 1.0, 0.0, Phase.HOLD)
PAIR = AxisState(0.0, 0.0, (T, T))
GOOD_EST = encode(Estimate(1, 1, 0.0, (PAIR, PAIR), ((1.0, 2.0),) * 4))
GOOD_HB = encode(Heartbeat(Side.MASTER, 1, 0.0, SideState.READY))
_E0 = 3 + 19                                     # the first axis
_T0 = _E0 + 17                                   # its first tendon


@pytest.mark.parametrize("buf, match", [
    (b"", "truncated: 0 bytes"),
    (b"\xa7\x01", "truncated: 2 bytes"),
    (GOOD_CMD[:10], "Command message truncated"),
    (GOOD_CMD[:-1], "Command message truncated"),
    (GOOD_CMD + b"\x00", "Command message too long"),
    (GOOD_CMD[:20] + b"\x00" + GOOD_CMD[21:], f"Command has 0 axes: expected 1 to {MAX_AXES}"),
    (GOOD_CMD[:20] + bytes([MAX_AXES + 1]) + GOOD_CMD[21:], f"Command has {MAX_AXES + 1} axes"),
    (GOOD_CMD[:15] + b"\x02" + GOOD_CMD[16:], "Command.engaged byte is 2"),
    (GOOD_HB[:10], "Heartbeat message truncated"),
    (GOOD_EST[:10], "Estimate message truncated"),
    (GOOD_EST[:_T0 + 20], r"Estimate message truncated: .* inside axis 0 of 2"),
    (GOOD_EST[:-1], "Estimate with 2 axes, 4 tendons and 2 profile points needs"),
    (GOOD_EST + b"\x00" * 4, "needs"),
    (GOOD_EST[:_E0] + b"\x03" + GOOD_EST[_E0 + 1:], r"Estimate.axes\[0\] has 3 tendons: expected 1"),
    (GOOD_EST[:_T0 + 32] + b"\x09" + GOOD_EST[_T0 + 33:], r"Estimate.axes\[0\].tendons\[0\].phase 9 is not a Phase"),
    (b"\x00" + GOOD_CMD[1:], "magic byte 0x00"),
    (GOOD_CMD[:2] + b"\x09" + GOOD_CMD[3:], "unknown message type 9"),
])
def test_decode_rejects(buf, match):
    with pytest.raises(CodecError, match=match):
        decode(buf)


@pytest.mark.parametrize("version", [1, 2, 4])
def test_other_wire_versions_are_refused_naming_both(version):
    """Version 2 (Command/Estimate of one tendon beside JointCommand/JointEstimate) is refused with the
    version seen and the one expected; so is a newer one."""
    v2_command = struct.pack("<BBBIddBI", 0xA7, version, 1, 7, 1.5, -0.002, 1, 3)      # a v2 Command
    with pytest.raises(CodecError, match=rf"message version {version} refused: this build speaks wire version 3"):
        decode(v2_command)
    with pytest.raises(CodecError, match="upgrade the sender" if version < 3 else "upgrade this side"):
        decode(GOOD_EST[:1] + bytes([version]) + GOOD_EST[2:])


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_floats_are_named_both_ways(bad):
    for name in ("t_master",):
        raw = bytearray(GOOD_CMD)
        struct.pack_into("<d", raw, 3 + 4, bad)
        with pytest.raises(CodecError, match=f"Command.{name} is"):
            decode(bytes(raw))
    with pytest.raises(CodecError, match=r"Command.targets\[1\] is"):
        encode(Command(1, 0.0, (0.1, bad)))
    raw = bytearray(GOOD_CMD)
    struct.pack_into("<d", raw, 3 + 18 + 8, bad)
    with pytest.raises(CodecError, match=r"Command.targets\[1\] is"):
        decode(bytes(raw))
    raw = bytearray(GOOD_EST)
    struct.pack_into("<d", raw, 3 + 8, bad)
    with pytest.raises(CodecError, match="Estimate.t_slave is"):
        decode(bytes(raw))
    second = _E0 + 17 + 66                       # axis 1
    for k, name in enumerate(("effort_hat", "position_hat")):
        raw = bytearray(GOOD_EST)
        struct.pack_into("<d", raw, second + 1 + 8 * k, bad)
        with pytest.raises(CodecError, match=rf"Estimate.axes\[1\].{name} is"):
            decode(bytes(raw))
    for k, name in enumerate(("T_in", "x_in", "T_out_hat", "elongation_hat")):
        raw = bytearray(GOOD_EST)
        struct.pack_into("<d", raw, second + 17 + 33 + 8 * k, bad)       # axis 1, tendon 1
        with pytest.raises(CodecError, match=rf"Estimate.axes\[1\].tendons\[1\].{name} is"):
            decode(bytes(raw))
    raw = bytearray(GOOD_EST)
    struct.pack_into("<f", raw, len(raw) - 4, bad)
    with pytest.raises(CodecError, match=r"Estimate.profiles\[3\]\[1\] is"):
        decode(bytes(raw))
    with pytest.raises(CodecError, match="Heartbeat.t_sender is"):
        decode(struct.pack("<BBBBIdB", 0xA7, WIRE_VERSION, 3, 1, 0, bad, 0))


def test_decode_rejects_bad_enums():
    with pytest.raises(CodecError, match="Heartbeat.side 0 is not a Side"):
        decode(struct.pack("<BBBBIdB", 0xA7, WIRE_VERSION, 3, 0, 0, 0.0, 0))
    with pytest.raises(CodecError, match="Heartbeat.state 9 is not a SideState"):
        decode(struct.pack("<BBBBIdB", 0xA7, WIRE_VERSION, 3, 1, 0, 0.0, 9))


def test_decode_accepts_bytearray_and_memoryview():
    assert decode(bytearray(GOOD_CMD)) == decode(memoryview(GOOD_CMD)) == Command(1, 2.0, (3.0, 0.1))


# ---- rejections on encode ------------------------------------------------------------------------

def test_encode_rejects_what_decode_would():
    with pytest.raises(CodecError, match=r"Command.targets\[0\] is nan"):
        encode(Command(1, 0.0, (math.nan,)))
    with pytest.raises(CodecError, match=r"Estimate.axes\[0\].tendons\[0\].T_out_hat is inf"):
        encode(Estimate(1, 1, 0.0, (AxisState(0.0, 0.0, (TendonState(1.0, 0.0, math.inf, 0.0, Phase.HOLD),)),)))
    with pytest.raises(CodecError, match=r"Estimate.axes\[0\].effort_hat is nan"):
        encode(Estimate(1, 1, 0.0, (AxisState(math.nan, 0.0, (T,)),)))
    with pytest.raises(CodecError, match=r"Estimate.profiles\[0\]\[2\] is nan"):
        encode(tendon_estimate(1, 1, 0.0, 1.0, 0.0, 1.0, 0.0, 0.0, Phase.HOLD, (1.0, 2.0, math.nan)))
    with pytest.raises(CodecError, match="float32 range"):
        encode(tendon_estimate(1, 1, 0.0, 1.0, 0.0, 1.0, 0.0, 0.0, Phase.HOLD, (1e39,)))
    with pytest.raises(CodecError, match="Heartbeat.t_sender is"):
        encode(Heartbeat(Side.SLAVE, 1, math.nan, SideState.SAFE))


def test_encode_rejects_out_of_range_integers_counts_and_sizes():
    with pytest.raises(CodecError, match=r"Command.seq is 4294967296: expected an integer in \[0, 2\*\*32\)"):
        encode(Command(2**32, 0.0, (0.0,)))
    with pytest.raises(CodecError, match="Command.marker is -1"):
        encode(Command(0, 0.0, (0.0,), True, -1))
    with pytest.raises(CodecError, match="Command has 0 axes"):
        encode(Command(1, 0.0, ()))
    with pytest.raises(CodecError, match=f"Estimate has {MAX_AXES + 1} axes"):
        encode(Estimate(1, 1, 0.0, (PAIR,) * (MAX_AXES + 1)))
    with pytest.raises(CodecError, match=r"Estimate.axes\[1\] has 3 tendons"):
        encode(Estimate(1, 1, 0.0, (PAIR, AxisState(0.0, 0.0, (T, T, T)))))
    with pytest.raises(CodecError, match="Estimate.cmd_seq is -1"):
        encode(tendon_estimate(0, -1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, Phase.HOLD))
    with pytest.raises(CodecError, match="none or 4 profiles"):
        encode(Estimate(0, 0, 0.0, (PAIR, PAIR), ((1.0,),) * 3))
    with pytest.raises(CodecError, match="65536 points: at most 65535"):
        encode(tendon_estimate(0, 0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, Phase.HOLD, (0.0,) * 65536))
    with pytest.raises(CodecError, match=r"Estimate.axes\[0\].tendons\[1\].phase is 'pull': expected a Phase"):
        encode(Estimate(0, 0, 0.0, (AxisState(0.0, 0.0, (T, TendonState(1.0, 0.0, 1.0, 0.0, "pull"))),)))
    with pytest.raises(CodecError, match="Heartbeat.side is 5: expected a Side"):
        encode(Heartbeat(5, 0, 0.0, SideState.READY))
    with pytest.raises(CodecError, match="Heartbeat.state is None: expected a SideState"):
        encode(Heartbeat(Side.MASTER, 0, 0.0, None))
    with pytest.raises(CodecError, match="cannot encode a dict"):
        encode({"seq": 1})


def test_overflowing_sum_of_finite_floats_is_not_rejected():
    msg = tendon_estimate(0, 0, 1e308, 1e308, 1e308, 0.0, 0.0, 0.0, Phase.PULL)
    assert decode(encode(msg)) == msg


def test_max_profile_points_matches_wire_count():
    assert codec.MAX_PROFILE_POINTS == 2**16 - 1


def test_sixteen_pair_axes_round_trip_at_the_documented_sizes():
    """The largest instrument (MAX_AXES pairs, 2 MAX_AXES tendons): Command 21 + 8 n bytes, Estimate 22 +
    83 n bytes without profiles (docs/reference/wire.md), and back unchanged."""
    n = MAX_AXES
    cmd = Command(7, 1.5, tuple(0.01 * k for k in range(n)), True, 3)
    est = Estimate(7, 6, 1.5, tuple(AxisState(0.1 * k, -0.1 * k, (TendonState(1.0 + k, 1e-3, 0.5, 1e-4, Phase.PULL),
                                                                  TendonState(2.0, -1e-3, 1.5, 2e-4, Phase.HOLD)))
                                    for k in range(n)))
    assert n == 16 and len(encode(cmd)) == 21 + 8 * n and len(encode(est)) == 22 + 83 * n
    assert decode(encode(cmd)) == cmd and decode(encode(est)) == est


def test_a_prepared_body_encodes_the_same_bytes_and_a_bad_one_is_refused_as_before():
    rng = random.Random(5)
    for _ in range(50):
        axes = tuple(_axis(rng, rng.choice((1, 2))) for _ in range(rng.randint(1, MAX_AXES)))
        m = sum(len(a.tendons) for a in axes)
        profiles = (tuple(tuple(rng.uniform(-1e3, 1e3) for _ in range(20)) for _ in range(m))
                    if rng.random() < 0.5 else ())
        msg = Estimate(_u32(rng), _u32(rng), _f(rng), axes, profiles)
        plain = encode(msg)
        assert codec.prepare_estimate(axes, profiles)
        assert encode(msg) == plain                              # the prepared body
        # equal, not the same
        same = Estimate(msg.seq, msg.cmd_seq, msg.t_slave, tuple(list(axes)), tuple(list(profiles)))
        assert encode(same) == plain and decode(plain) == decode(encode(msg))
    assert len(codec._BODIES) <= codec._BODIES_MAX                # bounded, whatever was prepared
    bad = (AxisState(1.0, math.nan, (TendonState(1.0, 0.0, 1.0, 0.0, Phase.PULL),)),)
    assert not codec.prepare_estimate(bad)
    with pytest.raises(CodecError, match=r"Estimate.axes\[0\].position_hat is nan"):
        encode(Estimate(1, 1, 0.0, bad))
    good = (AxisState(1.0, 0.0, (TendonState(1.0, 0.0, 1.0, 0.0, Phase.PULL),)),)
    assert codec.prepare_estimate(good)
    with pytest.raises(CodecError, match="t_slave is inf"):          # the header is still checked
        encode(Estimate(1, 1, math.inf, good))
    with pytest.raises(CodecError, match="seq is -1"):
        encode(Estimate(-1, 1, 0.0, good))
