"""``scale_by``: a number scaled by a power of ten another register holds (a SunSpec
``sunssf``), and the sentinels SunSpec marks "not implemented" values with."""

from __future__ import annotations

from decimal import Decimal
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st
from pydantic import ValidationError

from bridge.core.codec import decode, encode, scale_exponent
from bridge.core.entity import Table
from bridge.core.mapping import Mapping, Point, format_validation_errors, parse_mapping
from bridge.core.planner import limits_for, plan_reads
from bridge.core.request import Write
from bridge.errors import MappingError, MissingDataError, ValueRejectedError
from tests.factory import make_mapping

H = Table.HOLDING
Image = dict[tuple[Table, int], int]


def scaled(value: dict[str, Any] | None = None, **top: Any) -> Mapping:
    """A watt value at 0 scaled by ``w_sf`` at 2 (s16), as a SunSpec model lays them out."""
    return make_mapping(
        {
            "w": {
                "name": "Power",
                "address": 0,
                "type": "s16",
                "scale_by": "w_sf",
                **(value or {}),
            },
            "va": {"name": "Apparent power", "address": 1, "scale_by": "w_sf"},
            "w_sf": {"name": "Power scale", "address": 2, "type": "s16"},
        },
        **top,
    )


def point(key: str = "w", value: dict[str, Any] | None = None) -> Point:
    return scaled(value).points()[key]


def image(raw: int, sf: int, va: int = 0) -> Image:
    return {(H, 0): raw & 0xFFFF, (H, 1): va, (H, 2): sf & 0xFFFF}


# --- decode ------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("raw", "sf", "expected"),
    [
        (1234, -2, 12.34),
        (1234, 0, 1234),
        (1234, 2, 123400),
        (-5, -1, -0.5),
        (0x7FFF, -10, 3.2767e-6),
        (7, 10, 70000000000),
        (-32768, 1, -327680),
    ],
)
def test_the_value_is_raw_times_ten_to_the_exponent(raw: int, sf: int, expected: float) -> None:
    got = decode(point(), image(raw, sf))
    assert got == expected
    assert type(got) is type(expected)  # no decimals (sf >= 0): an int


@pytest.mark.parametrize("sf", [0x8000, 11, -11, 0x7FFF, 100])
def test_an_exponent_not_implemented_or_out_of_range_reads_unknown(sf: int) -> None:
    assert decode(point(), image(1234, sf)) is None
    assert decode(point("va"), image(0, sf, va=1)) is None


def test_an_exponent_marked_as_a_sentinel_reads_unknown() -> None:
    mapping = make_mapping(
        {
            "w": {"name": "Power", "address": 0, "scale_by": "w_sf"},
            "w_sf": {"name": "Power scale", "address": 1, "type": "s16", "sentinels": {0: "none"}},
        }
    )
    assert decode(mapping.points()["w"], {(H, 0): 5, (H, 1): 0}) is None


def test_a_value_whose_exponent_was_not_read_is_missing() -> None:
    with pytest.raises(MissingDataError):
        decode(point(), {(H, 0): 1})


def test_the_value_sentinel_wins_over_any_exponent() -> None:
    p = point(value={"sentinels": {0x8000: "not implemented"}})
    assert decode(p, image(-32768, -2)) is None


def test_a_fixed_scale_and_offset_apply_after_the_exponent() -> None:
    p = point(value={"scale": 0.5, "offset": 1})
    assert decode(p, image(30, -1)) == 2.5  # 30 x 0.1 x 0.5 + 1
    p = point(value={"scale": 1000, "precision": 1})
    assert decode(p, image(1234, -3)) == 1234.0  # kW as W, with the precision asked


def test_clamp_and_zero_suppress_shape_the_scaled_reading() -> None:
    p = point(value={"zero_suppress": 0.05, "clamp": {"max": 100}})
    assert decode(p, image(4, -2)) == 0
    assert decode(p, image(20000, -2)) == 100
    assert decode(p, image(-300, -2)) == -3.0


@given(raw=st.integers(-0x8000, 0x7FFF), sf=st.integers(-10, 10))
def test_every_pair_decodes_exactly(raw: int, sf: int) -> None:
    got = decode(point(), image(raw, sf))
    exact = Decimal(raw).scaleb(sf)
    assert isinstance(got, int | float)
    assert Decimal(repr(got)) == exact if isinstance(got, float) else got == exact


def test_scale_exponent_reads_the_register_as_a_signed_power() -> None:
    source = point("w_sf")
    assert scale_exponent(source, {(H, 2): 0xFFFE}) == -2
    assert scale_exponent(source, {(H, 2): 0x8000}) is None


