"""interpret(): raw registers read every way a manual might mean them, checked by hand."""

from __future__ import annotations

import json
import math
import re
import struct

import pytest
from hypothesis import given
from hypothesis import strategies as st

from bridge.core.interpret import ORDERS, f32_value, interpret, interpret_bits, pair_bytes, words_of

WORDS = st.integers(0, 0xFFFF)


def pair(words: list[int], order: str, index: int = 0) -> dict[str, object]:
    return interpret(100, words)["pairs"][index][order]  # type: ignore[no-any-return]


@pytest.mark.parametrize(
    ("words", "order", "u32", "s32", "f32"),
    [
        ([0x4148, 0x0000], "ABCD", 0x41480000, 0x41480000, 12.5),
        ([0x0000, 0x4148], "CDAB", 0x41480000, 0x41480000, 12.5),
        ([0x4841, 0x0000], "BADC", 0x41480000, 0x41480000, 12.5),
        ([0x0000, 0x4841], "DCBA", 0x41480000, 0x41480000, 12.5),
        ([0x0001, 0x0000], "ABCD", 65536, 65536, 9.1835e-41),
        ([0x0001, 0x0000], "CDAB", 1, 1, 1e-45),
        ([0x0001, 0x0000], "BADC", 0x01000000, 0x01000000, 2.3509887e-38),
        ([0x0001, 0x0000], "DCBA", 256, 256, 3.59e-43),
        ([0xFFFF, 0xFFFE], "ABCD", 0xFFFFFFFE, -2, "nan"),
        ([0xFFFE, 0xFFFF], "CDAB", 0xFFFFFFFE, -2, "nan"),
        ([0x3DCC, 0xCCCD], "ABCD", 0x3DCCCCCD, 0x3DCCCCCD, 0.1),
        ([0xC2F6, 0xE979], "ABCD", 0xC2F6E979, -1024005767, -123.456),
        ([0x7F80, 0x0000], "ABCD", 0x7F800000, 0x7F800000, "inf"),
        ([0xFF80, 0x0000], "ABCD", 0xFF800000, -8388608, "-inf"),
        ([0x8000, 0x0000], "ABCD", 0x80000000, -(2**31), -0.0),
    ],
)
def test_pairs_in_every_order(
    words: list[int], order: str, u32: int, s32: int, f32: float | str
) -> None:
    assert pair(words, order) == {"u32": u32, "s32": s32, "f32": f32}


def test_the_largest_float32_does_not_round_out_of_range() -> None:
    assert f32_value(bytes.fromhex("7F7FFFFF")) == 3.4028235e38
    assert f32_value(bytes.fromhex("7F7FFF00")) == 3.4027717e38


def test_negative_zero_keeps_its_sign() -> None:
    value = pair([0x8000, 0x0000], "ABCD")["f32"]
    assert isinstance(value, float)
    assert math.copysign(1.0, value) == -1.0


def test_one_word_in_full() -> None:
    result = interpret(0x0097, [0x4142])
    assert result == {
        "address": 0x0097,
        "count": 1,
        "registers": [0x4142],
        "hex": ["0x4142"],
        "words": [
            {
                "address": 0x0097,
                "u16": 16706,
                "s16": 16706,
                "hex": "0x4142",
                "ascii": "AB",
                "bits": "0100 0001 0100 0010",
            }
        ],
        "pairs": [],
    }


@pytest.mark.parametrize(
    ("word", "u16", "s16", "ascii", "bits"),
    [
        (0x0000, 0, 0, "..", "0000 0000 0000 0000"),
        (0x0102, 258, 258, "..", "0000 0001 0000 0010"),
        (0x7FFF, 32767, 32767, "..", "0111 1111 1111 1111"),
        (0x8000, 32768, -32768, "..", "1000 0000 0000 0000"),
        (0xFFFF, 65535, -1, "..", "1111 1111 1111 1111"),
        (0x2041, 8257, 8257, " A", "0010 0000 0100 0001"),
        (0x7E7F, 32383, 32383, "~.", "0111 1110 0111 1111"),
    ],
)
def test_word_readings(word: int, u16: int, s16: int, ascii: str, bits: str) -> None:
    reading = interpret(0, [word])["words"][0]
    assert (reading["u16"], reading["s16"], reading["ascii"], reading["bits"]) == (
        u16,
        s16,
        ascii,
        bits,
    )


