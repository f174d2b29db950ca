"""Fingerprints: validation (naming file, probe and field), probe reads, matching, scoring."""

from __future__ import annotations

import math
from typing import Any

import pytest
import yaml
from hypothesis import given
from hypothesis import strategies as st

from bridge.core.entity import Table
from bridge.core.fingerprint import (
    LIKE_CAP,
    Fingerprint,
    Probe,
    ascii_text,
    level,
    matches,
    probe_read,
    score,
)
from bridge.core.mapping import parse_mapping
from bridge.core.request import Read
from bridge.errors import MappingError


def mapping_text(fingerprint: object, **protocol: Any) -> str:
    return yaml.safe_dump(
        {
            "manufacturer": "Test",
            "model": "FP-1",
            "description": "a device with a fingerprint",
            "source": {"title": "tests"},
            "protocol": {"addressing": {"offset": -1}, "function_codes": [3, 6]} | protocol,
            "fingerprint": fingerprint,
            "entities": {
                "code": {"name": "Device code", "address": 0x11},
                "name_text": {"name": "Name", "address": 0x21, "type": "ascii", "count": 4},
            },
        }
    )


def refusal(fingerprint: object, **protocol: Any) -> str:
    with pytest.raises(MappingError) as refused:
        parse_mapping(mapping_text(fingerprint, **protocol), "fp.yaml")
    return str(refused.value)


def test_a_valid_fingerprint_loads_and_resolves_to_wire_reads() -> None:
    probes = [
        {"entity": "code", "one_of": [7, 8], "weight": 0.9},
        {"entity": "name_text", "ascii": "FP-1*", "weight": 0.8},
        {"address": 0x31, "unit": True, "weight": 0.5},
        {"table": "holding", "address": 0x40, "count": 2, "answers": True, "weight": 0.2},
    ]
    mapping = parse_mapping(mapping_text({"probes": probes}), "fp.yaml")
    assert mapping.fingerprint is not None
    reads = [probe_read(p, mapping.entities, mapping.protocol) for p in mapping.fingerprint.probes]
    assert reads == [
        Read(Table.HOLDING, 0x10, 1),
        Read(Table.HOLDING, 0x20, 4),
        Read(Table.HOLDING, 0x30, 1),
        Read(Table.HOLDING, 0x3F, 2),
    ]


@pytest.mark.parametrize(
    ("fingerprint", "protocol", "message"),
    [
        ({"probes": [{"entity": "nope", "answers": True, "weight": 1}]}, {},
         "fingerprint.probes.0.entity: no entity 'nope'"),
        ({"probes": [{"table": "input", "address": 1, "answers": True, "weight": 1}]}, {},
         "fingerprint.probes.0.table: reading input needs function 4"),
        ({"probes": [{"entity": "name_text", "ascii": "X", "weight": 1}]},
         {"max_read_registers": 2},
         "fingerprint.probes.0.count: 4 is more than the device reads at once (2)"),
        ({"probes": [{"address": 0x31, "equals": 1, "weight": 1}]},
         {"reserved": [{"start": 0x31}]},
         "fingerprint.probes.0.address: the read covers a reserved address"),
        ({"probes": [{"address": 0x30, "count": 2, "answers": True, "weight": 1}]},
         {"segments": [{"name": "a", "start": 0x31, "end": 0x40}]},
         "fingerprint.probes.0.address: the read crosses the edge of segment 'a'"),
        ({"probes": [{"entity": "name_text", "equals": 1, "weight": 1}]}, {},
         "fingerprint.probes.0.equals: a number is tested on 1 register, not 4"),
        ({"probes": [{"entity": "code", "equals": 1, "min": 0, "weight": 1}]}, {},
         "fingerprint.probes.0: give exactly one test"),
        ({"probes": [{"entity": "code", "weight": 1}]}, {},
         "fingerprint.probes.0: give exactly one test"),
        ({"probes": [{"entity": "code", "address": 1, "answers": True, "weight": 1}]}, {},
         "name the register by entity or by address"),
        ({"probes": [{"entity": "code", "count": 2, "answers": True, "weight": 1}]}, {},
         "an entity probe takes the entity's table and size"),
        ({"probes": [{"entity": "code", "min": 9, "max": 2, "weight": 1}]}, {},
         "min 9 is above max 2"),
        ({"probes": [{"entity": "code", "answers": True, "weight": 0}]}, {},
         "fingerprint.probes.0.weight: Input should be greater than 0"),
        ({"probes": [{"entity": "code", "answers": True, "weight": 1}] * 5}, {},
         "fingerprint.probes: Tuple should have at most 4 items"),
        ({"probes": []}, {}, "fingerprint.probes: Tuple should have at least 1 item"),
    ],
)  # fmt: skip
def test_bad_fingerprints_are_refused_naming_the_probe_and_field(
    fingerprint: object, protocol: dict[str, Any], message: str
) -> None:
    assert message in refusal(fingerprint, **protocol)


