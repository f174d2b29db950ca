"""The mapping format: every item DESIGN.md lists, and errors that name file, entity and field."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from pydantic import ValidationError

from bridge.core.entity import Component, PollClass, Table
from bridge.core.mapping import (
    builtin_mapping_path,
    check_mapping_file,
    check_mapping_text,
    format_validation_errors,
    load_mapping,
    parse_mapping,
    printed_address,
    resolve_mapping_path,
)
from bridge.core.planner import limits_for
from bridge.errors import MappingError
from tests.factory import make_mapping

NO_ENTRY = "library: a shipped mapping has its index entry (docs/mappings.md, Library)"
HEADER = """
manufacturer: Test
model: T1
description: test device
source: {title: test manual}
"""


def errors_of(entities: dict[str, dict[str, Any]], **top: Any) -> list[str]:
    """The ``location: message`` rows a user would see for this mapping."""
    with pytest.raises(ValidationError) as caught:
        make_mapping(entities, **top)
    return list(format_validation_errors(caught.value))


# --- addresses ------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("name", "table", "wire", "printed"),
    [
        ("nastec_vasco", Table.HOLDING, 0x9F, "0x00A0"),  # power factor: index 0xA0
        ("nastec_vasco", Table.HOLDING, 0xAB, "0x00AC"),  # electric life, second word
        ("nastec_vasco", Table.HOLDING, 0x6E, "0x006F"),  # a gap: the offset undone
        ("p2_vfd", Table.HOLDING, 0xF008, "F0.08"),  # a parameter code
        ("vacon_nx", Table.HOLDING, 2100, "2101"),  # decimal IDs
        ("smartgen_hgm6100", Table.COIL, 7, "7"),  # generator on load, a coil
    ],
)
def test_printed_address_of_a_wire_address(
    name: str, table: Table, wire: int, printed: str
) -> None:
    """Log lines show the address as the manual prints it (bridge/modbus/poller.py)."""
    mapping = load_mapping(builtin_mapping_path(name))
    points = mapping.points().values()
    assert printed_address(points, table, wire, mapping.protocol) == printed


@pytest.mark.parametrize(
    ("addressing", "printed", "wire"),
    [
        ({"offset": -1}, 0x98, 0x97),  # Nastec index N is sent as N-1
        ({"offset": -1}, 2001, 2000),  # Vacon ID 2001 = 42001 = wire 2000
        ({"groups": {"F": 0xF0}}, "F3.01", 0xF301),  # P2 Fx.yy = 0xFxyy
        ({"groups": {"F": 0xF0}}, "F0.10", 0xF00A),  # index in binary
        ({"groups": {"y": 0xC0}}, "y0.01", 0xC001),
        ({}, "1F00H", 0x1F00),
        ({}, "0x1036", 0x1036),
        ({}, "24", 24),
    ],
)
def test_printed_address_to_wire(addressing: dict, printed: object, wire: int) -> None:
    mapping = make_mapping(
        {"v": {"name": "V", "address": printed}}, protocol={"addressing": addressing}
    )
    assert mapping.points()["v"].address == wire


@pytest.mark.parametrize(
    ("printed", "message"),
    [
        ("Q1.01", "parameter group 'Q'"),
        ("banana", "is not a number"),
        (0, "outside 0..65535"),
        ("F0.300", "does not fit"),
    ],
)
def test_bad_addresses_are_named(printed: object, message: str) -> None:
    rows = errors_of(
        {"speed": {"name": "Speed", "address": printed}},
        protocol={"addressing": {"offset": -1, "groups": {"F": 0xF0}}},
    )
    assert any(r.startswith("entities.speed.address:") and message in r for r in rows), rows


def test_tables_and_function_codes() -> None:
    mapping = make_mapping(
        {
            "h": {"name": "H", "address": 1},
            "i": {"name": "I", "address": 1, "table": "input"},
            "c": {"name": "C", "address": 1, "table": "coil"},
            "d": {"name": "D", "address": 1, "table": "discrete"},
        }
    )
    assert [p.table.read_function for p in mapping.points().values()] == [3, 4, 1, 2]
    rows = errors_of(
        {"c": {"name": "C", "address": 1, "table": "coil"}}, protocol={"function_codes": [3, 6]}
    )
    assert rows == [
        "entities.c.table: reading coil needs function 1, which the device does not support"
    ]


def test_write_function_follows_table_width_and_device() -> None:
    mapping = make_mapping(
        {
            "single": {"name": "S", "address": 1, "access": "rw"},
            "double": {"name": "D", "address": 2, "type": "u32", "access": "rw"},
            "coil": {"name": "C", "address": 1, "table": "coil", "access": "rw"},
        }
    )
    points = mapping.points()
    assert [points[k].write_function for k in ("single", "double", "coil")] == [6, 16, 5]
    rows = errors_of(
        {"double": {"name": "D", "address": 2, "type": "u32", "access": "rw"}},
        protocol={"function_codes": [3, 6]},
    )
    assert rows == ["entities.double.access: a write needs function 16, not supported"]


def test_fc16_only_device_writes_single_registers_with_16() -> None:
    mapping = make_mapping(
        {"s": {"name": "S", "address": 1, "access": "rw"}}, protocol={"function_codes": [3, 16]}
    )
    assert mapping.points()["s"].write_function == 16


# --- types and fields ------------------------------------------------------------------


@pytest.mark.parametrize(
    ("fields", "message"),
    [
        ({"table": "coil", "type": "u16"}, "has type bool"),
        ({"type": "bool", "bit": 0}, "a bit field is a boolean already"),
        ({"table": "input", "access": "rw"}, "input registers are read-only"),
        ({"table": "discrete", "access": "rw"}, "discrete inputs are read-only"),
        ({"type": "ascii"}, "count is given for ascii"),
        ({"count": 2}, "count is given for ascii"),
        ({"type": "u32", "bit": 3}, "bit fields are taken from u16"),
        ({"bit": 14, "width": 4}, "exceeds the 16-bit register"),
        ({"width": 4}, "width needs bit"),
        ({"word_radix": 10000}, "word_radix applies to u32"),
        ({"scale": 0}, "scale cannot be 0"),
        ({"enum": {0: "a"}, "scale": 0.1}, "scale/offset apply to numbers"),
        ({"enum": {0: "a", 1: "a"}}, "enum labels must be unique"),
        ({"enum": {0: "a", 23: "code_23"}}, "reserved for codes the mapping has no label"),
        ({"type": "f32", "enum": {0: "a"}}, "enum needs an integer type"),
        ({"min": 5, "max": 1}, "min 5.0 is above max 1.0"),
        ({"type": "s16", "sign_from": "x"}, "sign_from takes a magnitude"),
        ({"unit": "V", "unit_from": "x"}, "give unit or unit_from"),
        ({"press": 1}, "press (a button) needs access: w"),
        ({"access": "w", "pulse": True}, "pulse is for a write-only single bit"),
        ({"access": "rw", "write_function": 3}, "write_function is one of"),
        ({"write_address": 5}, "need access rw or w"),
        ({"dangerous": True}, "the entity is read-only"),
        ({"on_when": {"min": 1}, "access": "rw"}, "derives a read-only boolean"),
        ({"confidence": "low", "ha": {"enabled": True}}, "low-confidence entity stays disabled"),
        ({"scale": 0.1, "alarm": True}, "alarm entities are booleans or enums"),
        ({"ha": {"entity_category": "config"}}, "refuses entity_category config"),
        (
            {"enum": {0: "a"}, "ha": {"state_class": "measurement"}},
            "state_class applies to numbers",
        ),
        ({"ha": {"icon": "pump"}}, "String should match pattern"),
        ({"colour": "red"}, "Extra inputs are not permitted"),
        ({"dangerous_below": 0}, "dangerous_below guards writes of a number"),
        ({"access": "rw", "type": "bool", "dangerous_below": 0}, "guards writes of a number"),
        ({"access": "rw", "type": "s32", "dangerous_below": 0}, "a whole u16 or s16 register"),
        ({"access": "rw", "bit": 0, "width": 4, "dangerous_below": 1}, "a whole u16 or s16"),
        ({"access": "rw", "scale": -1, "dangerous_below": 0}, "a positive scale"),
        ({"access": "rw", "byte_order": "little", "dangerous_below": 0}, "a positive scale"),
        ({"requires": {"x": True}}, "requires/write_interval describe writes"),
        ({"write_interval": "2s"}, "requires/write_interval describe writes"),
        ({"access": "rw", "write_interval": 0}, "write_interval: Input should be greater than 0"),
        ({"access": "rw", "write_interval": float("nan")}, "a duration must be a finite"),
        ({"toggle_of": "x", "access": "rw"}, "toggle_of is for a write-only coil"),
        ({"toggle_of": "x", "table": "coil", "access": "w", "press": True}, "not a button"),
    ],
)
def test_field_errors_name_entity_and_field(fields: dict, message: str) -> None:
    fields.setdefault("address", 1)
    rows = errors_of({"pump_speed": {"name": "Pump speed", **fields}})
    assert any(r.startswith("entities.pump_speed") and message in r for r in rows), rows


def test_kinds_and_derived_components() -> None:
    mapping = make_mapping(
        {
            "temp": {"name": "T", "address": 1},
            "setpoint": {"name": "S", "address": 2, "access": "rw"},
            "mode": {"name": "M", "address": 3, "access": "rw", "enum": {0: "a", 1: "b"}},
            "state": {"name": "St", "address": 4, "enum": {0: "a"}},
            "flag": {"name": "F", "address": 5, "bit": 0},
            "switch": {"name": "Sw", "address": 5, "bit": 1, "access": "rw"},
            "reset": {"name": "R", "address": 6, "access": "w", "press": 0},
            "label": {"name": "L", "address": 7, "type": "ascii", "count": 2, "access": "rw"},
            "prot": {"name": "P", "address": 2, "on_when": {"min": 100}},
        }
    )
    components = {k: e.component for k, e in mapping.entities.items()}
    assert components == {
        "temp": Component.SENSOR,
        "setpoint": Component.NUMBER,
        "mode": Component.SELECT,
        "state": Component.SENSOR,
        "flag": Component.BINARY_SENSOR,
        "switch": Component.SWITCH,
        "reset": Component.BUTTON,
        "label": Component.TEXT,
        "prot": Component.BINARY_SENSOR,
    }
    assert mapping.entities["temp"].poll_class is PollClass.FAST
    assert mapping.entities["setpoint"].poll_class is PollClass.SLOW


def test_low_confidence_diagnostic_and_dangerous_settings_are_disabled_by_default() -> None:
    mapping = make_mapping(
        {
            "a": {"name": "A", "address": 1},
            "b": {"name": "B", "address": 2, "confidence": "low"},
            "c": {"name": "C", "address": 3, "ha": {"entity_category": "diagnostic"}},
            "d": {
                "name": "D",
                "address": 4,
                "ha": {"entity_category": "diagnostic", "enabled": True, "enabled_reason": "r"},
            },
            "e": {
                "name": "E",
                "address": 5,
                "access": "rw",
                "dangerous": True,
                "ha": {"entity_category": "config"},
            },
            "f": {"name": "F", "address": 6, "access": "rw", "ha": {"entity_category": "config"}},
        }
    )
    enabled = [e.enabled_by_default for e in mapping.entities.values()]
    assert enabled == [True, False, False, True, False, True]


def test_decimals_follow_scale_and_offset() -> None:
    mapping = make_mapping(
        {
            "a": {"name": "A", "address": 1, "scale": 0.1},
            "b": {"name": "B", "address": 2, "scale": 0.01},
            "c": {"name": "C", "address": 3, "scale": 1, "offset": 0.5},
            "d": {"name": "D", "address": 4, "scale": 10},
            "e": {"name": "E", "address": 5, "scale": 0.001, "precision": 1},
        }
    )
    assert [e.decimals for e in mapping.entities.values()] == [1, 2, 1, 0, 1]


# --- references, options, overlaps ----------------------------------------------------


def test_references_must_exist_and_have_the_right_kind() -> None:
    rows = errors_of(
        {
            "a": {"name": "A", "address": 1, "unit_from": "nope"},
            "b": {"name": "B", "address": 2, "sign_from": "a", "access": "rw"},
            "c": {"name": "C", "address": 3, "max_from": "e"},
            "d": {"name": "D", "address": 4, "unit_from": "a"},
            "e": {"name": "E", "address": 5, "enum": {0: "x"}},
        }
    )
    assert "entities.a.unit_from: no entity 'nope'" in rows
    assert "entities.b.sign_from: 'a' must be a 1-bit field of a register" in rows
    assert "entities.c.max_from: 'e' must be a number entity" in rows
    assert "entities.d.unit_from: 'a' must be an enum entity" in rows


@pytest.mark.parametrize(
    ("fields", "message"),
    [
        ({"toggle_of": "nothing"}, "toggle_of: 'nothing' must be a readable boolean"),
        ({"toggle_of": "level"}, "toggle_of: 'level' must be a readable boolean"),
        ({"requires": {"nothing": True}}, "requires: 'nothing' must be a readable entity"),
        ({"requires": {"locked": "yes"}}, "requires.locked: a boolean entity takes true or"),
        ({"requires": {"mode": "turbo"}}, "requires.mode: not one of 'mode''s labels"),
        ({"requires": {"level": 3}}, "Input should be"),
    ],
)
def test_toggles_and_requirements_name_readable_states(fields: dict, message: str) -> None:
    entities = {
        "breaker": {"name": "Breaker", "address": 5, "table": "coil", "access": "w"} | fields,
        "closed": {"name": "Closed", "address": 7, "table": "coil"},
        "locked": {"name": "Locked", "address": 4, "table": "coil"},
        "mode": {"name": "Mode", "address": 1, "enum": {0: "auto", 1: "manual"}},
        "level": {"name": "Level", "address": 2},
    }
    rows = errors_of(entities)
    assert any(message in row for row in rows), rows
    fine = entities | {
        "breaker": entities["breaker"]
        | {"toggle_of": "closed", "requires": {"locked": False, "mode": ["manual"]}}
    }
    assert make_mapping(fine).points()["breaker"].state_source is not None


def test_status_must_name_an_entity() -> None:
    assert errors_of({"a": {"name": "A", "address": 1}}, status="b") == ["status: no entity 'b'"]


def test_options_select_model_variants() -> None:
    options = {
        "register_9f": {"description": "idx 0x9F", "choices": ["pcb", "current"], "default": "pcb"}
    }
    mapping = make_mapping(
        {
            "pcb_temperature": {"name": "PCB", "address": 159, "when": {"register_9f": "pcb"}},
            "input_current": {
                "name": "In",
                "address": 159,
                "scale": 0.1,
                "when": {"register_9f": ["current"]},
            },
        },
        options=options,
    )
    assert list(mapping.points()) == ["pcb_temperature"]
    assert list(mapping.points({"register_9f": "current"})) == ["input_current"]


def test_variants_change_a_reading_under_the_same_key() -> None:
    options = {
        "frequency_scale": {"description": "Hz", "choices": ["0.1", "0.01"], "default": "0.1"}
    }
    mapping = make_mapping(
        {
            "frequency": {
                "name": "F",
                "address": 13,
                "scale": 0.1,
                "unit": "Hz",
                "variants": [{"when": {"frequency_scale": "0.01"}, "scale": 0.01}],
            },
        },
        options=options,
    )
    assert mapping.points()["frequency"].entity.scale == 0.1
    assert mapping.points({"frequency_scale": "0.01"})["frequency"].entity.scale == 0.01


def test_bad_options_are_named() -> None:
    options = {"model": {"description": "m", "choices": ["a", "b"], "default": "c"}}
    rows = errors_of(
        {
            "x": {"name": "X", "address": 1, "when": {"model": "z"}},
            "y": {"name": "Y", "address": 2, "when": {"colour": "red"}},
            "z": {"name": "Z", "address": 3, "variants": [{"when": {"model": "a"}, "scale": 0}]},
        },
        options=options,
    )
    assert "options.model.default: 'c' is not one of ['a', 'b']" in rows
    assert "entities.x.when: model='z' is not a choice" in rows
    assert "entities.y.when: unknown option 'colour'" in rows
    assert any(r.startswith("entities.z.variants.0:") and "scale cannot be 0" in r for r in rows)


def test_reference_missing_for_some_options_is_an_error() -> None:
    options = {"model": {"description": "m", "choices": ["a", "b"], "default": "a"}}
    rows = errors_of(
        {
            "unit": {"name": "U", "address": 1, "enum": {0: "bar"}, "when": {"model": "a"}},
            "value": {"name": "V", "address": 2, "unit_from": "unit"},
        },
        options=options,
    )
    assert rows == ["entities.value.unit_from: 'unit' is missing for some option values"]


@pytest.mark.parametrize(
    ("first", "second", "problem"),
    [
        # readers whose values cross: neither inside the other
        ({"address": 1, "type": "u32"}, {"address": 2, "type": "u32"}, "starts inside 'a'"),
        ({"address": 1, "count": 4, "type": "ascii"}, {"address": 4, "type": "u32"}, "inside"),
        ({"address": 1, "bit": 0, "width": 4}, {"address": 1, "bit": 3, "width": 2}, "bit fie"),
        # a secret and a published view of it
        ({"address": 1, "access": "rw", "secret": True}, {"address": 1}, "publish the secret"),
        ({"address": 1}, {"address": 1, "access": "rw", "secret": True}, "publish the secret"),
    ],
)
def test_overlaps_that_make_no_sense(first: dict, second: dict, problem: str) -> None:
    rows = errors_of({"a": {"name": "A", **first}, "b": {"name": "B", **second}})
    assert len(rows) == 1 and rows[0].startswith("entities.b.address: ") and problem in rows[0]


_SWITCH = {"type": "bool", "access": "rw"}


@pytest.mark.parametrize(
    ("first", "second", "row"),
    [
        (  # a write of one changes half of the other
            {"address": 1, "type": "u32", "access": "w"},
            {"address": 2, "type": "u32", "access": "w"},
            "entities.b.address: written across the writes of 'a': starts inside 'a'",
        ),
        (  # bit fields 0-3 and 3-4 of a command word
            {"address": 1, "bit": 0, "width": 4, "access": "w"},
            {"address": 1, "bit": 3, "width": 2, "access": "w"},
            "entities.b.address: written across the writes of 'a': overlapping bit fields",
        ),
        (  # one option, two codes
            {"address": 1, "enum": {0: "auto", 1: "backup"}, "access": "rw"},
            {"address": 1, "enum": {0: "auto", 3: "backup"}, "access": "rw"},
            "entities.b.enum: option 'backup' written as 3, as 1 by 'a'",
        ),
        (  # the same state read, written with other words
            {"address": 1, **_SWITCH, "words": {"write_on": 1, "write_off": 0}},
            {"address": 1, **_SWITCH, "words": {"write_on": 1, "write_off": 2, "read_off": [0]}},
            "entities.b.words: writes 1/2 for on/off, 'a' 1/0 for the same words read",
        ),
    ],
)
def test_writers_that_contradict_each_other(first: dict, second: dict, row: str) -> None:
    rows = errors_of({"a": {"name": "A", **first}, "b": {"name": "B", **second}})
    assert len(rows) == 1 and rows[0].startswith(row), rows


def test_many_entities_on_one_register() -> None:
    """A raw mode word, a switch with its words, a select, a scaled reading, bit fields
    and a u32 with its raw words: views of one value, as Home Assistant allows."""
    make_mapping(
        {
            "mode_raw": {"name": "Mode raw", "address": 1},
            "mode_scaled": {"name": "Mode scaled", "address": 1, "scale": 0.1},
            "mode": {"name": "Mode", "address": 1, "enum": {0: "auto", 1: "backup"}, "access": "rw"},
            "mode_again": {"name": "M2", "address": 1, "enum": {1: "backup", 2: "x"}, "access": "rw"},
            "backup": {"name": "Backup", "address": 1, **_SWITCH, "words": {"write_on": 1, "write_off": 0}},
            "force_charge": {"name": "FC", "address": 1, **_SWITCH, "words": {"write_on": 2, "write_off": 0}},
            "raw_setting": {"name": "Raw setting", "address": 1, "access": "rw"},
            "bit_0": {"name": "Bit 0", "address": 1, "bit": 0},
            "bit_0_switch": {"name": "Bit 0 switch", "address": 1, "bit": 0, "access": "rw"},
            "nibble": {"name": "Nibble", "address": 1, "bit": 0, "width": 4},
            "energy": {"name": "Energy", "address": 10, "type": "u32", "access": "rw"},
            "energy_high": {"name": "Energy high", "address": 10},
            "energy_low": {"name": "Energy low", "address": 11, "access": "rw"},
            "energy_low_bit": {"name": "Energy low bit", "address": 11, "bit": 15},
            "command": {"name": "Command", "address": 20, "access": "w", "type": "bool"},
            "command_word": {"name": "Command word", "address": 20},
        }
    )  # fmt: skip


def test_overlaps_that_make_sense() -> None:
    options = {"m": {"description": "m", "choices": ["a", "b"], "default": "a"}}
    make_mapping(
        {
            "state": {"name": "S", "address": 1, "bit": 0, "width": 4, "enum": {0: "off"}},
            "combo": {"name": "C", "address": 1, "bit": 7},
            "word": {"name": "W", "address": 1, "ha": {"entity_category": "diagnostic"}},
            "limit": {"name": "L", "address": 2, "access": "rw"},
            "limit_on": {"name": "LO", "address": 2, "on_when": {"min": 100}},
            "va": {"name": "VA", "address": 3, "when": {"m": "a"}},
            "vb": {"name": "VB", "address": 3, "when": {"m": "b"}},
            "cmd_run": {"name": "Run", "address": 4, "access": "w", "press": 1},
            "cmd_stop": {"name": "Stop", "address": 4, "access": "w", "press": 6},
            "fault_number": {"name": "Fault number", "address": 5},
            "fault_code": {"name": "Fault", "address": 5, "enum": {0: "none"}, "alarm": True},
            "coil_alarm": {"name": "Alarm", "address": 0, "table": "coil"},
            "coil_start": {
                "name": "Start",
                "address": 0,
                "table": "coil",
                "access": "w",
                "press": True,
            },
        },
        options=options,
    )


def test_reserved_and_segments_are_respected() -> None:
    rows = errors_of(
        {"a": {"name": "A", "address": 12}, "b": {"name": "B", "address": 19, "type": "u32"}},
        protocol={
            "reserved": [{"start": 10, "end": 15}],
            "segments": [{"name": "pd", "start": 0, "end": 19}],
        },
    )
    assert rows == [
        "entities.a.address: reads reserved holding 12",
        "entities.b.address: the value crosses a segment boundary",
    ]


def test_keys_are_snake_case() -> None:
    rows = errors_of({"Pump-Speed": {"name": "P", "address": 1}})
    assert rows == [
        "entities.Pump-Speed: keys are snake_case (a-z, 0-9, _), starting with a letter"
    ]


def test_protocol_quirks_are_expressed() -> None:
    mapping = make_mapping(
        {"a": {"name": "A", "address": 1}},
        protocol={
            "max_read_registers": 16,
            "readable_gaps": False,
            "coil_on_value": 0x00FF,
            "exceptions": {
                8: {"name": "busy", "action": "busy"},
                3: {"name": "crc", "action": "retry"},
            },
            "min_request_interval": "1000ms",
            "keepalive": {"interval": "20s"},
            "eeprom_write_interval": "1m",
            "serial": {"stopbits": 2},
        },
    )
    protocol = mapping.protocol
    assert protocol.max_read_registers == 16 and not protocol.readable_gaps
    assert protocol.coil_on_value == 0x00FF and protocol.exceptions[8].action == "busy"
    assert protocol.min_request_interval == 1.0 and protocol.keepalive
    assert protocol.keepalive.interval == 20.0 and protocol.eeprom_write_interval == 60.0


# --- files ------------------------------------------------------------------------------


def test_load_error_names_file_entity_and_field(tmp_path: Path) -> None:
    path = tmp_path / "pump.yaml"
    path.write_text(HEADER + "entities:\n  speed: {name: Speed, address: 1, scale: zero}\n")
    with pytest.raises(MappingError) as caught:
        load_mapping(path)
    assert caught.value.source == str(path)
    assert caught.value.issues == (
        "entities.speed.scale: Input should be a valid number, unable to parse string as a number",
    )
    assert str(path) in str(caught.value)


def test_every_problem_of_a_file_in_one_run() -> None:
    """A bad field in one entity does not hide a bad reference or an overlap elsewhere;
    a reference to the bad entity is not reported as missing (it is there, and wrong)."""
    text = (
        HEADER
        + """
