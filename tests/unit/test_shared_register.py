"""Many entities on one register, written (bridge/modbus/writer.py over the fake bus of
test_writer): one read back serves every entity of the register, a command whose keys
ask one register for different words is refused whole, and a harmless entity on a
guarded register is no way around the guard (asked as a hostile MQTT client would)."""

from __future__ import annotations

import dataclasses
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bridge.core.codec import decode
from bridge.core.device_state import DeviceState
from bridge.core.entity import Table
from bridge.core.guard import Guard
from bridge.core.planner import limits_for, plan_reads
from bridge.core.request import Read, Write
from bridge.core.simulation import build_movers, initial_image
from bridge.core.timing import LinkTiming
from bridge.errors import CommandRejectedError
from bridge.modbus.writer import DeviceWriter
from tests.factory import make_mapping
from tests.unit.test_writer import FakeBus

pytestmark = pytest.mark.asyncio
H = Table.HOLDING
SWITCH = {"type": "bool", "access": "rw"}
ENTITIES: dict[str, dict[str, Any]] = {
    # a hybrid inverter's work mode: the raw word, a select, a switch, a view, a bit
    "mode_raw": {"name": "Mode raw", "address": 10, "access": "rw"},
    "mode": {
        "name": "Mode",
        "address": 10,
        "access": "rw",
        "enum": {0: "self_use", 1: "backup", 2: "feed_in"},
    },
    "backup": {
        "name": "Backup",
        "address": 10,
        **SWITCH,
        "words": {"write_on": 1, "write_off": 0, "read_off": [0, 2]},
    },
    "feeding_in": {"name": "Feeding in", "address": 10, "on_when": {"min": 2, "max": 2}},
    "bit_0": {"name": "Bit 0", "address": 10, "bit": 0, "access": "rw"},
    # a breaker word: a dangerous switch; beside it a harmless reset button, a raw number
    # and a select that may write only what the reset button does
    "breaker": {
        "name": "Breaker",
        "address": 20,
        **SWITCH,
        "dangerous": True,
        "words": {"write_on": 0x0100, "write_off": 0x0200},
    },
    "breaker_raw": {"name": "Breaker raw", "address": 20, "access": "rw"},
    "reset_trip": {"name": "Reset trip", "address": 20, "access": "w", "press": 0x0300},
    "breaker_command": {
        "name": "Breaker command",
        "address": 20,
        "access": "rw",
        "enum": {0x0100: "close", 0x0200: "open", 0x0300: "reset", 0x0400: "test"},
    },
    # a u32 and its raw words
    "energy": {"name": "Energy", "address": 30, "type": "u32", "access": "rw"},
    "energy_high": {"name": "Energy high", "address": 30, "access": "rw"},
    "energy_low": {"name": "Energy low", "address": 31, "access": "rw"},
}
SHARED = make_mapping(ENTITIES)
MODE = ("mode_raw", "mode", "backup", "feeding_in", "bit_0")


class Device:
    def __init__(self, registers: dict[int, int] | None = None, **device: Any) -> None:
        self.state = DeviceState(SHARED, {}, timing=LinkTiming(), recheck=60.0)
        self.bus = FakeBus(self.state, registers or {}, **device)
        self.changes: list[frozenset[str]] = []
        self.writer = DeviceWriter(self.state, self.bus, self.changes.append)

    async def write(self, **items: object) -> dict[str, Any]:
        return await self.writer.write_many(dict(items))

    def values(self, keys: tuple[str, ...]) -> dict[str, Any]:
        return {k: self.state.values.get(k) for k in keys}


async def test_a_switch_written_is_read_back_once_and_every_view_of_its_register_follows() -> None:
    device = Device({10: 0})
    assert await device.write(backup="ON") == {"backup": True}
    assert device.bus.frames == [Write(6, H, 10, (1,)), Read(H, 10, 1)]
    assert device.values(MODE) == {
        "mode_raw": 1,
        "mode": "backup",
        "backup": True,
        "feeding_in": False,
        "bit_0": True,
    }
    assert set().union(*device.changes) == set(MODE)


async def test_a_select_written_turns_the_switch_off_and_the_view_on() -> None:
    device = Device({10: 1})
    assert await device.write(mode="feed_in") == {"mode": "feed_in"}
    assert device.bus.frames == [Write(6, H, 10, (2,)), Read(H, 10, 1)]
    assert device.values(MODE) == {
        "mode_raw": 2,
        "mode": "feed_in",
        "backup": False,
        "feeding_in": True,
        "bit_0": False,
    }