# --- encode ------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("value", "sf", "word"),
    [(12.34, -2, 1234), ("-0.5", -1, 0xFFFB), (123400, 2, 1234), (12.345, -2, 1235)],
)
def test_a_write_is_encoded_with_the_exponent_in_the_image(
    value: object, sf: int, word: int
) -> None:
    p = point(value={"access": "rw"})
    assert encode(p, value, image(0, sf)) == (Write(6, H, 0, (word,)),)


@pytest.mark.parametrize("sf", [0x8000, 11, -11])
def test_a_write_with_an_unknown_exponent_is_refused(sf: int) -> None:
    p = point(value={"access": "rw"})
    with pytest.raises(ValueRejectedError, match="w: its scale factor w_sf is unknown"):
        encode(p, 1.0, image(0, sf))


def test_a_write_whose_exponent_was_never_read_is_refused() -> None:
    p = point(value={"access": "rw"})
    with pytest.raises(ValueRejectedError, match="scale factor w_sf is unknown"):
        encode(p, 1.0, {})


def test_a_write_beyond_the_register_at_this_exponent_is_refused() -> None:
    p = point(value={"access": "rw"})
    assert encode(p, 327.67, image(0, -2)) == (Write(6, H, 0, (0x7FFF,)),)
    with pytest.raises(ValueRejectedError, match="does not fit the register"):
        encode(p, 327.68, image(0, -2))


@given(raw=st.integers(-0x8000, 0x7FFF), sf=st.integers(-10, 10))
def test_what_is_read_is_written_back_as_the_same_word(raw: int, sf: int) -> None:
    p = point(value={"access": "rw"})
    words = image(raw, sf)
    value = decode(p, words)
    assert encode(p, value, words) == (Write(6, H, 0, (raw & 0xFFFF,)),)


# --- checks ------------------------------------------------------------------------------


def errors_of(entities: dict[str, dict[str, Any]], **top: Any) -> list[str]:
    with pytest.raises(ValidationError) as caught:
        make_mapping(entities, **top)
    return list(format_validation_errors(caught.value))


SF = {"name": "Scale", "address": 5, "type": "s16"}


@pytest.mark.parametrize(
    ("sf", "value", "message"),
    [
        (SF, {"scale_by": "nope"}, "entities.v.scale_by: no entity 'nope'"),
        (SF, {"scale_by": "v"}, "entities.v.scale_by: an entity cannot scale itself"),
        (
            SF | {"type": "u16"},
            {},
            "entities.v.scale_by: 'sf' must be a whole s16 number (a power-of-ten exponent)",
        ),
        (
            SF | {"bit": 0, "width": 4},
            {},
            "entities.v.scale_by: 'sf' must be a whole s16 number (a power-of-ten exponent)",
        ),
        (
            SF | {"enum": {0: "x"}},
            {},
            "entities.v.scale_by: 'sf' must be a whole s16 number (a power-of-ten exponent)",
        ),
        (SF | {"access": "w"}, {}, "entities.v.scale_by: 'sf' must be readable"),
        (
            SF | {"table": "input"},
            {},
            "entities.v.scale_by: 'sf' must be on the same table (holding), read with it",
        ),
        (
            SF | {"scale": 0.1},
            {},
            "entities.v.scale_by: 'sf' holds the exponent as it is: no scale, offset or scale_by",
        ),
        (
            SF | {"scale_by": "other"},
            {},
            "entities.v.scale_by: 'sf' holds the exponent as it is: no scale, offset or scale_by",
        ),
    ],
)
def test_scale_by_names_a_readable_unscaled_s16_of_the_same_table(
    sf: dict[str, Any], value: dict[str, Any], message: str
) -> None:
    entities = {
        "v": {"name": "Value", "address": 0, "scale_by": "sf"} | value,
        "sf": sf,
        "other": {"name": "Other", "address": 6, "type": "s16"},
    }
    assert message in errors_of(entities)


@pytest.mark.parametrize(
    ("fields", "message"),
    [
        ({"type": "f32"}, "scale_by scales an integer number (not a float, text, enum or boolean)"),
        ({"enum": {0: "a"}}, "scale_by scales an integer number"),
        ({"bit": 3}, "scale_by scales an integer number"),
        ({"type": "ascii", "count": 2}, "scale_by scales an integer number"),
        (
            {"access": "rw", "dangerous_below": 0, "type": "s16"},
            "dangerous_below is judged on a fixed scale: not with scale_by",
        ),
    ],
)
def test_scale_by_is_for_integer_numbers(fields: dict[str, Any], message: str) -> None:
    entities = {"v": {"name": "Value", "address": 0, "scale_by": "sf"} | fields, "sf": SF}
    assert any(message in row for row in errors_of(entities) if row.startswith("entities.v"))