status: state
entities:
  speed: {name: Speed, address: 1, scale: zero}
  level: {name: Level, address: 2, unit_from: units}
  limit: {name: Limit, address: 3, max_from: speed}
  state: {name: State, address: 4, type: u32}
  twin: {name: Twin, address: 5, type: u32}
"""
    )
    with pytest.raises(MappingError) as caught:
        parse_mapping(text, "pump.yaml")
    assert caught.value.issues == (
        "entities.speed.scale: Input should be a valid number, unable to parse string as a number",
        "entities.level.unit_from: no entity 'units'",
        "entities.twin.address: starts inside 'state' and ends past it (an off-by-one? a u32 "
        "takes two addresses) (holding 5)",
    )


def test_a_bad_header_field_hides_only_the_checks_it_decides() -> None:
    """A bad model name hides nothing; a bad protocol number is taken at its default for
    the checks across entities; a bad addressing rule stops them (addresses would be
    guessed), not the conventions."""
    entities = """
entities:
  speed: {name: Speed, address: 1, scale: zero}
  level: {name: Level, address: 2, unit_from: units}
  coil: {name: Relay STATUS, address: 3, table: coil}
"""
    model = HEADER.replace("model: T1", "model: [T1]") + entities
    limit = HEADER + "protocol: {max_read_registers: 200, function_codes: [3, 4]}\n" + entities
    rule = HEADER + "protocol: {addressing: {offset: many}, function_codes: [3]}\n" + entities
    reports = [check_mapping_text(text, "pump.yaml", library=True) for text in (model, limit, rule)]
    assert [[row.split(":")[0] for row in report.errors] for report in reports] == [
        ["model", "entities.speed.scale", "entities.level.unit_from"],
        [
            "protocol.max_read_registers",
            "entities.speed.scale",
            "entities.level.unit_from",
            "entities.coil.table",
        ],
        ["protocol.addressing.offset", "entities.speed.scale"],
    ]
    assert all(r.warnings == (NO_ENTRY, "entities.coil.name: 'STATUS' is written in capitals: write "
               "it as a word, or add the abbreviation to bridge/core/convention.py "
               "('Relay STATUS')",) for r in reports)  # fmt: skip
    # a user's file is not held to the library's conventions
    assert check_mapping_text(model, "pump.yaml").warnings == ()


def test_one_error_in_each_layer_is_reported_in_one_run(tmp_path: Path) -> None:
    """Fields (a bad scale), checks across fields and entities (a bit field of a u32, two
    values on one register), the protocol (a read limit Modbus does not allow, a coil on a
    device without function 1) and, for a file of the library, its conventions (a name in
    capitals, as a warning)."""
    path = tmp_path / "layers.yaml"
    path.write_text(
        HEADER
        + """protocol: {max_read_registers: 200, function_codes: [3, 6]}