async def test_keys_that_agree_on_the_word_go_out_as_one_frame() -> None:
    device = Device({10: 0})
    result = await device.write(backup="ON", mode="backup", mode_raw=1, bit_0=True)
    assert result == {"backup": True, "mode": "backup", "mode_raw": 1, "bit_0": True}
    assert [f for f in device.bus.frames if isinstance(f, Write)] == [Write(6, H, 10, (1,))]
    assert device.bus.frames.count(Read(H, 10, 1)) == 2  # the bit's word first, one read back


@pytest.mark.parametrize(
    ("items", "refused"),
    [
        ({"backup": "ON", "mode_raw": 0}, "mode_raw"),
        ({"mode_raw": 0, "backup": "ON"}, "backup"),  # 0 is unchanged: still a contradiction
        ({"mode": "feed_in", "backup": "ON"}, "backup"),
        ({"bit_0": True, "mode_raw": 2}, "mode_raw"),
        ({"energy": 0x00010002, "energy_low": 3}, "energy_low"),
    ],
)
async def test_keys_that_ask_one_register_for_different_words_are_refused_whole(
    items: dict[str, object], refused: str
) -> None:
    device = Device({10: 0, 30: 0, 31: 0})
    with pytest.raises(CommandRejectedError) as caught:
        await device.write(**items)
    assert list(caught.value.refused) == [refused]
    assert "another value than" in caught.value.refused[refused]
    assert not [f for f in device.bus.frames if isinstance(f, Write)]  # nothing written


async def test_a_u32_and_its_raw_words_in_one_command_are_one_frame() -> None:
    device = Device()
    await device.write(energy=0x00010002, energy_high=1, energy_low=2)
    assert [f for f in device.bus.frames if isinstance(f, Write)] == [Write(16, H, 30, (1, 2))]
    assert device.values(("energy", "energy_high", "energy_low")) == {
        "energy": 0x00010002,
        "energy_high": 1,
        "energy_low": 2,
    }


async def test_a_raw_word_written_updates_the_u32_it_is_part_of() -> None:
    device = Device({30: 1, 31: 2})
    await device.write(energy_low=7)
    assert device.values(("energy", "energy_high", "energy_low")) == {
        "energy": 0x00010007,
        "energy_high": 1,
        "energy_low": 7,
    }


@pytest.mark.parametrize(
    ("items", "allowed"),
    [
        ({"breaker": "ON"}, False),  # the dangerous switch itself
        ({"breaker_raw": 0x0100}, False),  # its ON word through the harmless raw number
        ({"breaker_raw": 0x0400}, False),  # any other word
        ({"breaker_command": "close"}, False),  # its word through a harmless select
        ({"breaker_command": "test"}, False),
        ({"breaker_raw": 0x0300}, True),  # the harmless button's word
        ({"breaker_command": "reset"}, True),
        ({"reset_trip": "PRESS"}, True),
        ({"reset_trip": "PRESS", "breaker_raw": 0x0100}, False),  # refused whole
    ],
)
async def test_a_harmless_writer_on_a_guarded_register_writes_only_harmless_words(
    items: dict[str, object], allowed: bool
) -> None:
    device = Device({20: 0x0200})
    if allowed:
        await device.write(**items)
        assert device.bus.registers[(H, 20)] == 0x0300
        return
    with pytest.raises(CommandRejectedError, match="guarded write"):
        await device.write(**items)
    assert device.bus.registers[(H, 20)] == 0x0200
    assert not [f for f in device.bus.frames if isinstance(f, Write)]


async def test_allow_dangerous_writes_opens_the_register_to_every_writer() -> None:
    device = Device({20: 0x0200}, allow_dangerous_writes=True)
    await device.write(breaker_raw=0x0400)
    assert device.values(("breaker", "breaker_raw", "breaker_command")) == {
        "breaker": None,  # 0x0400 is neither on nor off
        "breaker_raw": 0x0400,
        "breaker_command": "test",
    }


async def test_a_reloaded_mapping_cannot_declare_another_word_harmless() -> None:
    points = SHARED.points({})
    shipped = Guard.of(points.values())
    assert shipped.harmless == {(H, 20): frozenset({0x0300})}
    wider = dict(ENTITIES) | {
        "reset_test": {"name": "Test trip", "address": 20, "access": "w", "press": 0x0400}
    }
    reloaded = Guard.of(make_mapping(wider).points({}).values())
    assert reloaded.harmless[(H, 20)] == {0x0300, 0x0400}
    for guard in (shipped | reloaded, reloaded | shipped):
        assert guard.dangerous_in(H, 20, (0x0400,)) == [20]
        assert guard.dangerous_in(H, 20, (0x0300,)) == []


