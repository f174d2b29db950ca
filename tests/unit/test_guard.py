"""The write guard and the secret set of a unit, from the shipped mappings."""

from __future__ import annotations

from bridge.core.entity import Table
from bridge.core.guard import UNGUARDED, Guard
from bridge.core.mapping import Point, builtin_mapping_path, load_mapping
from tests.factory import make_mapping

FACTORY_RESET = 0x102F


def points_of(name: str) -> list[Point]:
    return list(load_mapping(builtin_mapping_path(name)).points({}).values())


def test_dangerous_cells_are_where_the_mapping_writes() -> None:
    guard = Guard.of(points_of("soft_starter"))
    assert (Table.HOLDING, FACTORY_RESET) in guard.dangerous
    assert guard.dangerous_in(Table.HOLDING, FACTORY_RESET, (0,)) == [FACTORY_RESET]
    assert guard.dangerous_in(Table.HOLDING, FACTORY_RESET, (7,)) == [FACTORY_RESET]
    window = range(FACTORY_RESET - 3, FACTORY_RESET + 2)
    marked = {
        a for p in points_of("soft_starter") if p.entity.dangerous for a in p.span if a in window
    }
    assert guard.dangerous_in(Table.HOLDING, window.start, (1,) * len(window)) == sorted(marked)
    assert guard.dangerous_in(Table.HOLDING, FACTORY_RESET + 1, (0,)) == []
    assert guard.dangerous_in(Table.COIL, FACTORY_RESET, (1,)) == []  # another table
    motor_run = next(p for p in points_of("soft_starter") if p.key == "motor_run")
    assert not guard.dangerous_in(Table.HOLDING, motor_run.write_address, (1,))


def test_secret_and_write_only_cells_are_hidden() -> None:
    points = points_of("nastec_vasco")
    guard = Guard.of(points)
    secret = {a for p in points if p.entity.secret for a in p.span}
    assert secret and {a for t, a in guard.hidden if t is Table.HOLDING} >= secret
    readable = next(p for p in points if p.entity.readable and not p.entity.secret)
    assert guard.hidden_in(readable.table, readable.address, 1) == []
    starter_points = points_of("soft_starter")
    write_only = [p for p in starter_points if not p.entity.readable]
    assert write_only
    starter = Guard.of(starter_points)
    published = {(p.table, a) for p in starter_points if p.entity.readable for a in p.span}
    for point in write_only:
        shown = (point.table, point.write_address) in published  # a run time its clear resets
        hidden = [] if shown else [point.write_address]
        assert starter.hidden_in(point.table, point.write_address, 1) == hidden
    assert any((p.table, p.write_address) in published for p in write_only)


def test_a_write_only_switch_beside_the_sensor_of_its_register_hides_nothing() -> None:
    """Home Assistant's switch without verify and the sensor of its register: the value is
    published anyway, raw reads of it are not refused; a secret stays hidden."""
    guard = Guard.of(
        make_mapping(
            {
                "mode": {"name": "Mode", "address": 5},
                "mode_switch": {"name": "Mode switch", "address": 5, "type": "bool", "access": "w"},
                "command": {"name": "Command", "address": 6, "access": "w"},
                "password": {"name": "Password", "address": 7, "access": "w", "secret": True},
            }
        )
        .points({})
        .values()
    )
    assert guard.hidden_in(Table.HOLDING, 5, 3) == [6, 7]


def test_a_guard_only_grows() -> None:
    shipped = Guard.of(points_of("soft_starter"))
    harmless = [p for p in points_of("soft_starter") if not p.entity.dangerous]
    assert not Guard.of(harmless).dangerous
    combined = shipped | Guard.of(harmless)
    assert combined.dangerous == shipped.dangerous
    assert UNGUARDED | shipped == shipped


def test_a_harmless_bit_beside_a_guarded_one_may_be_written_with_the_guarded_bits_as_read() -> None:
    points = points_of("nastec_vasco")
    guard = Guard.of(points)
    set_value = next(p for p in points if p.key == "set_value")
    sign = set_value.sign
    assert sign is not None and not set_value.entity.dangerous
    cell = (sign.table, sign.write_address)
    guarded = guard.dangerous.get(cell, 0)
    assert guarded, "the sign's word holds guarded bits (the shipped mapping)"
    sign_bit = 1 << (sign.entity.bit or 0)
    assert not guarded & sign_bit
    held = 0b1010_0000_0000_0101
    flipped_sign = held ^ sign_bit
    assert (
        guard.dangerous_changed(sign.table, sign.write_address, (flipped_sign,), {cell: held}) == []
    )
    flipped_guarded = held ^ (guarded & -guarded)  # the lowest guarded bit
    assert guard.dangerous_changed(
        sign.table, sign.write_address, (flipped_guarded,), {cell: held}
    ) == [sign.write_address]
    # what the unit holds is unknown: any write to the word counts as a change
    assert guard.dangerous_changed(sign.table, sign.write_address, (held,), {}) == [
        sign.write_address
    ]


