"""Which registers of a unit are guarded. Pure.

A ``Guard`` holds two sets of (table, wire address) cells:

- ``dangerous``: written only when the device's config says ``allow_dangerous_writes``
  (a factory reset, a breaker, a parameter that bricks the drive);
- ``hidden``: secret or write-only entities (a password), read raw by
  ``bridge/request/device/read`` only when ``bridge.allow_raw_writes`` is on.

A device's guard only grows while the bridge runs: a reloaded mapping adds its own cells
(``guard | Guard.of(points)``) but never removes one, so a mapping switched in at
runtime cannot declare a guarded register harmless.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from bridge.core.entity import Table
from bridge.core.mapping import Point

Cell = tuple[Table, int]


@dataclass(frozen=True, slots=True)
class Guard:
    """The guarded cells of one unit."""

    dangerous: frozenset[Cell] = frozenset()
    hidden: frozenset[Cell] = frozenset()

    @classmethod
    def of(cls, points: Iterable[Point]) -> Guard:
        """The cells a mapping's points mark dangerous (where they write) and secret or
        write-only (where they read and write)."""
        dangerous: set[Cell] = set()
        hidden: set[Cell] = set()
        for point in points:
            entity = point.entity
            written = _cells(point.table, point.write_address, point.count)
            if entity.dangerous:
                dangerous |= written
                if point.sign is not None:
                    dangerous |= _cells(point.sign.table, point.sign.write_address, 1)
            if entity.secret or not entity.readable:
                hidden |= written | _cells(point.table, point.address, point.count)
        return cls(frozenset(dangerous), frozenset(hidden))

    def __or__(self, other: Guard) -> Guard:
        return Guard(self.dangerous | other.dangerous, self.hidden | other.hidden)

    def dangerous_in(self, table: Table, address: int, count: int) -> list[int]:
        """Guarded addresses a write of ``count`` cells from ``address`` would touch."""
        return _within(self.dangerous, table, address, count)

    def hidden_in(self, table: Table, address: int, count: int) -> list[int]:
        """Secret or write-only addresses a read of ``count`` cells would return."""
        return _within(self.hidden, table, address, count)


UNGUARDED = Guard()


def _cells(table: Table, address: int, count: int) -> set[Cell]:
    return {(table, address + offset) for offset in range(count)}


def _within(cells: frozenset[Cell], table: Table, address: int, count: int) -> list[int]:
    return sorted(a for t, a in cells if t is table and address <= a < address + count)