def test_a_bit_probe_is_tested_for_0_or_1_only() -> None:
    text = yaml.safe_load(mapping_text({"probes": [{"table": "coil", "address": 5, "min": 0,
                                                    "weight": 1}]}))  # fmt: skip
    text["protocol"]["function_codes"] = [1, 3, 6]
    with pytest.raises(MappingError, match=r"probes\.0\.min: a bit reads 0 or 1"):
        parse_mapping(yaml.safe_dump(text), "fp.yaml")


def probe(**fields: Any) -> Probe:
    return Probe.model_validate({"address": 0, "weight": 0.5} | fields)


@pytest.mark.parametrize(
    ("fields", "values", "expected"),
    [
        ({"equals": 0}, (0,), True),
        ({"equals": 0}, (1,), False),
        ({"min": 10, "max": 20}, (10,), True),
        ({"min": 10, "max": 20}, (21,), False),
        ({"max": 20}, (0,), True),
        ({"min": 10}, (0xFFFF,), True),
        ({"one_of": [1, 3]}, (3,), True),
        ({"one_of": [1, 3]}, (2,), False),
        ({"unit": True}, (7,), True),
        ({"unit": True}, (8,), False),
        ({"answers": True}, (0,), True),
        ({"ascii": "HGM61*"}, (0x4847, 0x4D36, 0x3132, 0x3000), True),
        ({"ascii": "HGM61*"}, (0x4847, 0x4D37, 0x3132, 0x3000), False),
        ({"answers": True}, None, False),
        ({"equals": 0}, None, False),
        ({"answers": True}, (), False),
    ],
)
def test_matches(fields: dict[str, Any], values: tuple[int, ...] | None, expected: bool) -> None:
    assert matches(probe(**fields), 7, values) is expected


def test_ascii_text_drops_padding_and_masks_unprintable_bytes() -> None:
    assert ascii_text((0x5375, 0x6E53, 0x0000)) == "SunS"
    assert ascii_text((0x4101, 0x2020)) == "A?"


def fingerprint(*weights: float, identifies: bool = True, required: int = -1) -> Fingerprint:
    probes = [
        {"address": i, "answers": True, "weight": w, "required": i == required}
        for i, w in enumerate(weights)
    ]
    return Fingerprint.model_validate({"identifies": identifies, "probes": probes})


def test_score_is_strength_times_share() -> None:
    fp = fingerprint(0.9, 0.5)
    assert score(fp, [True, True]) == round(1 - 0.1 * 0.5, 3)
    assert score(fp, [True, False]) == round(0.9 * 0.9 / 1.4, 3)
    assert score(fp, [False, True]) == round(0.5 * 0.5 / 1.4, 3)
    assert score(fp, [False, False]) == 0.0


def test_a_fingerprint_that_does_not_identify_is_scaled_low() -> None:
    fp = fingerprint(0.9, 0.9, identifies=False)
    assert score(fp, [True, True]) == round(0.99 * LIKE_CAP, 3)
    assert level(score(fp, [True, True])) == "low"
    assert score(fp, [True, False]) < score(fp, [True, True])  # the order is kept


def test_a_failed_required_probe_rules_the_model_out() -> None:
    fp = fingerprint(0.2, 0.9, 0.9, required=0)
    assert score(fp, [False, True, True]) == 0.0
    assert score(fp, [True, False, False]) > 0.0


def test_outcomes_must_match_the_probes() -> None:
    with pytest.raises(ValueError, match="1 outcomes for 2 probes"):
        score(fingerprint(0.5, 0.5), [True])


@given(
    st.lists(st.tuples(st.floats(0.01, 1.0), st.booleans()), min_size=1, max_size=4),
)
def test_score_properties(probes: list[tuple[float, bool]]) -> None:
    fp = fingerprint(*(w for w, _ in probes))
    outcomes = [hit for _, hit in probes]
    confidence = score(fp, outcomes)
    assert 0.0 <= confidence <= 1.0
    everything = score(fp, [True] * len(probes))
    assert confidence <= everything + 1e-9  # a failed probe never raises the confidence
    assert math.isclose(everything, 1 - math.prod(1 - w for w, _ in probes), abs_tol=1e-3)


@pytest.mark.parametrize(
    ("confidence", "expected"), [(0.9, "high"), (0.75, "high"), (0.5, "medium"), (0.2, "low")]
)
def test_levels(confidence: float, expected: str) -> None:
    assert level(confidence) == expected