def test_coils_and_whole_registers_are_guarded_whatever_they_held() -> None:
    points = points_of("soft_starter")
    guard = Guard.of(points)
    cell = (Table.HOLDING, FACTORY_RESET)
    assert guard.dangerous[cell] == 0xFFFF
    assert guard.dangerous_changed(Table.HOLDING, FACTORY_RESET, (0,), {cell: 0}) == []
    assert guard.dangerous_changed(Table.HOLDING, FACTORY_RESET, (1,), {cell: 0}) == [FACTORY_RESET]
    genset = Guard.of(points_of("smartgen_hgm6100"))
    coils = [a for (t, a), bits in genset.dangerous.items() if t is Table.COIL]
    assert coils and all(genset.dangerous[(Table.COIL, a)] == 1 for a in coils)
    assert genset.dangerous_changed(Table.COIL, coils[0], (0,), {(Table.COIL, coils[0]): 0}) == [
        coils[0]
    ]


def test_a_command_register_guards_only_the_words_of_its_dangerous_buttons() -> None:
    points = points_of("p2_vfd")
    guard = Guard.of(points)
    command = next(p for p in points if p.key == "stop").write_address
    cell = (Table.HOLDING, command)
    assert cell not in guard.dangerous
    assert guard.dangerous_words[cell] == frozenset({2, 4})  # reverse run, reverse jog
    for word in (1, 3, 5, 6, 7):  # forward run and jog, stops, fault reset
        assert guard.dangerous_changed(Table.HOLDING, command, (word,), {}) == []
        assert guard.dangerous_in(Table.HOLDING, command, (word,)) == []
    for word in (2, 4):
        assert guard.dangerous_changed(Table.HOLDING, command, (word,), {cell: 6}) == [command]
        assert guard.dangerous_in(Table.HOLDING, command, (word,)) == [command]
    merged = Guard() | guard
    assert merged.dangerous_words == guard.dangerous_words


SET_VALUE = 0x1000  # P2: communication set value, s16 0.01 %, negative = reverse
SPEED_REFERENCE = 2002  # Vacon ID 2003: FB speed reference, s16 0.01 %, negative = reverse


def test_a_negative_speed_reference_is_guarded_like_reverse_run() -> None:
    """P2 1000H and Vacon 2003: a word below 0 (two's complement) is a guarded write, whatever
    the register held before; 0 and positive references are not."""
    for name, address in (("p2_vfd", SET_VALUE), ("vacon_nx", SPEED_REFERENCE)):
        guard = Guard.of(points_of(name))
        cell = (Table.HOLDING, address)
        assert cell not in guard.dangerous
        assert guard.floors[cell] == frozenset({(0, True)})
        for word in (0, 1, 5000, 10000, 0x7FFF):
            assert guard.dangerous_changed(Table.HOLDING, address, (word,), {cell: 0}) == []
            assert guard.dangerous_in(Table.HOLDING, address, (word,)) == []
        for word in (0xFFFF, 0xEC78, 0xD8F0, 0x8000):  # -1, -5000, -10000, -32768
            assert guard.dangerous_changed(Table.HOLDING, address, (word,), {cell: word}) == [
                address
            ]
            assert guard.dangerous_in(Table.HOLDING, address - 1, (0, word)) == [address]
        assert (Guard() | guard).floors == guard.floors  # survives a reload


def test_a_floor_follows_scale_offset_and_signedness() -> None:
    mapping = make_mapping(
        {
            "signed": {
                "name": "Signed", "address": 0, "type": "s16", "access": "rw",
                "scale": 0.1, "dangerous_below": -2.5,
            },
            "unsigned": {
                "name": "Unsigned", "address": 1, "access": "rw", "offset": -40,
                "dangerous_below": 0,
            },
        }
    )  # fmt: skip
    guard = Guard.of(mapping.points().values())
    assert guard.floors[(Table.HOLDING, 0)] == frozenset({(-25, True)})
    assert guard.floors[(Table.HOLDING, 1)] == frozenset({(40, False)})
    assert guard.dangerous_in(Table.HOLDING, 0, (0xFFE7,)) == []  # -25 = -2.5
    assert guard.dangerous_in(Table.HOLDING, 0, (0xFFE6,)) == [0]  # -26 = -2.6
    assert guard.dangerous_in(Table.HOLDING, 1, (40,)) == []  # raw 40 - 40 = 0
    assert guard.dangerous_in(Table.HOLDING, 1, (39,)) == [1]  # -1


def test_a_guard_of_floors_alone_survives_every_merge() -> None:
    """A mapping whose only guard is a floor (no dangerous entity): the poller builds its
    guard as ``earlier | own``, and a reload as ``own | new``; the floor stays in both."""
    floor_only = make_mapping(
        {
            "reference": {
                "name": "Reference", "address": 0, "type": "s16", "access": "rw",
                "dangerous_below": 0,
            },
        }
    )  # fmt: skip
    harmless = make_mapping({"other": {"name": "Other", "address": 5, "access": "rw"}})
    own = Guard.of(floor_only.points().values())
    assert own and not Guard()
    for merged in (UNGUARDED | own, own | Guard.of(harmless.points().values()), own | own):
        assert merged.floors == own.floors
        assert merged.dangerous_in(Table.HOLDING, 0, (0xFFFF,)) == [0]  # -1 stays guarded
