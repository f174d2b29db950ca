"""A command's frames, planned without a bus (bridge/core/write_plan.py)."""

from __future__ import annotations

from typing import Any

from bridge.core.entity import Entity, Table
from bridge.core.mapping import Point
from bridge.core.request import Read, Write
from bridge.core.write_plan import dependencies, frames_of, stored, unchanged, undo_of

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
