"""Every library mapping against every independent source of it (tests/library/sources):
one seeded register image decoded both ways, every shared point agrees or is a
disagreement the mapping lists (``library.disagreements``, with its choice)."""

from __future__ import annotations

import pytest

from bridge.core.entity import Table
from bridge.core.mapping import Mapping, shipped_library
from tests.factory import make_mapping
from tests.library.cross_check import compare, source_value, source_words
from tests.library.source import SourceDefinition, SourcePoint
from tests.library.sources import SOURCES

LIBRARY = shipped_library()
PAIRS = [(name, definition) for name in sorted(LIBRARY) for definition in SOURCES.get(name, ())]


def listed(mapping: Mapping, source: str) -> set[str]:
    """The entities the mapping lists as disagreeing with ``source``."""
    assert mapping.library is not None
    return {d.entity for d in mapping.library.disagreements if source in d.sources}


@pytest.mark.parametrize("name", sorted(LIBRARY))
def test_the_sources_named_are_the_sources_compared(name: str) -> None:
    library = LIBRARY[name].library
    assert library is not None
    assert set(library.sources) == {d.source for d in SOURCES.get(name, ())}


@pytest.mark.parametrize(("name", "definition"), PAIRS, ids=[f"{n}-{d.source}" for n, d in PAIRS])
def test_every_shared_point_agrees_or_is_a_listed_disagreement(
    name: str, definition: SourceDefinition
) -> None:
    mapping = LIBRARY[name]
    comparison = compare(mapping, definition)
    assert comparison.compared > 0, "the source shares no point with the mapping"
    found = {d.key: d.what for d in comparison.differences}
    unlisted = {
        key: what for key, what in found.items() if key not in listed(mapping, definition.source)
    }
    assert not unlisted, f"disagreements with {definition.source} not in library.disagreements"
    stale = listed(mapping, definition.source) - set(found)
    assert not stale, f"listed as disagreeing with {definition.source}, but they agree"


def test_the_pairs_cover_the_eastron_meters() -> None:
    assert {("eastron_sdm630", "mbmd"), ("eastron_sdm630", "evcc")} <= {
        (n, d.source) for n, d in PAIRS
    }
    assert {("eastron_sdm120", "mbmd"), ("eastron_sdm120", "evcc")} <= {
        (n, d.source) for n, d in PAIRS
    }


# --- the harness finds what it must -------------------------------------------------------

METER = {
    "power": {"name": "Power", "table": "input", "address": 0x0C, "type": "f32", "unit": "W"},
    "energy": {"name": "Energy", "table": "input", "address": 0x10, "type": "s32", "unit": "Wh"},
}


PROTOCOL = {"function_codes": [4]}


def definition(*points: SourcePoint) -> SourceDefinition:
    return SourceDefinition("test_meter", "mbmd", "test", points)


def test_a_unit_prefix_and_a_scale_agree_when_they_mean_the_same() -> None:
    mapping = make_mapping(METER, protocol=PROTOCOL)
    kw = SourcePoint("power", "input", 0x0C, "f32", "kW", scale=0.001)
    kwh = SourcePoint("energy", "input", 0x10, "s32", "kWh", scale=0.001)
    comparison = compare(mapping, definition(kw, kwh))
    assert comparison.agreed == ("power", "energy")
    assert comparison.differences == ()


@pytest.mark.parametrize(
    ("point", "said"),
    [
        (SourcePoint("power", "input", 0x0E, "f32", "W"), "input 0x000E as f32"),
        (SourcePoint("power", "holding", 0x0C, "f32", "W"), "holding 0x000C"),
        (SourcePoint("power", "input", 0x0C, "f32", "W", word_order="little"), "word order"),
        (SourcePoint("energy", "input", 0x10, "u32", "Wh"), "as u32"),
        (SourcePoint("energy", "input", 0x10, "s32", "Wh", scale=10.0), "the source"),
        (SourcePoint("energy", "input", 0x10, "s32", "kvarh"), "unit 'kvarh'"),
    ],
)
def test_a_point_read_differently_is_a_disagreement(point: SourcePoint, said: str) -> None:
    comparison = compare(make_mapping(METER, protocol=PROTOCOL), definition(point))
    assert comparison.agreed == ()
    (difference,) = comparison.differences
    assert difference.key == point.key and said in difference.what


def test_a_source_key_the_mapping_lacks_is_not_compared() -> None:
    other = SourcePoint("frequency", "input", 0x46, "f32", "Hz")
    comparison = compare(make_mapping(METER, protocol=PROTOCOL), definition(other))
    assert (comparison.compared, comparison.unshared) == (0, ("frequency",))


@pytest.mark.parametrize("order", ["big", "little"])
@pytest.mark.parametrize("kind", ["f32", "s16", "u32", "s32", "u64"])
def test_source_words_read_back(kind: str, order: str) -> None:
    point = SourcePoint("x", "input", 100, kind, "W", scale=0.5, word_order=order)
    raw = -1234 if kind.startswith("s") else 1234
    image = source_words(point, raw)
    assert {address for _, address in image} == set(range(100, 100 + len(image)))
    assert all(table is Table.INPUT for table, _ in image)
    assert source_value(point, image) == raw * 0.5
