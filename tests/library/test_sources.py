"""Every transcribed source definition is well-formed, and every library device is listed."""

from __future__ import annotations

import re

import pytest

from tests.library.source import (
    TABLES,
    TYPES,
    UNITS,
    WORD_ORDERS,
    SourceDefinition,
    registers,
)
from tests.library.sources import SOURCES

# the meters issue 37 names; a device with no independent source maps to ()
DEVICES = frozenset(
    {
        "eastron_sdm630",
        "eastron_sdm120",
        "eastron_sdm230",
        "eastron_sdm72d_m",
        "abb_b23",
    }
)
SOURCE_NAMES = re.compile(r"^(mbmd|evcc|vendor|ha-community:[\w.-]+/[\w.-]+)$")
REPO_REF = re.compile(r"^[\w.-]+/[\w.-]+@[0-9a-f]{40}:\S+$")
KEY = re.compile(r"^[a-z][a-z0-9]*(_[a-z0-9]+)*$")
# (device, source, key, other key) pairs where a source really reads one register twice
SHARED_REGISTERS: frozenset[tuple[str, str, str, str]] = frozenset()

DEFINITIONS = [d for defs in SOURCES.values() for d in defs]
IDS = [f"{d.device}-{d.source}" for d in DEFINITIONS]


def test_every_device_is_listed() -> None:
    assert not DEVICES - SOURCES.keys(), "devices without a SOURCES entry"


@pytest.mark.parametrize(("device", "definitions"), SOURCES.items())
def test_definitions_belong_to_their_device(
    device: str, definitions: tuple[SourceDefinition, ...]
) -> None:
    assert all(d.device == device for d in definitions)
    sources = [d.source for d in definitions]
    assert len(sources) == len(set(sources)), "one definition per device per source"


@pytest.mark.parametrize("definition", DEFINITIONS, ids=IDS)
def test_definition_is_well_formed(definition: SourceDefinition) -> None:
    assert SOURCE_NAMES.match(definition.source)
    if definition.source != "vendor":
        assert REPO_REF.match(definition.ref), definition.ref
    assert definition.points
    keys = [p.key for p in definition.points]
    assert len(keys) == len(set(keys)), "keys unique per definition"
    for p in definition.points:
        assert KEY.match(p.key), p.key
        assert p.table in TABLES, p
        assert p.type in TYPES, p
        assert p.unit in UNITS, p
        assert p.word_order in WORD_ORDERS, p
        assert p.scale > 0, p
        assert p.address >= 0 and registers(p).stop <= 65536, p


@pytest.mark.parametrize("definition", DEFINITIONS, ids=IDS)
def test_points_do_not_overlap(definition: SourceDefinition) -> None:
    owner: dict[tuple[str, int], str] = {}
    for p in definition.points:
        for address in registers(p):
            other = owner.setdefault((p.table, address), p.key)
            if other != p.key:
                pair = (definition.device, definition.source, other, p.key)
                assert pair in SHARED_REGISTERS, f"{p.key} overlaps {other} at {address:#06x}"


def test_shared_registers_are_real() -> None:
    """Every declared exception names two points of one definition that do overlap."""
    for device, source, first, second in SHARED_REGISTERS:
        (definition,) = [d for d in SOURCES[device] if d.source == source]
        points = {p.key: p for p in definition.points}
        a, b = points[first], points[second]
        assert a.table == b.table and set(registers(a)) & set(registers(b))