entities:
  speed: {name: Speed, address: 1, scale: zero}
  temp: {name: Temperature, address: 2, bit: 3, type: u32}
  level: {name: Level, address: 5, type: u32}
  twin: {name: Twin, address: 6, type: u32}
  relay: {name: Relay, address: 6, table: coil}
  mode: {name: Motor MODE, address: 8}
"""
    )
    report = check_mapping_file(path, library=True)
    assert report.mapping is None
    assert report.errors == (
        "protocol.max_read_registers: Input should be less than or equal to 125",
        "entities.speed.scale: Input should be a valid number, unable to parse string as a number",
        "entities.temp: bit fields are taken from u16 registers",
        "entities.relay.table: reading coil needs function 1, which the device does not support",
        "entities.twin.address: starts inside 'level' and ends past it (an off-by-one? a u32 "
        "takes two addresses) (holding 6)",
    )
    assert report.warnings == (
        NO_ENTRY,
        "entities.mode.name: 'MODE' is written in capitals: write it as a word, or add the "
        "abbreviation to bridge/core/convention.py ('Motor MODE')",
    )


def test_duplicate_keys_are_refused() -> None:
    text = HEADER + "entities:\n  speed: {name: A, address: 1}\n  speed: {name: B, address: 2}\n"
    with pytest.raises(MappingError, match="duplicate key 'speed'"):
        parse_mapping(text, "dup.yaml")


def test_yaml_merge_keys_work() -> None:
    text = (
        HEADER
        + """
