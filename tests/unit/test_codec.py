"""Codec tables: decode and encode for every type, word order, field and special rule."""

from __future__ import annotations

import math

import pytest

from bridge.core.codec import decode, encode, limits_of, unit_of
from bridge.core.entity import Table
from bridge.core.request import Write
from bridge.errors import MissingDataError, ValueRejectedError
from tests.factory import make_mapping, make_point

H = Table.HOLDING


def image_of(*words: int, start: int = 0, table: Table = H) -> dict[tuple[Table, int], int]:
    return {(table, start + i): w for i, w in enumerate(words)}


DECODE_CASES = [
    ("u16", {}, [0x1234], 0x1234),
    ("u16 max", {}, [0xFFFF], 65535),
    ("s16 negative", {"type": "s16"}, [0xFFFF], -1),
    ("s16 min", {"type": "s16"}, [0x8000], -32768),
    ("u32 big", {"type": "u32"}, [0x0001, 0x0002], 65538),
    ("u32 little", {"type": "u32", "word_order": "little"}, [0x0002, 0x0001], 65538),
    ("s32 big", {"type": "s32"}, [0xFFFF, 0xFFFE], -2),
    ("s32 little", {"type": "s32", "word_order": "little"}, [0xFFFE, 0xFFFF], -2),
    ("u32 byte swap", {"type": "u32", "byte_order": "little"}, [0x0100, 0x0200], 65538),
    ("u32 radix 10000", {"type": "u32", "word_radix": 10000}, [12, 345], 120345),
    ("radix 60 little", {"type": "u32", "word_order": "little", "word_radix": 60}, [5, 2], 125),
    ("f32 big", {"type": "f32"}, [0x4048, 0xF5C3], 3.14),
    ("f32 little", {"type": "f32", "word_order": "little"}, [0xF5C3, 0x4048], 3.14),
    ("f32 nan", {"type": "f32"}, [0x7FC0, 0x0000], None),
    ("f32 scaled", {"type": "f32", "scale": 0.001}, [0x4643, 0x5000], 12.5),  # Wh -> kWh
    ("f32 offset", {"type": "f32", "offset": -273.15}, [0x4392, 0x9333], 20.0),  # K -> °C
    ("ascii", {"type": "ascii", "count": 3}, [0x4142, 0x4344, 0x4500], "ABCDE"),
    ("ascii swap", {"type": "ascii", "count": 2, "byte_order": "little"}, [0x4241, 0x4443], "ABCD"),
    ("ascii blank", {"type": "ascii", "count": 2}, [0x0000, 0x0000], ""),
    ("scale 0.1", {"scale": 0.1}, [35], 3.5),
    ("scale 0.01 s16", {"type": "s16", "scale": 0.01}, [0xEC78], -50.0),
    ("scale offset", {"scale": 0.5, "offset": -40}, [100], 10.0),
    ("scale 10 int", {"scale": 10}, [7], 70),
    ("precision", {"scale": 0.1, "precision": 0}, [36], 4),
    ("bit 13 set", {"bit": 13}, [1 << 13], True),
    ("bit 13 clear", {"bit": 13}, [0xDFFF], False),
    ("nibble", {"bit": 0, "width": 4}, [0x86], 6),
    ("nibble high", {"bit": 4, "width": 4}, [0x86], 8),
    ("enum", {"enum": {0: "off", 6: "running"}}, [6], "running"),
    ("enum unknown", {"enum": {0: "off"}}, [9], "code_9"),  # never lost: code_<n>
    ("enum unknown s16", {"enum": {0: "off"}, "type": "s16"}, [0xFFFF], "code_-1"),
    ("enum field", {"bit": 0, "width": 4, "enum": {6: "running"}}, [0x86], "running"),
    ("sentinel", {"sentinels": {0xFFFF: "none"}}, [0xFFFF], None),
    ("s16 sentinel", {"type": "s16", "sentinels": {32766: "open"}}, [32766], None),
    ("on_when in", {"on_when": {"min": 100}}, [120], True),
    ("on_when out", {"on_when": {"min": 100}}, [99], False),
    ("on_when max", {"on_when": {"max": 90}}, [91], False),
]


@pytest.mark.parametrize(
    ("fields", "words", "expected"), [c[1:] for c in DECODE_CASES], ids=[c[0] for c in DECODE_CASES]
)
def test_decode(fields: dict, words: list[int], expected: object) -> None:
    point = make_point(**fields)
    value = decode(point, image_of(*words))
    if isinstance(expected, float):
        assert value == pytest.approx(expected, abs=1e-6)
    else:
        assert value == expected
    assert type(value) is type(expected)


def test_decode_coil() -> None:
    point = make_point(table="coil")
    assert decode(point, image_of(1, table=Table.COIL)) is True
    assert decode(point, image_of(0, table=Table.COIL)) is False


def test_whole_register_bool() -> None:
    point = make_point(type="bool", access="rw")
    assert decode(point, image_of(1)) is True
    assert decode(point, image_of(0)) is False
    assert encode(point, "ON", {}) == (Write(6, H, 0, (1,)),)
    assert encode(point, False, {}) == (Write(6, H, 0, (0,)),)


