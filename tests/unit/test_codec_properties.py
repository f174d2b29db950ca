"""Property tests: decode(encode(x)) == x over each type's range; out-of-range is refused."""

from __future__ import annotations

import struct
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bridge.core.codec import decode, encode, raw_bounds, scale_value
from bridge.core.entity import Table
from bridge.core.mapping import Point
from bridge.errors import ValueRejectedError
from tests.factory import make_point

H = Table.HOLDING

INTEGER_TYPES: list[dict[str, Any]] = [
    {"type": "u16"},
    {"type": "s16"},
    {"type": "u32"},
    {"type": "u32", "word_order": "little"},
    {"type": "u32", "byte_order": "little"},
    {"type": "s32"},
    {"type": "s32", "word_order": "little"},
    {"type": "u32", "word_radix": 10000},
    {"type": "u32", "word_radix": 60, "word_order": "little"},
    {"type": "u16", "scale": 0.1},
    {"type": "s16", "scale": 0.01},
    {"type": "u16", "scale": 0.5, "offset": -40},
    {"type": "s32", "scale": 0.001},
    {"type": "u16", "scale": 10},
]


def _apply(point: Point, value: object, image: dict) -> dict:
    result = dict(image)
    for write in encode(point, value, image):
        assert write.table is H
        for offset, word in enumerate(write.values):
            assert 0 <= word <= 0xFFFF, "nothing out of range reaches the wire"
            result[(H, write.address + offset)] = word
    return result


@pytest.mark.parametrize("fields", INTEGER_TYPES, ids=lambda f: "-".join(map(str, f.values())))
@settings(max_examples=150, deadline=None)
@given(data=st.data())
def test_round_trip_over_the_raw_range(fields: dict[str, Any], data: st.DataObject) -> None:
    point = make_point(access="rw", **fields)
    low, high = raw_bounds(point.entity)
    raw = data.draw(st.integers(low, high))
    value = scale_value(point.entity, raw)
    assert decode(point, _apply(point, value, {})) == value


@pytest.mark.parametrize("fields", INTEGER_TYPES, ids=lambda f: "-".join(map(str, f.values())))
@settings(max_examples=60, deadline=None)
@given(data=st.data())
def test_beyond_the_raw_range_is_refused(fields: dict[str, Any], data: st.DataObject) -> None:
    point = make_point(access="rw", **fields)
    low, high = raw_bounds(point.entity)
    raw = data.draw(
        st.one_of(st.integers(high + 1, high + 10**6), st.integers(low - 10**6, low - 1))
    )
    value = scale_value(point.entity, raw)
    with pytest.raises(ValueRejectedError):
        encode(point, value, {})


@settings(max_examples=200, deadline=None)
@given(
    bit=st.integers(0, 15),
    data=st.data(),
    word=st.integers(0, 0xFFFF),
)
def test_fields_round_trip_and_keep_other_bits(bit: int, data: st.DataObject, word: int) -> None:
    width = data.draw(st.integers(1, 16 - bit))
    point = (
        make_point(access="rw", bit=bit, width=width)
        if width > 1
        else make_point(access="rw", bit=bit)
    )
    value = data.draw(st.integers(0, (1 << width) - 1))
    written = _apply(point, bool(value) if width == 1 else value, {(H, 0): word})
    expected = bool(value) if width == 1 else value
    assert decode(point, written) == expected
    mask = ((1 << width) - 1) << bit
    assert written[(H, 0)] & ~mask == word & ~mask


@settings(max_examples=200, deadline=None)
@given(number=st.floats(width=32, allow_nan=False, allow_infinity=False))
def test_f32_round_trip(number: float) -> None:
    point = make_point(access="rw", type="f32")
    decoded = decode(point, _apply(point, number, {}))
    assert struct.pack(">f", decoded) == struct.pack(">f", number)


@settings(max_examples=200, deadline=None)
@given(text=st.text(st.characters(min_codepoint=0x21, max_codepoint=0x7E), max_size=8))
def test_ascii_round_trip(text: str) -> None:
    point = make_point(access="rw", type="ascii", count=4)
    assert decode(point, _apply(point, text, {})) == text


@settings(max_examples=100, deadline=None)
@given(
    labels=st.lists(
        st.text(st.characters(categories=["L"]), min_size=1, max_size=6),
        min_size=1,
        max_size=8,
        unique_by=str.casefold,
    ),
    data=st.data(),
)
def test_enum_round_trip(labels: list[str], data: st.DataObject) -> None:
    enum = {index * 3: label for index, label in enumerate(labels)}
    point = make_point(access="rw", enum=enum)
    label = data.draw(st.sampled_from(labels))
    assert decode(point, _apply(point, label, {})) == label


@settings(max_examples=100, deadline=None)
@given(value=st.floats(allow_nan=False, allow_infinity=False))
def test_static_limits_hold_for_any_value(value: float) -> None:
    point = make_point(access="rw", scale=0.1, min=-5, max=999.9, type="s16")
    if -5 <= value <= 999.9:
        written = _apply(point, value, {})
        assert -5 <= decode(point, written) <= 999.9
    else:
        with pytest.raises(ValueRejectedError):
            encode(point, value, {})
