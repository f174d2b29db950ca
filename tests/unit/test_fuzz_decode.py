"""Fuzzing the read path: any register contents for every shipped mapping and option set.

A device may answer anything: words no manual mentions, NaN floats, sentinels, enum codes
out of the table, limit registers that contradict each other, and a read may be missing
(refused, not yet polled). Whatever it holds, decoding raises nothing but the bridge's own
CodecError (MissingDataError), every value is of the entity's kind (finite numbers, labels
of the mapping, booleans, text, or None), and what the bridge builds from the values (the
state document, the plain payloads, the discovery payloads with units and limits read from
registers) is JSON without NaN or infinities.
"""

from __future__ import annotations

import contextlib
import json
import math
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from bridge.core.codec import Value, decode, is_unknown_code, limits_of, unit_of
from bridge.core.discovery import DeviceInfo, Origin, build_discovery
from bridge.core.entity import DataType, Table
from bridge.core.mapping import Point
from bridge.core.state import plain_payload, published, state_document
from bridge.errors import CodecError, MissingDataError
from tests.unit.test_fuzz_commands import MAPPINGS, POINT_SETS, TOPICS, WORDS, combinations

Cell = tuple[Table, int]


def readable_cells(points: dict[str, Point]) -> list[Cell]:
    every = {(p.table, a) for p in points.values() if p.entity.readable for a in p.span}
    return sorted(every, key=lambda cell: (cell[0].value, cell[1]))


@st.composite
def images(draw: st.DrawFn, points: dict[str, Point]) -> dict[Cell, int]:
    """Any word in every cell a poll reads; some cells maybe missing (refused, not read)."""
    cells = readable_cells(points)
    registers = [c for c in cells if not c[0].is_bits]
    bits = [c for c in cells if c[0].is_bits]
    words = draw(st.lists(WORDS, min_size=len(registers), max_size=len(registers)))
    flags = draw(st.lists(st.integers(0, 1), min_size=len(bits), max_size=len(bits)))
    image = dict(zip(registers, words, strict=True)) | dict(zip(bits, flags, strict=True))
    missing = draw(st.sets(st.sampled_from(cells), max_size=3) if cells else st.just(set()))
    return {cell: word for cell, word in image.items() if cell not in missing}


def check_kind(point: Point, value: Value) -> None:
    """The value is of the entity's kind, and JSON."""
    entity = point.entity
    kind = entity.kind
    if value is None:
        return  # a sentinel, a NaN float
    if kind == "enum":
        labels = (entity.enum or {}).values()
        assert value in labels or is_unknown_code(entity, value), f"{point.key}: {value!r}"
    elif kind == "bool":
        assert isinstance(value, bool), f"{point.key}: {value!r}"
    elif kind == "text":
        assert isinstance(value, str), f"{point.key}: {value!r}"
    else:
        assert isinstance(value, int | float), f"{point.key}: {value!r}"
        assert not isinstance(value, bool), point.key
        assert math.isfinite(value), f"{point.key}: {value!r}"
        if entity.data_type is not DataType.F32 and entity.decimals == 0:
            assert isinstance(value, int), f"{point.key}: {value!r} has no decimals"
    json.dumps(value, allow_nan=False)


def values_of(points: dict[str, Point], image: dict[Cell, int]) -> dict[str, Value]:
    """Decode like the poller: a value that needs a missing register is None."""
    values: dict[str, Value] = {}
    for key, point in points.items():
        if not point.entity.readable:
            continue
        try:
            value = decode(point, image)
        except MissingDataError:
            value = None
        check_kind(point, value)
        values[key] = value
    return values


def discovery_inputs(
    points: dict[str, Point], image: dict[Cell, int]
) -> tuple[dict[str, str | None], dict[str, Any]]:
    """Units and limits read from registers, as the bridge gathers them for discovery."""
    units: dict[str, str | None] = {}
    limits: dict[str, Any] = {}
    for key, point in points.items():
        if point.unit_source is not None:
            unit = unit_of(point, image)
            assert unit is None or isinstance(unit, str)
            units[key] = unit
        if point.min_source is not None or point.max_source is not None:
            with contextlib.suppress(MissingDataError):
                low, high = limits_of(point, image)
                for bound in (low, high):
                    assert bound is None or math.isfinite(bound), key
                limits[key] = (low, high)
    return units, limits


@pytest.mark.parametrize("name", sorted(MAPPINGS))
@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_any_register_content_decodes_to_json_of_the_entity_s_kind(
    name: str, data: st.DataObject
) -> None:
    mapping = MAPPINGS[name]
    index = data.draw(st.integers(0, len(POINT_SETS[name]) - 1))
    points = POINT_SETS[name][index]
    image = data.draw(images(points))
    values = values_of(points, image)

    document = state_document(mapping, points, values)
    assert json.loads(json.dumps(document, allow_nan=False)) == document
    for key in published(points):
        payload = plain_payload(values[key])
        if not isinstance(values[key], str):
            assert json.loads(payload) == values[key]

    units, limits = discovery_inputs(points, image)
    device = DeviceInfo(
        id="dev",
        name="Device",
        mapping=mapping,
        options=combinations(mapping)[index],
        bus="bus",
        unit=1,
        allow_dangerous_writes=False,
        fast_interval=2.0,
        slow_interval=60.0,
    )
    for mode in ("device", "entity"):
        for message in build_discovery(
            device, TOPICS, Origin(), mode=mode, units=units, limits=limits
        ):
            payload = json.loads(message.payload)
            json.dumps(payload, allow_nan=False)
            components = payload.get("cmps", {"one": payload})
            for component in components.values():
                if "min" in component and "max" in component:
                    assert component["min"] <= component["max"], component


@pytest.mark.parametrize("name", sorted(MAPPINGS))
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_one_entity_any_words_raises_only_codec_errors(name: str, data: st.DataObject) -> None:
    """One point with any words, including none at all for some of its registers."""
    points = data.draw(st.sampled_from(POINT_SETS[name]))
    point = data.draw(st.sampled_from([p for p in points.values() if p.entity.readable]))
    parts = [p for p in (point, point.sign) if p is not None]
    image: dict[Cell, int] = {}
    for part in parts:
        for address in part.span:
            if data.draw(st.integers(0, 9)) == 0:
                continue  # not read
            top = 1 if part.table.is_bits else 0xFFFF
            image[(part.table, address)] = data.draw(st.one_of(WORDS, st.integers(0, top)))
            if part.table.is_bits:
                image[(part.table, address)] &= 1
    try:
        value = decode(point, image)
    except CodecError:
        return
    check_kind(point, value)