def test_decode_missing_register() -> None:
    point = make_point(type="u32", address=10)
    with pytest.raises(MissingDataError, match="holding 11"):
        decode(point, image_of(1, start=10))


def test_decode_does_not_mutate_image() -> None:
    point = make_point(scale=0.1)
    image = image_of(35)
    before = dict(image)
    decode(point, image)
    assert image == before


ENCODE_CASES = [
    ("u16", {}, 1234, [Write(6, H, 0, (1234,))]),
    ("scale 4.5 -> 45", {"scale": 0.1}, 4.5, [Write(6, H, 0, (45,))]),
    ("scale 0.3 -> 3", {"scale": 0.1}, 0.3, [Write(6, H, 0, (3,))]),
    ("half away from zero", {"scale": 0.1}, 4.55, [Write(6, H, 0, (46,))]),
    ("string number", {"scale": 0.1}, "4.5", [Write(6, H, 0, (45,))]),
    ("s16 negative", {"type": "s16", "scale": 0.01}, -50, [Write(6, H, 0, (0xEC78,))]),
    ("offset", {"scale": 0.5, "offset": -40}, 10, [Write(6, H, 0, (100,))]),
    ("u32 big", {"type": "u32"}, 65538, [Write(16, H, 0, (1, 2))]),
    ("u32 little", {"type": "u32", "word_order": "little"}, 65538, [Write(16, H, 0, (2, 1))]),
    ("s32", {"type": "s32"}, -2, [Write(16, H, 0, (0xFFFF, 0xFFFE))]),
    ("radix", {"type": "u32", "word_radix": 10000}, 120345, [Write(16, H, 0, (12, 345))]),
    ("f32", {"type": "f32"}, 1.5, [Write(16, H, 0, (0x3FC0, 0))]),
    ("f32 scaled", {"type": "f32", "scale": 0.001}, 12.5, [Write(16, H, 0, (0x4643, 0x5000))]),
    ("ascii", {"type": "ascii", "count": 2}, "AB", [Write(16, H, 0, (0x4142, 0))]),
    ("enum label", {"enum": {0: "off", 1: "on"}}, "on", [Write(6, H, 0, (1,))]),
    ("enum any case", {"enum": {3: "Fix speed"}}, "fix SPEED", [Write(6, H, 0, (3,))]),
    ("enum raw", {"enum": {0: "off", 1: "on"}}, 1, [Write(6, H, 0, (1,))]),
    ("write address", {"write_address": 9}, 5, [Write(6, H, 9, (5,))]),
    ("fc16 single", {"write_function": 16}, 5, [Write(16, H, 0, (5,))]),
]


@pytest.mark.parametrize(
    ("fields", "value", "writes"), [c[1:] for c in ENCODE_CASES], ids=[c[0] for c in ENCODE_CASES]
)
def test_encode(fields: dict, value: object, writes: list[Write]) -> None:
    point = make_point(access="rw", **fields)
    assert encode(point, value, {}) == tuple(writes)


def test_encode_bit_keeps_other_bits() -> None:
    point = make_point(access="rw", bit=3)
    assert encode(point, "ON", image_of(0b1000_0001)) == (Write(6, H, 0, (0b1000_1001,)),)
    assert encode(point, False, image_of(0xFFFF)) == (Write(6, H, 0, (0xFFF7,)),)


def test_encode_nibble_keeps_other_bits() -> None:
    point = make_point(access="rw", bit=4, width=4)
    assert encode(point, 5, image_of(0xF00F)) == (Write(6, H, 0, (0xF05F,)),)


def test_encode_bit_needs_current_word() -> None:
    point = make_point(access="rw", bit=3)
    with pytest.raises(MissingDataError):
        encode(point, True, {})


def test_pulse_sets_then_clears_the_bit() -> None:
    point = make_point(access="w", bit=2, pulse=True, press=True)
    assert encode(point, "PRESS", image_of(0x0001)) == (
        Write(6, H, 0, (0x0005,)),
        Write(6, H, 0, (0x0001,)),
    )


def test_pulse_makes_a_rising_edge_when_the_bit_was_left_set() -> None:
    point = make_point(access="w", bit=2, pulse=True, press=True)
    assert encode(point, "PRESS", image_of(0x0005)) == (
        Write(6, H, 0, (0x0001,)),
        Write(6, H, 0, (0x0005,)),
        Write(6, H, 0, (0x0001,)),
    )


@pytest.mark.parametrize(
    ("on_value", "value", "word"),
    [(0xFF00, True, 0xFF00), (0x00FF, "ON", 0x00FF), (0x00FF, "OFF", 0)],
)
def test_coil_uses_the_device_on_value(on_value: int, value: object, word: int) -> None:
    mapping = make_mapping(
        {"run": {"name": "Run", "address": 3, "table": "coil", "access": "rw"}},
        protocol={"coil_on_value": on_value},
    )
    assert encode(mapping.points()["run"], value, {}) == (Write(5, Table.COIL, 3, (word,)),)


