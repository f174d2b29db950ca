"""64-bit integers and floats (four registers) and half floats (one): golden words per type
and word order, round trips, NaN as unknown, exact 64-bit writes, and reads that never
tear a 64-bit value."""

from __future__ import annotations

import math
import struct
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pydantic import ValidationError

from bridge.core.codec import decode, encode, raw_bounds
from bridge.core.entity import Table
from bridge.core.gateway import ProxyRequest
from bridge.core.gateway_writes import GatewayRefusalError, items_of
from bridge.core.mapping import Point
from bridge.core.planner import ReadLimits, plan_reads
from bridge.core.request import Write
from bridge.errors import ValueRejectedError
from tests.factory import make_mapping, make_point

H = Table.HOLDING
# Home Assistant's own test words for uint64 (tests/components/modbus/test_sensor.py)
HA_WORDS = [0x89AB, 0xCDEF, 0x0123, 0x4567]


def image_of(*words: int, start: int = 0) -> dict[tuple[Table, int], int]:
    return {(H, start + i): w for i, w in enumerate(words)}


DECODE_CASES = [
    ("u64 big", {"type": "u64"}, HA_WORDS, 0x89ABCDEF01234567),
    # Home Assistant's swap: word reverses the four words
    ("u64 word swap", {"type": "u64", "word_order": "little"}, HA_WORDS, 0x45670123CDEF89AB),
    ("u64 byte swap", {"type": "u64", "byte_order": "little"}, HA_WORDS, 0xAB89EFCD23016745),
    (
        "u64 word_byte",
        {"type": "u64", "word_order": "little", "byte_order": "little"},
        HA_WORDS,
        0x67452301EFCDAB89,
    ),
    ("s64 big", {"type": "s64"}, HA_WORDS, 0x89ABCDEF01234567 - (1 << 64)),
    ("s64 -1", {"type": "s64"}, [0xFFFF] * 4, -1),
    (
        "s64 little -2",
        {"type": "s64", "word_order": "little"},
        [0xFFFE, 0xFFFF, 0xFFFF, 0xFFFF],
        -2,
    ),
    ("u64 scaled", {"type": "u64", "scale": 0.001}, [0, 0, 0, 12345], 12.345),
    ("f64 big", {"type": "f64"}, [0x4009, 0x21FB, 0x5444, 0x2D18], math.pi),
    (
        "f64 little",
        {"type": "f64", "word_order": "little"},
        [0x2D18, 0x5444, 0x21FB, 0x4009],
        math.pi,
    ),
    ("f64 1.1", {"type": "f64"}, [0x3FF1, 0x9999, 0x9999, 0x999A], 1.1),
    ("f64 scaled", {"type": "f64", "scale": 0.001}, [0x40C8, 0x6A00, 0, 0], 12.5),
    ("f16 1.5", {"type": "f16"}, [0x3E00], 1.5),
    ("f16 shortest", {"type": "f16"}, [0x4248], 3.14),  # 3.140625: 3.14 reads back the same
    ("f16 byte swap", {"type": "f16", "byte_order": "little"}, [0x003E], 1.5),
    ("f16 negative", {"type": "f16"}, [0xC500], -5.0),
    ("f16 max", {"type": "f16"}, [0x7BFF], 65500.0),
]


@pytest.mark.parametrize(
    ("fields", "words", "expected"), [c[1:] for c in DECODE_CASES], ids=[c[0] for c in DECODE_CASES]
)
def test_decode(fields: dict[str, Any], words: list[int], expected: float) -> None:
    value = decode(make_point(**fields), image_of(*words))
    assert value == expected
    assert type(value) is type(expected)


@pytest.mark.parametrize(
    ("kind", "words"),
    [
        ("f16", [0x7E00]),  # NaN
        ("f16", [0x7C00]),  # infinity
        ("f16", [0xFC00]),  # minus infinity
        ("f64", [0x7FF8, 0, 0, 0]),
        ("f64", [0x7FF0, 0, 0, 0]),
    ],
)
def test_a_nan_or_infinite_float_reads_unknown(kind: str, words: list[int]) -> None:
    assert decode(make_point(type=kind), image_of(*words)) is None