entities:
  a: &setting {name: A, address: 1, access: rw, eeprom: true}
  b: {<<: *setting, name: B, address: 2}
"""
    )
    mapping = parse_mapping(text, "merge.yaml")
    assert mapping.entities["b"].eeprom and mapping.entities["b"].address == 2


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[1, 2]", "must hold a mapping"),
        ("a: [", "invalid YAML"),
    ],
)
def test_not_a_mapping(text: str, message: str) -> None:
    with pytest.raises(MappingError, match=message):
        parse_mapping(text, "x.yaml")


def test_missing_file() -> None:
    with pytest.raises(MappingError, match=r"cannot read /nonexistent/pump\.yaml: No such file"):
        load_mapping(Path("/nonexistent/pump.yaml"))


def test_a_mapping_path_is_relative_to_its_base_and_errors_name_the_path_tried(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Config files give ``base`` (their folder); command-line paths use the current
    directory. A path that is not there is named in full."""
    site, elsewhere = tmp_path / "site", tmp_path / "elsewhere"
    site.mkdir()
    elsewhere.mkdir()
    (site / "pump.yaml").write_text("x: 1\n")
    (site / "pump.txt").write_text("x: 1\n")
    monkeypatch.chdir(elsewhere)
    assert resolve_mapping_path("pump.yaml", site) == site / "pump.yaml"
    assert resolve_mapping_path("nastec_vasco", site) == builtin_mapping_path("nastec_vasco")
    with pytest.raises(MappingError) as missing:
        resolve_mapping_path("pump.yaml")  # from the current directory
    assert missing.value.issues[0].endswith(f"and no file {elsewhere / 'pump.yaml'}")
    with pytest.raises(MappingError) as wrong:
        resolve_mapping_path("pump.txt", site)
    assert wrong.value.issues == (f"{site / 'pump.txt'} is not a .yaml file",)