def test_a_value_and_its_exponent_beyond_one_read_is_read_bracketed() -> None:
    entities = {"v": {"name": "Value", "address": 0, "scale_by": "sf"}, "sf": SF}
    mapping = make_mapping(entities, protocol={"max_read_registers": 5})  # no mapping error
    plan = plan_reads(mapping.points().values(), limits_for(mapping))
    assert plan.unplannable == ()
    assert [(b.exponent.address, b.keys) for b in plan.bracketed] == [(5, ("v",))]


def test_a_value_and_its_exponent_in_two_segments_is_read_bracketed() -> None:
    entities = {"v": {"name": "Value", "address": 0, "scale_by": "sf"}, "sf": SF}
    segments = [{"name": "a", "start": 0, "end": 3}, {"name": "b", "start": 4, "end": 9}]
    mapping = make_mapping(entities, protocol={"segments": segments})
    plan = plan_reads(mapping.points().values(), limits_for(mapping))
    assert [b.keys for b in plan.bracketed] == [("v",)]


def test_a_scale_by_missing_for_some_options_is_named() -> None:
    entities = {
        "v": {"name": "Value", "address": 0, "scale_by": "sf"},
        "sf": SF | {"when": {"model": "b"}},
    }
    options = {"model": {"description": "model", "choices": ["a", "b"], "default": "a"}}
    assert "entities.v.scale_by: 'sf' is missing for some option values" in errors_of(
        entities, options=options
    )


def test_a_mapping_file_error_names_the_file_entity_and_field() -> None:
    text = """
manufacturer: Test
model: T1
description: test device
source: {title: test manual}
entities:
  w: {name: Power, address: 0, scale_by: w_sf}
"""
    with pytest.raises(MappingError) as caught:
        parse_mapping(text, "inverter.yaml")
    assert "inverter.yaml" in str(caught.value)
    assert "entities.w.scale_by: no entity 'w_sf'" in str(caught.value)


# --- SunSpec's "not implemented" values, as sentinels ---------------------------------------


@pytest.mark.parametrize(
    ("fields", "words"),
    [
        ({"type": "s16", "sentinels": {0x8000: "not implemented"}}, [0x8000]),
        ({"sentinels": {0xFFFF: "not implemented"}}, [0xFFFF]),
        ({"enum": {1: "off"}, "sentinels": {0xFFFF: "not implemented"}}, [0xFFFF]),
        ({"type": "s32", "sentinels": {0x80000000: "not implemented"}}, [0x8000, 0]),
        ({"type": "u32", "sentinels": {0xFFFFFFFF: "not implemented"}}, [0xFFFF, 0xFFFF]),
        ({"type": "u32", "sentinels": {0: "not accumulated"}}, [0, 0]),  # acc32
        ({"type": "f32", "sentinels": {0x7FC00000: "not implemented"}}, [0x7FC0, 0]),
        ({"type": "ascii", "count": 2, "sentinels": {0: "not implemented"}}, [0, 0]),
    ],
)
def test_sunspec_not_implemented_values_read_unknown(
    fields: dict[str, Any], words: list[int]
) -> None:
    p = make_mapping({"v": {"name": "Value", "address": 0} | fields}).points()["v"]
    assert decode(p, {(H, i): w for i, w in enumerate(words)}) is None


def test_an_all_zero_text_without_the_sentinel_is_empty_and_text_is_kept() -> None:
    plain = make_mapping({"v": {"name": "Value", "address": 0, "type": "ascii", "count": 2}})
    assert decode(plain.points()["v"], {(H, 0): 0, (H, 1): 0}) == ""
    marked = {"name": "Value", "address": 0, "type": "ascii", "count": 2, "sentinels": {0: "-"}}
    p = make_mapping({"v": marked}).points()["v"]
    assert decode(p, {(H, 0): 0x4142, (H, 1): 0}) == "AB"


def test_text_takes_only_the_all_zero_sentinel() -> None:
    fields = {"name": "Value", "address": 0, "type": "ascii", "count": 2, "sentinels": {1: "x"}}
    assert errors_of({"v": fields}) == [
        "entities.v.sentinels: text takes only 0 (every register 0: no text)"
    ]