def test_a_64_bit_sentinel_reads_unknown() -> None:
    point = make_point(type="u64", sentinels={(1 << 64) - 1: "not measured"})
    assert decode(point, image_of(0xFFFF, 0xFFFF, 0xFFFF, 0xFFFF)) is None
    assert decode(point, image_of(0xFFFF, 0xFFFF, 0xFFFF, 0xFFFE)) == (1 << 64) - 2


ENCODE_CASES = [
    ("u64", {"type": "u64"}, 0x89ABCDEF01234567, HA_WORDS),
    ("u64 little", {"type": "u64", "word_order": "little"}, 0x89ABCDEF01234567, HA_WORDS[::-1]),
    ("u64 max exact", {"type": "u64"}, (1 << 64) - 1, [0xFFFF] * 4),
    ("u64 digits exact", {"type": "u64"}, "18446744073709551614", [0xFFFF] * 3 + [0xFFFE]),
    ("s64 negative", {"type": "s64"}, -2, [0xFFFF, 0xFFFF, 0xFFFF, 0xFFFE]),
    ("s64 min", {"type": "s64"}, -(1 << 63), [0x8000, 0, 0, 0]),
    ("f64", {"type": "f64"}, 1.1, [0x3FF1, 0x9999, 0x9999, 0x999A]),
    (
        "f64 byte swap",
        {"type": "f64", "byte_order": "little"},
        1.1,
        [0xF13F, 0x9999, 0x9999, 0x9A99],
    ),
    ("f16", {"type": "f16"}, 1.5, [0x3E00]),
    ("f16 little", {"type": "f16", "byte_order": "little"}, -5, [0x00C5]),
]


@pytest.mark.parametrize(
    ("fields", "value", "words"), [c[1:] for c in ENCODE_CASES], ids=[c[0] for c in ENCODE_CASES]
)
def test_encode(fields: dict[str, Any], value: object, words: list[int]) -> None:
    point = make_point(access="rw", **fields)
    function = 16 if len(words) > 1 else 6
    assert encode(point, value, {}) == (Write(function, H, 0, tuple(words)),)


@pytest.mark.parametrize(
    ("fields", "value", "message"),
    [
        ({"type": "u64"}, 1 << 64, "does not fit the register"),
        ({"type": "u64"}, -1, "does not fit the register"),
        ({"type": "s64"}, 1 << 63, "does not fit the register"),
        ({"type": "f16"}, 70000, "does not fit a f16 float"),
        ({"type": "f64"}, "nan", "not a finite number"),
        ({"type": "u64", "sentinels": {0: "none"}}, 0, "'unknown' marker"),
    ],
)
def test_a_value_a_wide_type_cannot_hold_is_refused(
    fields: dict[str, Any], value: object, message: str
) -> None:
    with pytest.raises(ValueRejectedError, match=message):
        encode(make_point(access="rw", **fields), value, {})


def _apply(point: Point, value: object) -> dict[tuple[Table, int], int]:
    (write,) = encode(point, value, {})
    assert write.function == (16 if point.count > 1 else 6)  # one frame: all or nothing
    assert all(0 <= word <= 0xFFFF for word in write.values)
    return {(H, write.address + i): word for i, word in enumerate(write.values)}


ORDERS = [{"word_order": w, "byte_order": b} for w in ("big", "little") for b in ("big", "little")]


@pytest.mark.parametrize("kind", ["u64", "s64"])
@pytest.mark.parametrize("orders", ORDERS, ids=lambda o: f"{o['word_order']}-{o['byte_order']}")
@settings(max_examples=100, deadline=None)
@given(data=st.data())
def test_64_bit_integers_round_trip(kind: str, orders: dict[str, str], data: Any) -> None:
    point = make_point(access="rw", type=kind, **orders)
    low, high = raw_bounds(point.entity)
    raw = data.draw(st.integers(low, high))
    assert decode(point, _apply(point, raw)) == raw


@pytest.mark.parametrize("orders", ORDERS, ids=lambda o: f"{o['word_order']}-{o['byte_order']}")
@settings(max_examples=150, deadline=None)
@given(number=st.floats(allow_nan=False, allow_infinity=False))
def test_f64_round_trips(orders: dict[str, str], number: float) -> None:
    point = make_point(access="rw", type="f64", **orders)
    assert decode(point, _apply(point, number)) == number