def test_pairs_cover_every_adjacent_pair_with_its_address() -> None:
    result = interpret(10, [1, 2, 3, 4])
    assert [p["address"] for p in result["pairs"]] == [10, 11, 12]
    assert [p["ABCD"]["u32"] for p in result["pairs"]] == [0x10002, 0x20003, 0x30004]
    assert [w["address"] for w in result["words"]] == [10, 11, 12, 13]
    assert result["hex"] == ["0x0001", "0x0002", "0x0003", "0x0004"]


def test_no_words_is_an_empty_reading() -> None:
    assert interpret(5, []) == {
        "address": 5,
        "count": 0,
        "registers": [],
        "hex": [],
        "words": [],
        "pairs": [],
    }


@pytest.mark.parametrize(
    ("address", "words", "message"),
    [
        (0, [0x10000], "register value 65536 is outside 0..65535"),
        (0, [-1], "register value -1 is outside 0..65535"),
        (-1, [0], "address -1 with 1 values is outside 0..65535"),
        (0xFFFF, [0, 0], "address 65535 with 2 values is outside 0..65535"),
    ],
)
def test_impossible_input_is_refused(address: int, words: list[int], message: str) -> None:
    with pytest.raises(ValueError, match=re.escape(message)):
        interpret(address, words)


def test_unknown_byte_order_is_refused() -> None:
    with pytest.raises(ValueError, match="byte order 'ACBD' is not one of ABCD, CDAB"):
        pair_bytes("ACBD", 0, 0)


def test_bits() -> None:
    result = interpret_bits(16, [1, 0, 1, 0, 0, 0, 0, 0, 1, 1])
    assert result == {
        "address": 16,
        "count": 10,
        "bits": [1, 0, 1, 0, 0, 0, 0, 0, 1, 1],
        "on": [16, 18, 24, 25],
        "bytes": ["0x05", "0x03"],
    }


def test_bits_must_be_0_or_1() -> None:
    with pytest.raises(ValueError, match="bit value 2 is not 0 or 1"):
        interpret_bits(0, [0, 2])
    with pytest.raises(ValueError, match=re.escape("outside 0..65535")):
        interpret_bits(0xFFFF, [0, 1])


@given(st.lists(WORDS, max_size=125), st.integers(0, 0xFFFF - 125))
def test_every_reading_is_json_and_reencodes_to_the_same_words(
    words: list[int], address: int
) -> None:
    result = json.loads(json.dumps(interpret(address, words), allow_nan=False))
    assert result["registers"] == words
    for word, reading in zip(words, result["words"], strict=True):
        assert reading["u16"] == word
        assert reading["s16"] & 0xFFFF == word
        assert int(reading["hex"], 16) == word
        assert int(reading["bits"].replace(" ", ""), 2) == word
        text = reading["ascii"].encode("ascii")
        for byte, shown in zip(word.to_bytes(2, "big"), text, strict=True):
            assert shown == byte or shown == ord(".")
    for i, reading in enumerate(result["pairs"]):
        expected = (words[i], words[i + 1])
        for order in ORDERS:
            values = reading[order]
            assert words_of(order, values["u32"].to_bytes(4, "big")) == expected
            assert words_of(order, values["s32"].to_bytes(4, "big", signed=True)) == expected
            if isinstance(values["f32"], float):  # NaN payloads are lossy by nature
                assert words_of(order, struct.pack(">f", values["f32"])) == expected


@given(st.floats(width=32, allow_nan=False, allow_infinity=False))
def test_f32_is_the_shortest_decimal_of_the_same_float(value: float) -> None:
    raw = struct.pack(">f", value)
    shown = f32_value(raw)
    assert isinstance(shown, float)
    assert struct.pack(">f", shown) == raw
    digits = len(repr(shown).split("e")[0].replace("-", "").replace(".", "").strip("0"))
    if digits > 1:  # one digit fewer would not read back
        shorter = float(f"{shown:.{digits - 1}g}")
        assert abs(shorter) > 3.4028235e38 or struct.pack(">f", shorter) != raw


@given(st.lists(st.integers(0, 1), max_size=2000))
def test_bits_reencode(bits: list[int]) -> None:
    result = interpret_bits(0, bits)
    data = bytes(int(byte, 16) for byte in result["bytes"])
    assert [(data[i // 8] >> (i % 8)) & 1 for i in range(len(bits))] == bits
    assert result["on"] == [i for i, bit in enumerate(bits) if bit]
