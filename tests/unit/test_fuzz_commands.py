"""Fuzzing the command path: any payload on any /set topic of every shipped mapping.

What the bridge does with a command before a byte reaches the wire is pure: the topic
(``Topics.parse_command``), the payload (``parse_set``) and the value (``codec.encode``
against the register image the poller holds). Whatever arrives, that path either returns
writes that put a value within the entity's declared limits on the device (16-bit words,
an enum label of the mapping, a boolean) or refuses with the bridge's own CodecError;
never anything else, which would end the MQTT session or the bridge.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
from collections.abc import Iterable
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from bridge.core.codec import Image, decode, encode, limits_of, parse_bool
from bridge.core.commands import MAX_PAYLOAD, parse_get, parse_set
from bridge.core.entity import DataType, Table
from bridge.core.mapping import (
    Mapping,
    Point,
    builtin_mapping_names,
    builtin_mapping_path,
    load_mapping,
)
from bridge.core.request import Write
from bridge.core.simulation import initial_image, stored_cells
from bridge.core.topics import Action, Topics
from bridge.errors import CodecError, ValueRejectedError

TOPICS = Topics("modbus")
DEVICE = "dev"
MAPPINGS = {name: load_mapping(builtin_mapping_path(name)) for name in builtin_mapping_names()}

# Payloads that have broken command parsers somewhere: JSON oddities, numbers beyond every
# register, text that is not UTF-8, nesting deeper than the JSON parser's recursion limit.
HOSTILE: tuple[bytes, ...] = (
    b"", b" ", b"\n", b"null", b"true", b"false", b"ON", b"off", b"PRESS", b"press ",
    b"0", b"1", b"-1", b"-0", b"0.0", b"1.5", b"-1.5", b"4.9999999999", b"0.05", b"1e-320",
    b"1e400", b"-1e400", b"NaN", b"Infinity", b"-Infinity", b'"NaN"', b'"inf"', b'"1e400"',
    b"1" + b"0" * 400, b"-" + b"9" * 400, b"9" * (MAX_PAYLOAD - 1), b"0x10", b"1_000",
    b"65535", b"65536", b"-32768", b"-32769", b"4294967295", b"4294967296",
    b"[]", b"{}", b"[1]", b'{"a": 1}', b'"x"', b'"ON"', b'"\\ud800"', b"\xff\xfe\xfd",
    b"\x00", b"\xc3\xa9", b"[" * 3000, b'{"a":' * 1500, b"[" * 3000 + b"]" * 3000,
    b" " * (MAX_PAYLOAD + 1),
)  # fmt: skip


# --- the mappings --------------------------------------------------------------------


def combinations(mapping: Mapping) -> list[dict[str, str]]:
    names = list(mapping.options)
    choices = [mapping.options[n].choices for n in names]
    return [dict(zip(names, combo, strict=True)) for combo in itertools.product(*choices)]


POINT_SETS = {
    name: [mapping.points(options) for options in combinations(mapping)]
    for name, mapping in MAPPINGS.items()
}
REALISTIC = {  # what the simulator holds at start: settings inside their limits
    name: [initial_image(MAPPINGS[name], points) for points in sets]
    for name, sets in POINT_SETS.items()
}


def distinct_points(name: str) -> list[tuple[int, Point]]:
    """Every point of a mapping once per distinct resolution (options change a few), with
    the index of a point set it belongs to."""
    seen: set[tuple[str, str, int, int]] = set()
    found = []
    for index, points in enumerate(POINT_SETS[name]):
        for key, point in points.items():
            signature = (key, point.entity.model_dump_json(), point.address, point.write_address)
            if signature not in seen:
                seen.add(signature)
                found.append((index, point))
    return found


def cells(points: dict[str, Point], keys: Iterable[str]) -> list[tuple[Table, int]]:
    """The cells a write of these keys depends on: their words, signs and limit registers."""
    found: set[tuple[Table, int]] = set()
    for key in keys:
        point = points.get(key)
        if point is None:
            continue
        for part in (point, point.sign, point.min_source, point.max_source):
            if part is not None:
                found |= {(part.table, a) for a in part.span}
    return sorted(found, key=lambda cell: (cell[0].value, cell[1]))


# --- the property ----------------------------------------------------------------------


def command(points: dict[str, Point], topic: str, payload: bytes, image: Image) -> set[str]:
    """Run a /set message through the bridge's pure path and check what would be written;
    return the keys it would write."""
    target = TOPICS.parse_command(topic)
    assert target is not None
    assert target.action is Action.SET
    try:
        items = parse_set(payload, target.key)
    except ValueRejectedError:
        return set()
    accepted: set[str] = set()
    for key, value in items.items():
        point = points.get(key)
        if point is None:
            continue  # the poller refuses: no such entity
        try:
            writes = encode(point, value, image)
        except CodecError:
            continue
        check_writes(point, value, image, writes)
        accepted.add(key)
    return accepted


def check_writes(point: Point, value: object, image: Image, writes: Iterable[Write]) -> None:
    entity = point.entity
    targets = {
        (point.table, a) for a in range(point.write_address, point.write_address + point.count)
    }
    if point.sign is not None:
        targets.add((point.sign.table, point.sign.write_address))
    after = dict(image)
    for write in writes:
        assert write.function in (5, 6, 15, 16), write
        assert write.values, write
        assert all(0 <= word <= 0xFFFF for word in write.values), write
        if write.function == 5:
            assert write.values in ((0,), (point.coil_on_value,)), write
        if write.function == 15:
            assert set(write.values) <= {0, 1}, write
        if write.function == 6:
            assert len(write.values) == 1, write
        spanned = {(write.table, write.address + i) for i in range(len(write.values))}
        assert spanned <= targets, f"{point.key}: {write} outside {sorted(targets)}"
        after |= stored_cells(write)
    if point.state_source is not None:  # a toggle: the ON word, only towards the other state
        state = bool(decode(point.state_source, image))
        assert bool(writes) == (state != parse_bool(point.key, value)), (point.key, value)
        assert all(w.values == (point.coil_on_value,) for w in writes), writes
        return
    if entity.press is not None or entity.pulse:
        return  # a command word: the words are checked above, the value is the press value
    held = decode(at_write_address(point), after)
    check_value(point, value, held, image)


def at_write_address(point: Point) -> Point:
    """The point as the device stores it: read where it is written."""
    sign = point.sign
    if sign is not None:
        sign = dataclasses.replace(sign, address=sign.write_address)
    return dataclasses.replace(point, address=point.write_address, sign=sign)


def check_value(point: Point, value: object, held: object, image: Image) -> None:
    entity = point.entity
    kind = entity.kind
    if kind == "enum":
        labels = list((entity.enum or {}).values())
        assert held in labels, f"{point.key}: {held!r} not a label"
        if isinstance(value, str):
            assert held == value or str(held).casefold() == value.strip().casefold()
        else:
            assert held == (entity.enum or {})[value]  # type: ignore[index]
    elif kind == "bool":
        assert isinstance(held, bool), f"{point.key}: {held!r}"
        assert held == parse_bool(point.key, value)
    elif kind == "text":
        assert isinstance(held, str)
    else:
        assert isinstance(held, int | float), f"{point.key}: {held!r}"
        assert not isinstance(held, bool)
        assert math.isfinite(held)
        low, high = limits_of(point, image)
        assert low is None or held >= low, f"{point.key}: {value!r} -> {held} < {low}"
        assert high is None or held <= high, f"{point.key}: {value!r} -> {held} > {high}"
        asked = float(value)  # type: ignore[arg-type]
        if entity.data_type is DataType.F32:
            assert math.isclose(held, asked, rel_tol=1e-6, abs_tol=1e-30)
        else:
            assert abs(held - asked) <= abs(entity.scale) / 2 + 1e-9 * max(1.0, abs(asked))


# --- a fixed sweep: every entity of every mapping, hostile payloads -------------------


def tailored(point: Point, image: Image) -> list[bytes]:
    """Values at and beyond the entity's limits (static and read from registers) and its
    labels, as plain payloads."""
    entity = point.entity
    values: list[object] = []
    limits = limits_of(point, image) if entity.kind == "number" else (None, None)
    for limit in {entity.min, entity.max, *limits} - {None}:
        assert limit is not None
        values += [limit, limit - entity.scale, limit + entity.scale, limit + entity.scale / 2]
    values += list((entity.enum or {}).values()) + list(entity.enum or {})
    values += [str(label).upper() for label in (entity.enum or {}).values()]
    return [json.dumps(v).encode() for v in values] + [str(v).encode() for v in values]


@pytest.mark.parametrize("name", sorted(MAPPINGS))
def test_every_entity_with_hostile_payloads(name: str) -> None:
    never_written = set()
    for index, point in distinct_points(name):
        points, image = POINT_SETS[name][index], REALISTIC[name][index]
        plain_topic = TOPICS.set(DEVICE, point.key)
        accepted: set[str] = set()
        for payload in (*HOSTILE, *tailored(point, image)):
            accepted |= command(points, plain_topic, payload, image)
            try:
                inner = json.loads(payload)
            except (ValueError, RecursionError):
                inner = payload.decode(errors="replace")
            document = json.dumps({point.key: inner}).encode()
            accepted |= command(points, TOPICS.set(DEVICE), document, image)
        if point.entity.writable and point.key not in accepted:
            never_written.add(point.key)
    assert not never_written, "the sweep must reach the wire for every writable entity"


# --- hypothesis: any payload, any register image ----------------------------------------

WORDS = st.one_of(
    st.sampled_from([0, 1, 0x7FFF, 0x8000, 0xFFFF, 0x7F80, 0x7FC0]), st.integers(0, 0xFFFF)
)
SCALARS = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(),
    st.integers(-(10**400), 10**400),
    st.floats(),
    st.text(max_size=20),
)
JSON_VALUES = st.recursive(
    SCALARS,
    lambda inner: (
        st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=5), inner, max_size=3)
    ),
    max_leaves=6,
)


@st.composite
def images(draw: st.DrawFn, name: str, index: int, keys: Iterable[str]) -> dict[Any, int]:
    """The poller's image: realistic, or any word in the cells the writes depend on (limit
    registers, sign bits, the word around a bit field)."""
    image = dict(REALISTIC[name][index])
    if draw(st.booleans()):
        for cell in cells(POINT_SETS[name][index], keys):
            image[cell] = draw(st.integers(0, 1)) if cell[0].is_bits else draw(WORDS)
    return image


@st.composite
def plain_payloads(draw: st.DrawFn, point: Point) -> bytes:
    entity = point.entity
    near = [v for v in (entity.min, entity.max, 0) if v is not None]
    numbers = st.sampled_from(near).flatmap(
        lambda v: st.floats(v - 10 * abs(entity.scale), v + 10 * abs(entity.scale))
    )
    labels = list((entity.enum or {}).values()) or ["ON", "OFF", "PRESS"]
    return draw(
        st.one_of(
            st.binary(max_size=40),
            st.text(max_size=20).map(str.encode),
            JSON_VALUES.map(lambda v: json.dumps(v).encode()),
            numbers.map(lambda v: repr(v).encode()),
            st.sampled_from(labels).map(lambda label: f" {label.swapcase()} ".encode()),
            st.sampled_from(HOSTILE),
        )
    )


def keys_of(points: dict[str, Point]) -> st.SearchStrategy[str]:
    return st.one_of(st.sampled_from(sorted(points)), st.text(max_size=8))


FUZZ = settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@pytest.mark.parametrize("name", sorted(MAPPINGS))
@FUZZ
@given(data=st.data())
def test_any_payload_on_a_key_topic(name: str, data: st.DataObject) -> None:
    index = data.draw(st.integers(0, len(POINT_SETS[name]) - 1))
    points = POINT_SETS[name][index]
    key = data.draw(st.sampled_from(sorted(points)))
    payload = data.draw(plain_payloads(points[key]))
    image = data.draw(images(name, index, [key]))
    command(points, TOPICS.set(DEVICE, key), payload, image)


@pytest.mark.parametrize("name", sorted(MAPPINGS))
@FUZZ
@given(data=st.data())
def test_any_payload_on_the_device_topic(name: str, data: st.DataObject) -> None:
    index = data.draw(st.integers(0, len(POINT_SETS[name]) - 1))
    points = POINT_SETS[name][index]
    document = data.draw(st.dictionaries(keys_of(points), JSON_VALUES, max_size=4))
    payload = data.draw(
        st.one_of(
            st.just(json.dumps(document).encode()),
            st.binary(max_size=60),
            st.sampled_from(HOSTILE),
        )
    )
    image = data.draw(images(name, index, document))
    command(points, TOPICS.set(DEVICE), payload, image)


@settings(max_examples=300, deadline=None)
@given(
    payload=st.one_of(
        st.binary(max_size=60),
        JSON_VALUES.map(lambda v: json.dumps(v).encode()),
        st.sampled_from(HOSTILE),
    )
)
def test_any_payload_on_get(payload: bytes) -> None:
    try:
        keys = parse_get(payload)
    except ValueRejectedError:
        return
    assert keys is None or (keys and all(isinstance(k, str) for k in keys))
