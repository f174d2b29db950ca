"""Every shipped mapping loads for every option combination, decodes any register content,
encodes its buttons, and follows the presentation conventions."""

from __future__ import annotations

import itertools

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from bridge.core.codec import Image, decode, encode, raw_bounds, scale_value
from bridge.core.entity import Access, Component, Confidence, DataType
from bridge.core.mapping import (
    Mapping,
    Point,
    builtin_mapping_names,
    builtin_mapping_path,
    library_problems,
    load_mapping,
)
from bridge.errors import MissingDataError, ValueRejectedError
from tests.library.layout import has_no_status

SEEDS = ["nastec_vasco", "p2_vfd", "soft_starter", "vacon_nx", "smartgen_hgm6100"]
MAPPINGS = {name: load_mapping(builtin_mapping_path(name)) for name in builtin_mapping_names()}


def combinations(mapping: Mapping) -> list[dict[str, str]]:
    names = list(mapping.options)
    choices = [mapping.options[n].choices for n in names]
    return [dict(zip(names, combo, strict=True)) for combo in itertools.product(*choices)]


def image_for(points: dict[str, Point], fill: int = 0) -> dict:
    image = {}
    for point in points.values():
        for address in point.span:
            image[(point.table, address)] = min(fill, 1) if point.table.is_bits else fill
    return image


def test_the_five_seed_mappings_ship() -> None:
    assert set(SEEDS) <= set(MAPPINGS)


@pytest.mark.parametrize("name", sorted(MAPPINGS))
def test_every_option_combination_resolves(name: str) -> None:
    mapping = MAPPINGS[name]
    for options in combinations(mapping):
        points = mapping.points(options)
        assert points, options
        for point in points.values():
            assert point.address >= 0 and point.address + point.count <= 0x10000


@pytest.mark.parametrize("name", sorted(MAPPINGS))
def test_status_and_alarms_are_declared(name: str) -> None:
    """Every device with a status word declares it and its alarms; a meter has neither
    (docs/mappings.md, Library)."""
    mapping = MAPPINGS[name]
    if has_no_status(mapping):
        assert not any(e.alarm for e in mapping.entities.values())
        return
    assert mapping.status in mapping.entities
    assert any(e.alarm for e in mapping.entities.values())


@pytest.mark.parametrize("name", sorted(MAPPINGS))
def test_presentation_conventions(name: str) -> None:
    mapping = MAPPINGS[name]
    for key, e in mapping.entities.items():
        assert mapping.manufacturer.split()[0].lower() not in e.name.lower(), key
        if e.confidence is Confidence.LOW:
            assert not e.enabled_by_default, key
        if e.secret:
            assert e.dangerous, key
        if e.component is Component.BUTTON:
            assert e.access is Access.WRITE, key


@pytest.mark.parametrize("name", sorted(MAPPINGS))
def test_the_naming_conventions_are_errors_for_the_shipped_mappings(name: str) -> None:
    """The naming conventions are the library's (a user's mapping is not checked against
    them): a shipped mapping has none, here they are errors."""
    assert library_problems(MAPPINGS[name]) == []


def test_the_naming_test_fails_for_a_shipped_mapping_that_shouts() -> None:
    """The test above can fail: one shipped entity renamed in capitals is found."""
    mapping = MAPPINGS["nastec_vasco"]
    key, entity = next(iter(mapping.entities.items()))
    shouting = entity.model_copy(update={"name": "Motor SPEED"})
    broken = mapping.model_copy(update={"entities": mapping.entities | {key: shouting}})
    assert library_problems(broken) == [
        f"entities.{key}.name: 'SPEED' is written in capitals: write it as a word, or add the "
        "abbreviation to bridge/core/convention.py ('Motor SPEED')"
    ]


@pytest.mark.parametrize("name", sorted(MAPPINGS))
def test_buttons_encode_with_the_registers_they_need(name: str) -> None:
    mapping = MAPPINGS[name]
    for options in combinations(mapping):
        points = mapping.points(options)
        image = image_for(points)
        for key, point in points.items():
            if point.entity.press is None:
                continue
            if point.entity.field_width is not None:
                image |= {(point.table, point.address): 0}
            writes = encode(point, "PRESS", image)
            assert writes, key
            for write in writes:
                assert all(0 <= v <= 0xFFFF for v in write.values), key


@pytest.mark.parametrize("name", sorted(MAPPINGS))
def test_writable_values_round_trip_from_the_device(name: str) -> None:
    """What a device reports for a writable value can be written back unchanged."""
    mapping = MAPPINGS[name]
    points = mapping.points()
    for fill in (0, 1, 5):
        image = image_for(points, fill)
        for key, point in points.items():
            e = point.entity
            if e.access is not Access.READ_WRITE or e.secret:
                continue
            value = decode(point, image)
            if value is None:
                continue
            try:
                writes = encode(point, value, image)
            except ValueRejectedError:
                continue  # the device reported a value outside the documented range
            written = dict(image)
            for write in writes:
                for offset, word in enumerate(write.values):
                    written[(write.table, write.address + offset)] = word
            assert decode(point, written) == value, key


@pytest.mark.parametrize("name", sorted(MAPPINGS))
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_any_register_content_decodes(name: str, data: st.DataObject) -> None:
    mapping = MAPPINGS[name]
    options = data.draw(st.sampled_from(combinations(mapping)))
    points = mapping.points(options)
    image: Image = {}
    for point in points.values():
        for address in point.span:
            top = 1 if point.table.is_bits else 0xFFFF
            image[(point.table, address)] = data.draw(st.integers(0, top))  # type: ignore[index]
    for key, point in points.items():
        if not point.entity.readable:
            continue
        try:
            value = decode(point, image)
        except MissingDataError:
            pytest.fail(f"{key} needs a register the mapping does not read")
        assert value is None or isinstance(value, bool | int | float | str), key


@pytest.mark.parametrize("name", sorted(MAPPINGS))
def test_number_limits_fit_the_register_in_every_variant(name: str) -> None:
    """A writable number's min/max (after its variant's scale) lie inside what its register
    can hold: Home Assistant is never offered a value the codec would refuse as too large."""
    mapping = MAPPINGS[name]
    for options in combinations(mapping):
        for key, point in mapping.points(options).items():
            e = point.entity
            if not e.writable or e.kind != "number" or e.data_type is DataType.F32:
                continue
            ends = sorted(scale_value(e, raw) for raw in raw_bounds(e))
            low, high = (-ends[1], ends[1]) if point.sign is not None else (ends[0], ends[1])
            for limit in (e.min, e.max):
                assert limit is None or low <= limit <= high, (options, key, limit, (low, high))
