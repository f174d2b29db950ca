"""The write guard and the secret set of a unit, from the shipped mappings."""

from __future__ import annotations

from bridge.core.entity import Table
from bridge.core.guard import UNGUARDED, Guard
from bridge.core.mapping import Point, builtin_mapping_path, load_mapping

FACTORY_RESET = 0x102F


def points_of(name: str) -> list[Point]:
    return list(load_mapping(builtin_mapping_path(name)).points({}).values())


def test_dangerous_cells_are_where_the_mapping_writes() -> None:
    guard = Guard.of(points_of("soft_starter"))
    assert (Table.HOLDING, FACTORY_RESET) in guard.dangerous
    assert guard.dangerous_in(Table.HOLDING, FACTORY_RESET, 1) == [FACTORY_RESET]
    window = range(FACTORY_RESET - 3, FACTORY_RESET + 2)
    marked = {
        a for p in points_of("soft_starter") if p.entity.dangerous for a in p.span if a in window
    }
    assert guard.dangerous_in(Table.HOLDING, window.start, len(window)) == sorted(marked)
    assert guard.dangerous_in(Table.HOLDING, FACTORY_RESET + 1, 1) == []
    assert guard.dangerous_in(Table.COIL, FACTORY_RESET, 1) == []  # another table
    motor_run = next(p for p in points_of("soft_starter") if p.key == "motor_run")
    assert not guard.dangerous_in(Table.HOLDING, motor_run.write_address, 1)


def test_secret_and_write_only_cells_are_hidden() -> None:
    points = points_of("nastec_vasco")
    guard = Guard.of(points)
    secret = {a for p in points if p.entity.secret for a in p.span}
    assert secret and {a for t, a in guard.hidden if t is Table.HOLDING} >= secret
    readable = next(p for p in points if p.entity.readable and not p.entity.secret)
    assert guard.hidden_in(readable.table, readable.address, 1) == []
    write_only = [p for p in points_of("soft_starter") if not p.entity.readable]
    assert write_only
    starter = Guard.of(points_of("soft_starter"))
    for point in write_only:
        assert starter.hidden_in(point.table, point.write_address, 1) == [point.write_address]


def test_a_guard_only_grows() -> None:
    shipped = Guard.of(points_of("soft_starter"))
    harmless = [p for p in points_of("soft_starter") if not p.entity.dangerous]
    assert not Guard.of(harmless).dangerous
    combined = shipped | Guard.of(harmless)
    assert combined.dangerous == shipped.dangerous
    assert UNGUARDED | shipped == shipped