def test_coil_button_and_fc15() -> None:
    mapping = make_mapping(
        {
            "auto": {"name": "Auto", "address": 3, "table": "coil", "access": "w", "press": True},
            "bit": {
                "name": "Bit",
                "address": 4,
                "table": "coil",
                "access": "rw",
                "write_function": 15,
            },
        },
        protocol={"coil_on_value": 0x00FF},
    )
    points = mapping.points()
    assert encode(points["auto"], "PRESS", {}) == (Write(5, Table.COIL, 3, (0x00FF,)),)
    assert encode(points["bit"], True, {}) == (Write(15, Table.COIL, 4, (1,)),)


def test_button_writes_its_press_value() -> None:
    point = make_point(access="w", press=0x55AA)
    assert encode(point, "PRESS", {}) == (Write(6, H, 0, (0x55AA,)),)


REJECTED = [
    ("read-only", {"access": "r"}, 1),
    ("above u16", {}, 65536),
    ("negative u16", {}, -1),
    ("above s16", {"type": "s16"}, 32768),
    ("above static max", {"max": 100}, 101),
    ("below static min", {"min": 10}, 9),
    ("scaled beyond raw", {"scale": 0.1}, 6553.6),
    ("not a number", {}, "abc"),
    ("bool for number", {}, True),
    ("nan", {}, math.nan),
    ("inf", {}, math.inf),
    ("list", {}, [1]),
    ("unknown label", {"enum": {0: "off"}}, "maybe"),
    ("unknown raw", {"enum": {0: "off"}}, 5),
    ("sentinel", {"sentinels": {0xFFFF: "none"}}, 65535),
    ("bad bool", {"bit": 0}, "perhaps"),
    ("field too wide", {"bit": 0, "width": 2}, 4),
    ("text too long", {"type": "ascii", "count": 1}, "ABC"),
    ("not ascii", {"type": "ascii", "count": 2}, "é"),
    ("text not str", {"type": "ascii", "count": 2}, 12),
    ("radix overflow", {"type": "u32", "word_radix": 10000}, 655360000),
]


@pytest.mark.parametrize(
    ("fields", "value"), [c[1:] for c in REJECTED], ids=[c[0] for c in REJECTED]
)
def test_encode_rejects(fields: dict, value: object) -> None:
    fields.setdefault("access", "rw")
    point = make_point(**fields)
    with pytest.raises(ValueRejectedError):
        encode(point, value, image_of(0))


def _signed_setting() -> dict:
    mapping = make_mapping(
        {
            "set_value": {
                "name": "Set value",
                "address": 51,
                "access": "rw",
                "scale": 0.1,
                "sign_from": "set_value_negative",
                "unit_from": "unit",
            },
            "set_value_negative": {"name": "Sign", "address": 75, "bit": 13, "access": "rw"},
            "unit": {"name": "Unit", "address": 87, "enum": {0: "bar", 1: "psi"}},
        }
    )
    return mapping.points()


def test_sign_from_other_register_decodes() -> None:
    points = _signed_setting()
    assert decode(points["set_value"], {(H, 51): 45, (H, 75): 1 << 13}) == -4.5
    assert decode(points["set_value"], {(H, 51): 45, (H, 75): 0}) == 4.5


def test_sign_written_first_and_only_when_it_changes() -> None:
    points = _signed_setting()
    image = {(H, 51): 10, (H, 75): 0x0001}
    assert encode(points["set_value"], -4.5, image) == (
        Write(6, H, 75, (0x2001,)),
        Write(6, H, 51, (45,)),
    )
    assert encode(points["set_value"], 4.5, image) == (Write(6, H, 51, (45,)),)


def test_unit_from_other_register() -> None:
    points = _signed_setting()
    assert unit_of(points["set_value"], {(H, 87): 1}) == "psi"
    assert unit_of(points["set_value"], {}) is None
    assert unit_of(points["unit"], {}) is None


def test_dynamic_limits_from_other_registers() -> None:
    mapping = make_mapping(
        {
            "f_min": {"name": "Min", "address": 1, "access": "rw"},
            "f_max": {"name": "Max", "address": 2, "access": "rw"},
            "f_run": {
                "name": "Run",
                "address": 3,
                "access": "rw",
                "min": 0,
                "max": 500,
                "min_from": "f_min",
                "max_from": "f_max",
            },
        }
    )
    point = mapping.points()["f_run"]
    image = {(H, 1): 30, (H, 2): 50, (H, 3): 40}
    assert limits_of(point, image) == (30, 50)
    assert encode(point, 50, image) == (Write(6, H, 3, (50,)),)
    with pytest.raises(ValueRejectedError, match=r"outside 30\.\.50"):
        encode(point, 51, image)
    with pytest.raises(ValueRejectedError):
        encode(point, 29, image)
    with pytest.raises(MissingDataError):
        limits_of(point, {})