async def test_a_dangerous_word_is_never_harmless() -> None:
    """A harmless switch writing the dangerous switch's ON word declares nothing."""
    entities = dict(ENTITIES) | {
        "lamp": {"name": "Lamp", "address": 20, **SWITCH, "words": {"write_on": 0x0100, "write_off": 0x0300, "read_on": [0x0500]}},
    }  # fmt: skip
    guard = Guard.of(make_mapping(entities).points({}).values())
    assert guard.harmless == {(H, 20): frozenset({0x0300})}


async def test_one_read_of_a_register_decodes_every_entity_on_it() -> None:
    """A poll of the raw word's class decodes the switch, select and bits of the same
    register too (``sharing``): one read, every view fresh."""
    state = DeviceState(SHARED, {}, timing=LinkTiming(), recheck=60.0)
    (read,) = state.reads_for([state.points["mode_raw"]])
    fresh: set[tuple[Table, int]] = set()
    state.keep(read, (2,), fresh)
    assert state.sharing(["mode_raw"]) == MODE
    assert state.decode_fresh(state.sharing(["mode_raw"]), fresh) == set(MODE)
    assert state.values["mode"] == "feed_in" and state.values["backup"] is False


async def test_the_simulator_holds_one_value_per_register_and_the_others_show_it() -> None:
    """The select holds the mode word (not the raw number beside it, which would wander
    as a measurement), the u32 its two words; every view decodes from them."""
    entities = ENTITIES | {
        "mode_raw": ENTITIES["mode_raw"] | {"access": "r", "ha": {"state_class": "measurement"}},
        "energy_high": ENTITIES["energy_high"]
        | {"access": "r", "ha": {"state_class": "measurement"}},
    }
    mapping = make_mapping(entities)
    points = mapping.points({})
    image = initial_image(mapping, points)
    assert decode(points["mode"], image) == "self_use"
    assert decode(points["mode_raw"], image) == 0
    assert decode(points["backup"], image) is False
    energy = decode(points["energy"], image)
    assert isinstance(energy, int) and energy > 0
    assert decode(points["energy_low"], image) == energy & 0xFFFF
    assert not {m.point.key for m in build_movers(points, image)} & {"mode_raw", "energy_high"}


VALUES = {  # what a command may ask of each view of the mode register
    "mode_raw": st.integers(0, 3),
    "mode": st.sampled_from(["self_use", "backup", "feed_in"]),
    "backup": st.sampled_from(["ON", "OFF"]),
    "bit_0": st.booleans(),
}
ASKED = {"ON": True, "OFF": False}


@settings(max_examples=150, deadline=None)
@given(
    start=st.integers(0, 3),
    command=st.dictionaries(
        st.sampled_from(list(VALUES)), st.just(None), min_size=1, max_size=4
    ).flatmap(lambda keys: st.fixed_dictionaries({k: VALUES[k] for k in keys})),
)
async def test_a_command_on_one_register_is_done_whole_or_not_at_all(
    start: int, command: dict[str, object]
) -> None:
    """Whatever views of one register a command names: refused with nothing written, or
    written so that every view it named reads what it asked (no key silently lost to
    another's word)."""
    device = Device({10: start})
    try:
        await device.write(**command)
    except CommandRejectedError:
        assert device.bus.registers[(H, 10)] == start
        assert not [f for f in device.bus.frames if isinstance(f, Write)]
        return
    for key, value in command.items():
        assert device.state.values[key] == ASKED.get(value, value)  # type: ignore[call-overload]


async def test_the_planner_reads_a_shared_register_once_and_crossing_values_whole() -> None:
    """Five views of one word, a u32 and its raw words: each register read once, each
    value inside one read. Two u32 that cross (a mapping refuses them: the planner alone
    is asked here) make one atom of three registers, never torn."""
    points = SHARED.points({})
    reads = plan_reads(list(points.values()), limits_for(SHARED)).reads
    spans = [set(r.span) for r in reads]
    for address in (10, 20, 30, 31):
        assert sum(address in span for span in spans) == 1
    for point in points.values():
        if point.entity.readable:
            assert any(set(point.span) <= span for span in spans), point.key
    crossing = make_mapping({"a": {"name": "A", "address": 1, "type": "u32"}})
    a = crossing.points({})["a"]
    b = dataclasses.replace(a, key="b", address=2)
    (read,) = plan_reads([a, b], limits_for(crossing)).reads
    assert (read.address, read.count) == (1, 3)
