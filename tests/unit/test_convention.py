"""How a mapping presents its device: names that read well, a manufacturer that reads as
a name, enabled defaults that follow the rule of docs/mappings.md. Bad mappings in a
table, each with the row a user sees."""

from __future__ import annotations

from typing import Any

import pytest
from pydantic import ValidationError

from bridge.core.convention import ABBREVIATIONS, name_problems
from bridge.core.mapping import format_validation_errors, library_problems
from tests.factory import make_mapping

SETTING = {"address": 1, "access": "rw"}
DIAGNOSTIC = {"ha": {"entity_category": "diagnostic"}}
OPTIONS = {"m": {"choices": ["a", "b"], "default": "a", "description": "model"}}


def rows_of(entities: dict[str, dict[str, Any]], **top: Any) -> list[str]:
    """The library's convention rows of a mapping that loads all the same (with its index
    entry: the row of a missing one is tests/unit/test_library.py's)."""
    return library_problems(make_mapping(entities, **({"library": {"category": "drive"}} | top)))


@pytest.mark.parametrize(
    ("fields", "row"),
    [
        (
            {"name": "Relay 1 STATUS"},
            "entities.v.name: 'STATUS' is written in capitals: write it as a word, or add the "
            "abbreviation to bridge/core/convention.py ('Relay 1 STATUS')",
        ),
        (
            {"name": "alarm_dry_running"},
            "entities.v.name: 'alarm_dry_running' reads as an internal key: write words "
            "('alarm_dry_running')",
        ),
        (
            {"name": "Speed", "variants": [{"when": {"m": "b"}, "name": "SPEED"}]},
            "entities.v.variants.0.name: 'SPEED' is written in capitals: write it as a word, "
            "or add the abbreviation to bridge/core/convention.py ('SPEED')",
        ),
        (
            {"name": "V", "ha": {"entity_category": "diagnostic", "enabled": True}},
            "entities.v.ha.enabled: a diagnostic entity is disabled by default: say why it is "
            "enabled in ha.enabled_reason",
        ),
        (
            {
                "name": "V",
                **SETTING,
                "dangerous": True,
                "ha": {"entity_category": "config", "enabled": True},
            },
            "entities.v.ha.enabled: a dangerous setting (shown read-only, as diagnostic) is "
            "disabled by default: say why it is enabled in ha.enabled_reason",
        ),
    ],
)
def test_a_bad_presentation_is_named(fields: dict[str, Any], row: str) -> None:
    assert rows_of({"v": {"address": 1} | fields}, options=OPTIONS) == [row]


def test_a_reason_without_enabled_is_an_error() -> None:
    """enabled_reason came with the conventions: no mapping that loaded before has one."""
    with pytest.raises(ValidationError) as caught:
        make_mapping({"v": {"name": "V", "address": 1, "ha": {"enabled_reason": "look"}}})
    assert list(format_validation_errors(caught.value)) == [
        "entities.v: enabled_reason explains an explicit ha.enabled: true"
    ]


@pytest.mark.parametrize(
    "manufacturer",
    ["Unknown (P2 series)", "Unidentified (Chinese OEM)", "unknown", "Acme?", "N/A"],
)
def test_a_manufacturer_reads_as_a_name(manufacturer: str) -> None:
    rows = rows_of({"v": {"name": "V", "address": 1}}, manufacturer=manufacturer)
    assert rows == [
        f"manufacturer: {manufacturer!r} does not read as a company's name (write 'Generic' "
        "when the manual names none, and what you know in a comment)"
    ]


def test_two_entities_shown_together_have_two_names() -> None:
    rows = rows_of(
        {
            "a": {"name": "Speed", "address": 1},
            "b": {"name": "speed", "address": 2},
            "c": {"name": "Speed", "address": 3, "when": {"m": "b"}},
        },
        options=OPTIONS,
    )
    assert rows == [
        "entities.b.name: 'speed' is also the name of 'a'",
        "entities.c.name: 'Speed' is also the name of 'a'",
    ]


def test_names_for_different_options_may_be_the_same() -> None:
    make_mapping(
        {
            "a": {"name": "Speed", "address": 1, "when": {"m": "a"}},
            "b": {"name": "Speed", "address": 2, "when": {"m": "b"}},
        },
        options=OPTIONS,
    )


@pytest.mark.parametrize(
    "name",
    [
        "PID setpoint",
        "Energy (kWh)",
        "DC bus voltage",
        "HGM6110 command 5",
        "ASCII example register 0004H",
        "Mains voltage UAB",
        "Relay 3 (DOL 1)",
        "Dry-run cos φ",
        "OK",
    ],
)
def test_names_that_read_well(name: str) -> None:
    assert name_problems(name) == []


def test_abbreviations_are_written_in_capitals() -> None:
    assert all(word.isupper() and word.isalpha() for word in ABBREVIATIONS)


def test_enabled_with_a_reason_and_the_defaults_pass() -> None:
    mapping = make_mapping(
        {
            "last_alarm": {
                "name": "Last alarm",
                "address": 1,
                "ha": {
                    "entity_category": "diagnostic",
                    "enabled": True,
                    "enabled_reason": "the first thing to look at after a trip",
                },
            },
            "firmware": {"name": "Firmware", "address": 2, **DIAGNOSTIC},
            "rated_current": {
                "name": "Rated current",
                **SETTING | {"address": 3},
                "dangerous": True,
                "ha": {"entity_category": "config"},
            },
            "ramp": {
                "name": "Ramp",
                **SETTING | {"address": 4},
                "ha": {"entity_category": "config"},
            },
        }
    )
    enabled = {key: e.enabled_by_default for key, e in mapping.entities.items()}
    assert enabled == {"last_alarm": True, "firmware": False, "rated_current": False, "ramp": True}