def test_points_link_their_sources() -> None:
    mapping = make_mapping(
        {
            "unit": {"name": "U", "address": 1, "enum": {0: "bar"}},
            "v": {
                "name": "V",
                "address": 2,
                "unit_from": "unit",
                "write_address": 9,
                "access": "rw",
            },
        }
    )
    point = mapping.points()["v"]
    assert point.unit_source is not None and point.unit_source.key == "unit"
    assert point.write_address == 9 and point.table is Table.HOLDING


# --- Home Assistant presentation -----------------------------------------------------------


@pytest.mark.parametrize(
    ("fields", "message"),
    [
        ({"unit": "bar", "ha": {"device_class": "temperature"}}, "unit 'bar' is not valid for"),
        ({"unit": "rpm", "ha": {"device_class": "speed"}}, "unknown device_class 'speed'"),
        (
            {"unit": "kWh", "ha": {"device_class": "energy", "state_class": "measurement"}},
            "state_class 'measurement' is impossible for device_class energy",
        ),
        ({"enum": {0: "a"}, "ha": {"device_class": "enum"}}, "takes no device_class"),
        ({"bit": 0, "ha": {"device_class": "temperature"}}, "is not one of binary_sensor's"),
        ({"access": "w", "press": 1, "ha": {"device_class": "problem"}}, "button's"),
        # counters (issue 26): summed right, or refused
        ({"unit": "kWh", "ha": {"device_class": "energy"}}, "a counter needs state_class"),
        ({"unit": "h", "simulate": {"per_hour": 1}}, "a counter needs state_class"),
        ({"confirm_reset": 5, "ha": {"state_class": "measurement"}}, "a counter needs"),
        (
            {"unit": "J", "ha": {"device_class": "energy", "state_class": "total_increasing"}},
            "unit 'J' is not one the energy dashboard takes",
        ),
    ],
)
def test_presentation_home_assistant_refuses(fields: dict, message: str) -> None:
    rows = errors_of({"v": {"name": "V", "address": 1, **fields}})
    assert any(r.startswith("entities.v.ha:") and message in r for r in rows), rows