@settings(max_examples=300, deadline=None)
@given(number=st.floats(width=16, allow_nan=False, allow_infinity=False))
def test_f16_round_trips(number: float) -> None:
    point = make_point(access="rw", type="f16")
    decoded = decode(point, _apply(point, number))
    assert isinstance(decoded, float)
    assert struct.pack(">e", decoded) == struct.pack(">e", number)


@pytest.mark.parametrize(
    "protocol",
    [
        {"max_read_registers": 3},
        {"segments": [{"name": "meter", "start": 0, "end": 9, "max_read_registers": 2}]},
    ],
)
def test_a_64_bit_value_needs_reads_of_4_registers(protocol: dict[str, Any]) -> None:
    with pytest.raises(ValidationError, match="a u64 is read whole, in one request of 4"):
        make_mapping({"value": {"name": "Value", "address": 0, "type": "u64"}}, protocol=protocol)
    make_mapping({"value": {"name": "Value", "address": 0, "type": "u32"}}, protocol=protocol)


@pytest.mark.parametrize(
    ("fields", "message"),
    [
        ({"type": "f16", "enum": {0: "off"}}, "enum needs an integer type"),
        ({"type": "f64", "enum": {0: "off"}}, "enum needs an integer type"),
        ({"type": "u64", "access": "rw", "write_function": 6}, "6 writes one register only"),
        ({"type": "s64", "sentinels": {1 << 64: "x"}}, "outside the raw range"),
        ({"type": "u64", "word_radix": 10000}, "word_radix applies to u32 values only"),
        ({"type": "u64", "address": 65533}, "address"),
    ],
)
def test_the_mapping_refuses_what_a_wide_type_cannot_be(
    fields: dict[str, Any], message: str
) -> None:
    with pytest.raises(ValidationError, match=message):
        make_mapping({"value": {"name": "Value", "address": 0} | fields})


@settings(max_examples=100, deadline=None)
@given(
    starts=st.lists(st.integers(0, 40), min_size=1, max_size=8, unique=True),
    limit=st.integers(4, 12),
    gaps=st.booleans(),
)
def test_a_64_bit_value_is_never_torn(starts: list[int], limit: int, gaps: bool) -> None:
    """A 64-bit value is an atom of four registers: whatever the device's read limit (at
    least four) and wherever the values sit, each is fetched by one read."""
    entities = {
        f"v{i}": {"name": f"V {i}", "address": 5 * start, "type": ("u64", "f64", "s64")[i % 3]}
        for i, start in enumerate(starts)
    }
    points = make_mapping(entities).points().values()
    plan = plan_reads(points, ReadLimits(max_registers=limit, readable_gaps=gaps))
    assert not plan.unplannable
    for point in points:
        holding = [r for r in plan.reads if r.address <= point.address < r.address + r.count]
        assert len(holding) == 1
        (read,) = holding
        assert point.address + 4 <= read.address + read.count


def test_a_gateway_master_writes_a_64_bit_value_whole_or_not_at_all() -> None:
    """A master of the Modbus TCP gateway writing two of a u64's four registers is refused
    (0x03): half a value is never written; all four are the value, exactly."""
    points = make_mapping(
        {"limit": {"name": "Limit", "address": 0, "type": "u64", "access": "rw"}}
    ).points()
    half = ProxyRequest(1, 16, 0, 2, (0x89AB, 0xCDEF))
    with pytest.raises(GatewayRefusalError, match="write its 4 registers at once"):
        items_of(points.values(), {}, half)
    whole = ProxyRequest(1, 16, 0, 4, tuple(HA_WORDS))
    assert items_of(points.values(), {}, whole) == {"limit": 0x89ABCDEF01234567}


def test_where_reads_are_shorter_a_64_bit_value_is_left_out_never_cut() -> None:
    """A limit learnt from the device (it refuses 4 registers): the u64 is named
    unplannable; the u32 beside it is read as before."""
    points = make_mapping(
        {
            "energy": {"name": "Energy", "address": 0, "type": "u64"},
            "power": {"name": "Power", "address": 4, "type": "u32"},
        }
    ).points()
    plan = plan_reads(points.values(), ReadLimits(max_registers=2))
    assert plan.unplannable == ("energy",)
    assert [(r.address, r.count) for r in plan.reads] == [(4, 2)]
