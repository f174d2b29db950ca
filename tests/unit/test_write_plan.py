"""A command's frames, planned without a bus (bridge/core/write_plan.py)."""

from __future__ import annotations

from typing import Any

import pytest

from bridge.core.entity import Entity, Table
from bridge.core.mapping import Point
from bridge.core.request import Read, Write
from bridge.core.write_plan import (
    contradictions,
    dependencies,
    frames_of,
    stored,
    unchanged,
    undo_of,
)

H, C = Table.HOLDING, Table.COIL


def point(key: str = "x", address: int = 10, **fields: Any) -> Point:
    entity = Entity.model_validate({"name": key, "address": address, "access": "rw"} | fields)
    return Point(
        key=key, entity=entity, address=address, write_address=address, write_function=None
    )


def test_a_register_write_is_stored_a_coil_command_is_not() -> None:
    assert stored(Write(16, H, 4, (1, 2))) == {(H, 4): 1, (H, 5): 2}
    assert stored(Write(6, H, 9, (7,))) == {(H, 9): 7}
    assert stored(Write(5, C, 3, (0xFF00,))) == {}
    assert stored(Write(15, C, 3, (1, 0))) == {}


def test_unchanged_only_when_every_word_is_already_held() -> None:
    setting = point(eeprom=True)
    write = (Write(6, H, 10, (5,)),)
    assert unchanged(setting, write, {(H, 10): 5})
    assert not unchanged(setting, write, {(H, 10): 6})
    assert not unchanged(setting, write, {})  # never read: written
    coil = point(table="coil", eeprom=True)
    assert not unchanged(coil, (Write(5, C, 10, (0xFF00,)),), {(C, 10): 0xFF00})


def test_what_a_write_reads_first() -> None:
    assert dependencies(point(), []) == []
    bit = point(bit=3)
    assert dependencies(bit, []) == [Read(H, 10, 1)]  # the word it shares
    eeprom = point(eeprom=True)
    assert dependencies(eeprom, []) == [Read(H, 10, 1)]  # skip if unchanged
    mode = point("mode", 42, table="coil", access="r")
    assert dependencies(point(), [mode, mode]) == [Read(C, 42, 1)]  # once


def test_bit_fields_of_one_word_go_out_as_one_frame_at_the_first_place() -> None:
    """Each key was encoded over the word the keys before it left: the last holds all."""
    plan = {
        "a": (Write(6, H, 10, (0b01,)),),
        "other": (Write(6, H, 11, (9,)),),
        "b": (Write(6, H, 10, (0b11,)),),
    }
    assert frames_of(plan, set()) == [Write(6, H, 10, (0b11,)), Write(6, H, 11, (9,))]


def test_a_pulse_keeps_every_frame_of_its_register() -> None:
    plan = {
        "reset": (Write(6, H, 10, (0b100,)), Write(6, H, 10, (0,))),
        "run": (Write(6, H, 10, (0b001,)),),
    }
    assert frames_of(plan, {"reset"}) == [
        Write(6, H, 10, (0b100,)),
        Write(6, H, 10, (0,)),
        Write(6, H, 10, (0b001,)),
    ]


def test_coil_frames_are_never_merged() -> None:
    plan = {"a": (Write(5, C, 1, (0xFF00,)),), "b": (Write(5, C, 1, (0,)),)}
    assert frames_of(plan, set()) == [Write(5, C, 1, (0xFF00,)), Write(5, C, 1, (0,))]


def test_the_undo_of_each_frame_puts_back_what_was_held_before_it() -> None:
    writes = [Write(6, H, 75, (0x2000,)), Write(6, H, 75, (0x2001,)), Write(16, H, 51, (5, 6))]
    image = {(H, 75): 0, (H, 51): 1, (H, 52): 2}
    assert undo_of(writes, image) == (
        Write(6, H, 75, (0,)),
        Write(6, H, 75, (0x2000,)),  # after the first frame of the list
        Write(16, H, 51, (1, 2)),
    )
    assert image == {(H, 75): 0, (H, 51): 1, (H, 52): 2}  # not changed


def test_no_undo_where_the_image_does_not_know_or_for_a_coil() -> None:
    writes = [Write(6, H, 99, (1,)), Write(16, H, 51, (5, 6)), Write(5, C, 1, (0xFF00,))]
    assert undo_of(writes, {(H, 51): 1}) == (None, None, None)


@pytest.mark.parametrize(
    ("first", "second", "refused"),
    [
        # two bit fields of one word agree where they do not overlap
        (({"bit": 0}, Write(6, H, 10, (0b01,))), ({"bit": 1}, Write(6, H, 10, (0b11,))), {}),
        # a bit set, then the whole word without it
        (({"bit": 0}, Write(6, H, 10, (1,))), ({}, Write(6, H, 10, (2,))), {"b": "a"}),
        # the whole word, then a bit field that keeps it
        (({}, Write(6, H, 10, (3,))), ({"bit": 1}, Write(6, H, 10, (3,))), {}),
        # a switch's word and the raw word it is not
        (({"type": "bool"}, Write(6, H, 10, (1,))), ({}, Write(6, H, 10, (0,))), {"b": "a"}),
        # a u32 and its low word, agreeing or not
        (({"type": "u32"}, Write(16, H, 10, (0, 5))), ({}, Write(6, H, 11, (5,))), {}),
        (({"type": "u32"}, Write(16, H, 10, (0, 5))), ({}, Write(6, H, 11, (6,))), {"b": "a"}),
        # one coil ON (the device's ON word) and OFF
        (({"table": "coil"}, Write(5, C, 10, (0xFF00,))), ({"table": "coil"}, Write(5, C, 10, (0,))), {"b": "a"}),
        # other registers: nothing to agree on
        (({}, Write(6, H, 10, (1,))), ({}, Write(6, H, 12, (0,))), {}),
    ],
)  # fmt: skip
def test_keys_of_one_command_that_ask_a_register_for_different_words(
    first: tuple[dict[str, Any], Write], second: tuple[dict[str, Any], Write], refused: dict
) -> None:
    a = point("a", first[1].address, **first[0])
    b = point("b", second[1].address, **second[0])
    found = contradictions([a, b], {"a": (first[1],), "b": (second[1],)})
    assert set(found) == set(refused)
    for key, by in refused.items():
        assert f"another value than {by} in the same command" in found[key]


def test_a_u32_frame_holds_the_raw_words_beside_it() -> None:
    whole = Write(16, H, 10, (1, 2))
    plan = {"energy": (whole,), "low": (Write(6, H, 11, (2,)),), "high": (Write(6, H, 10, (1,)),)}
    assert frames_of(plan, set()) == [whole]
    pulsed = {"energy": (whole,), "kick": (Write(6, H, 11, (2,)), Write(6, H, 11, (0,)))}
    assert frames_of(pulsed, {"kick"}) == [whole, *pulsed["kick"]]  # a pulse keeps its frames