def test_unit_from_register_takes_no_device_class() -> None:
    rows = errors_of(
        {
            "unit": {"name": "U", "address": 1, "enum": {0: "bar"}},
            "v": {
                "name": "V",
                "address": 2,
                "unit_from": "unit",
                "ha": {"device_class": "pressure"},
            },
        }
    )
    assert rows == [
        "entities.v.ha: a unit read from a register can change category: leave device_class out"
    ]


def test_presentation_home_assistant_accepts() -> None:
    make_mapping(
        {
            "a": {
                "name": "A",
                "address": 1,
                "unit": "kWh",
                "type": "u32",
                "ha": {"device_class": "energy", "state_class": "total_increasing"},
            },
            "b": {"name": "B", "address": 3, "unit": "°C", "ha": {"device_class": "temperature"}},
            "c": {
                "name": "C",
                "address": 4,
                "bit": 0,
                "alarm": True,
                "ha": {"device_class": "problem"},
            },
            "d": {"name": "D", "address": 5, "ha": {"device_class": "power_factor"}},
            "e": {"name": "E", "address": 6, "unit": "rpm"},
        }
    )


def test_variant_presentation_is_checked_and_ha_merges() -> None:
    options = {"u": {"description": "u", "choices": ["A", "pct"], "default": "A"}}
    entity = {
        "name": "I",
        "address": 1,
        "unit": "A",
        "access": "rw",
        "min": 0,
        "max": 600,
        "ha": {"device_class": "current", "entity_category": "config"},
        "variants": [{"when": {"u": "pct"}, "unit": "%", "max": 300}],
    }
    rows = errors_of({"i": entity}, options=options)
    assert any(r.startswith("entities.i.variants.0.ha: unit '%'") for r in rows), rows
    entity["variants"][0]["ha"] = {"device_class": None}
    mapping = make_mapping({"i": entity}, options=options)
    applied = mapping.points({"u": "pct"})["i"].entity
    assert applied.ha.device_class is None
    assert applied.ha.entity_category == "config"
    assert applied.max == 300


