"""A register proposed as an entity: decoded with the codec from known words, for each
type and word order, and refused with the mapping loader's own words."""

from __future__ import annotations

from typing import Any

import pytest
import yaml
from pydantic import ValidationError

from bridge.core.address import Addressing
from bridge.core.entity_proposal import EntityProposal, entity_fields, preview
from bridge.core.mapping import parse_mapping
from bridge.errors import MappingError

TOP = {"manufacturer": "Test", "model": "T1", "description": "d", "source": {"title": "t"}}


def shown(words: list[int], **fields: Any) -> dict[str, Any]:
    proposal = EntityProposal(device="pump", key="new", name="New", address=10, **fields)
    entity = entity_fields(proposal, Addressing())
    text = yaml.safe_dump(TOP | {"entities": {"new": entity}})
    return preview(parse_mapping(text, "proposal"), "new", words)


@pytest.mark.parametrize(
    ("fields", "words", "value", "text"),
    [
        ({}, [1234], 1234, "1234"),
        ({"scale": 0.1}, [1234], 123.4, "123.4"),
        ({"scale": 0.1, "offset": -40}, [650], 25.0, "25.0"),
        ({"type": "s16"}, [0xFFFE], -2, "-2"),
        ({"type": "u32"}, [0x0001, 0x0002], 65538, "65538"),
        ({"type": "u32", "word_order": "little"}, [0x0002, 0x0001], 65538, "65538"),
        ({"type": "s32"}, [0xFFFF, 0xFFFE], -2, "-2"),
        ({"type": "f32", "precision": 1}, [0x4148, 0x0000], 12.5, "12.5"),
        ({"type": "f32", "precision": 1, "word_order": "little"}, [0x0000, 0x4148], 12.5, "12.5"),
        ({"type": "f32", "precision": 1, "byte_order": "little"}, [0x4841, 0x0000], 12.5, "12.5"),
        ({"type": "f16", "precision": 2}, [0x3C00], 1.0, "1.00"),
        ({"type": "u64"}, [0, 0, 1, 5], 65541, "65541"),
        ({"type": "u64", "word_order": "little"}, [5, 1, 0, 0], 65541, "65541"),
        ({"type": "s64"}, [0xFFFF] * 4, -1, "-1"),
        ({"type": "f64", "precision": 1}, [0x4029, 0, 0, 0], 12.5, "12.5"),
        ({"type": "ascii", "count": 2}, [0x4142, 0x4344], "ABCD", "ABCD"),
        ({"type": "bool"}, [1], True, "On"),
        ({"table": "coil"}, [0], False, "Off"),
    ],
)
def test_a_proposal_decodes_as_the_poller_would(
    fields: dict[str, Any], words: list[int], value: object, text: str
) -> None:
    seen = shown(words, **fields)
    assert (seen["value"], seen["text"]) == (value, text)


def test_the_preview_says_the_unit_and_the_platform() -> None:
    seen = shown([215], scale=0.1, unit="°C", device_class="temperature")
    assert seen | {"value": None} == {
        "key": "new",
        "value": None,
        "text": "21.5",
        "unit": "°C",
        "decimals": 1,
        "component": "sensor",
        "registers": 1,
    }


def test_too_few_words_are_refused() -> None:
    with pytest.raises(ValueError, match="words: new spans 2 registers, 1 given"):
        shown([1], type="u32")


@pytest.mark.parametrize(
    ("fields", "row"),
    [
        ({"table": "coil", "type": "u16"}, "a coil entity has type bool, not u16"),
        ({"type": "u16", "count": 2}, "count is given for ascii values, and only for them"),
        ({"type": "u16", "scale": 0}, "scale"),
    ],
)
def test_invalid_combinations_are_refused_by_the_loader(fields: dict[str, Any], row: str) -> None:
    with pytest.raises(MappingError) as caught:
        shown([1, 2], **fields)
    assert any(row in issue for issue in caught.value.issues), caught.value.issues


@pytest.mark.parametrize(
    "fields",
    [
        {"key": "Bad Key"},
        {"type": "u128"},
        {"address": 65536},
        {"name": "x" * 101},
        {"unit": "u" * 21},
        {"scale": float("nan")},
        {"words": [70000]},
        {"words": [1] * 126},
        {"extra": 1},
    ],
)
def test_a_proposal_is_bounded(fields: dict[str, Any]) -> None:
    data = {"device": "pump", "key": "new", "name": "New", "address": 1} | fields
    with pytest.raises(ValidationError):
        EntityProposal.model_validate(data)


def test_the_address_is_written_as_the_manual_prints_it() -> None:
    proposal = EntityProposal(device="pump", key="new", name="New", address=97, scale=0.1)
    fields = entity_fields(proposal, Addressing(offset=-1))
    assert fields == {"name": "New", "address": 98, "scale": 0.1}
