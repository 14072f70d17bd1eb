"""HID report maps byte for byte (master/hid_reports.py): every field type and endianness decoded and encoded,
buttons by mask and an active-low presence bit, short and wrong-id reports counted rather than raised, and a force
saturated in newtons and in the raw type's range."""
import math
import struct

import pytest

from master.hid_reports import Field, OutputMap, Section, parse_input, parse_output


def h(s):
    return bytes.fromhex(s)


# ---- field types and endianness -------------------------------------------------------------------

CASES = [  # type, endian, raw value, bytes
    ("u8", "little", 200, "c8"), ("i8", "little", -2, "fe"),
    ("u16", "little", 0x1234, "34 12"), ("u16", "big", 0x1234, "12 34"),
    ("i16", "little", -2, "fe ff"), ("i16", "big", -300, "fe d4"),
    ("u32", "little", 0x01020304, "04 03 02 01"), ("u32", "big", 0x01020304, "01 02 03 04"),
    ("i32", "little", -2, "fe ff ff ff"), ("i32", "big", -70000, "ff fe ee 90"),
    ("f32", "little", 1.5, "00 00 c0 3f"), ("f32", "big", -2.25, "c0 10 00 00"),
]


@pytest.mark.parametrize("typ, endian, raw, payload", CASES)
def test_decode_each_type_and_endianness(typ, endian, raw, payload):
    m = parse_input(Section({"report_id": 7, "axes": {"x": {"byte_offset": 2, "type": typ, "endian": endian,
                                                             "scale": 0.5, "offset": 1.0}}}, "t.yaml", "input"))
    s = m.decode(h("07 aa") + h(payload))
    assert s.axes["x"] == raw * 0.5 + 1.0          # value = raw * scale + offset
    assert m.accepted == 1 and sum(m.rejected.values()) == 0


@pytest.mark.parametrize("typ, endian, raw, payload", CASES)
def test_encode_each_type_and_endianness(typ, endian, raw, payload):
    o = OutputMap("output", 9, Field(2, typ, endian, scale=2.0, offset=0.0), limit=1e9, length=8)
    data = o.encode(raw / 2.0)                      # raw = N * scale
    assert data[:2] == h("09 00") and data[2:2 + len(h(payload))] == h(payload)
    assert len(data) == 8 and set(data[2 + len(h(payload)):]) <= {0}


def input_map(**extra):
    base = {"report_id": 1, "axes": {"x": {"byte_offset": 1, "type": "i16", "scale": 1e-5}},
            "buttons": {"byte_offset": 3, "masks": [0x01, 0x04, "0x80"]},
            "presence": {"byte_offset": 4, "mask": 0x02, "active_low": True}}
    base.update(extra)
    return parse_input(Section(base, "t.yaml", "input"))


def test_buttons_by_mask_and_active_low_presence():
    m = input_map()
    s = m.decode(h("01 10 27 85 00"))               # x = 10000 counts; raw buttons 0x85; presence bit clear
    assert s.axes["x"] == pytest.approx(0.1)
    assert s.buttons == 0b111 and s.present is True
    s = m.decode(h("01 10 27 04 02"))
    assert s.buttons == 0b010 and s.present is False


@pytest.mark.parametrize("data, reason", [
    (b"", "short"), (h("01 10 27 85"), "short"), (h("02 10 27 85 00"), "wrong_id"),
])
def test_short_and_wrong_id_reports_are_counted_not_raised(data, reason):
    m = input_map()
    assert m.decode(data) is None
    assert m.rejected[reason] == 1 and m.accepted == 0


def test_non_finite_float_is_rejected_and_no_report_id_means_data_from_byte_0():
    m = parse_input(Section({"axes": {"x": {"byte_offset": 0, "type": "f32"}}}, "t.yaml", "input"))
    assert m.decode(struct.pack("<f", math.nan)) is None and m.rejected["non_finite"] == 1
    assert m.decode(struct.pack("<f", 0.25)).axes["x"] == 0.25


def vendor_out(**kw):
    d = {"report_id": 3, "length": 6, "fixed": [{"byte_offset": 1, "value": 0x46}],
         "field": {"byte_offset": 2, "type": "i16", "scale": 1000.0}, "raw_min": -2500, "raw_max": 3000}
    d.update(kw)
    return parse_output(Section(d, "t.yaml", "force.report"), limit=3.0)


@pytest.mark.parametrize("force, raw", [
    (1.234, 1234), (2.9, 2900), (10.0, 3000),     # N clamp 3 N
    (-2.4, -2400), (-2.9, -2500),                  # raw clamp -2500
    (math.nan, 0), (math.inf, 0), (-math.inf, 0),
])
def test_output_saturates_in_newtons_and_raw(force, raw):
    data = vendor_out().encode(force)
    assert data == h("03 46") + struct.pack("<h", raw) + h("00 00")


def test_output_clamps_to_the_type_range():
    o = parse_output(Section({"report_id": 1, "field": {"byte_offset": 1, "type": "u8", "scale": 100.0,
                                                        "offset": 128}}, "t.yaml", "r"), limit=5.0)
    assert o.encode(5.0) == h("01 ff") and o.encode(-5.0) == h("01 00") and o.encode(0.0) == h("01 80")