def test_devices_of_one_model_share_points_and_read_limits_without_changing_equality() -> None:

    mapping = load_mapping(builtin_mapping_path("soft_starter"))
    fresh = load_mapping(builtin_mapping_path("soft_starter"))
    first, second = mapping.points(), mapping.points()
    assert first is not second and first == second
    assert all(first[k] is second[k] for k in first)  # the same (frozen) points
    assert limits_for(mapping).defined is limits_for(mapping).defined
    assert mapping == fresh  # what the memo holds is not part of the mapping
    faster = mapping.protocol.model_copy(update={"max_read_registers": 2})
    copy = mapping.model_copy(update={"protocol": faster})
    assert copy.points()["motor_run"] is not first["motor_run"]  # built for the copy
    assert limits_for(copy).max_registers == 2


def test_unlock_addresses_must_be_addresses() -> None:
    entity = {"x": {"name": "X", "address": 1}}
    unlock = {"address": 0x1F00, "lock": "P99.999"}
    rows = errors_of(entity, protocol={"unlock": unlock})
    assert any(r.startswith("protocol.unlock.lock: ") for r in rows), rows


@pytest.mark.parametrize("key", ["event", "last_reset"])
def test_the_keys_the_events_and_counters_use_are_reserved(key: str) -> None:
    rows = errors_of({key: {"name": "V", "address": 1}})
    assert any(r.startswith(f"entities.{key}: '{key}' is reserved") for r in rows), rows
