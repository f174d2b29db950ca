"""Which registers of a unit are guarded. Pure.

A ``Guard`` holds two sets of (table, wire address) cells:

- ``dangerous``: each cell with the bits of it that are guarded (0xFFFF for a whole
  register, the field's bits for a bit field, 1 for a coil); written only when the
  device's config says ``allow_dangerous_writes`` (a factory reset, a breaker, a
  parameter that bricks the drive). A harmless bit field beside a guarded one in the same
  word may be written read-modify-write: the guarded bits go back as they were read.
- ``dangerous_words``: command registers that harmless entities write too, where only
  some words are guarded: a dangerous button there guards the word it writes (the P2's
  2000H takes "reverse run" 2 only with ``allow_dangerous_writes``, "stop" 6 always). A
  register only dangerous entities write is guarded whole, whatever the word.
- ``harmless``: on a register a dangerous entity writes whole (a breaker word, a mode
  register with a dangerous option), the words harmless buttons and switches there
  declare (a reset button's word, a switch's ``words``), less any word a dangerous entity
  there names too (a dangerous button's or switch's word, a dangerous select's codes):
  those words may be written without ``allow_dangerous_writes``, any other word is
  guarded for every writer of the register. So a harmless raw number or select sharing
  the breaker word is no way around the guard: it writes only what the harmless switch
  would.
- ``floors``: registers where a value below a floor is guarded (``dangerous_below``: a
  negative speed reference of the P2's 1000H or the Vacon's 2003 runs the motor in
  reverse, so it needs ``allow_dangerous_writes`` like the reverse-run command itself);
  each cell holds its raw floors, with whether the word is read signed.
- ``hidden``: secret or write-only entities (a password), read raw by
  ``bridge/request/device/read`` only when ``bridge.allow_raw_writes`` is on; not a
  write-only entity's register that a published entity reads too (a switch without
  ``verify`` beside the sensor of its register).

A device's guard only grows while the bridge runs: a reloaded mapping adds its own cells
(``guard | Guard.of(points)``) but never removes one, so a mapping switched in at
runtime cannot declare a guarded register harmless.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from decimal import ROUND_CEILING, Decimal
from typing import TypeVar

from bridge.core.codec import COMMAND_PRESS, encode, to_signed
from bridge.core.entity import DataType, Entity, Table
from bridge.core.mapping import Point

T = TypeVar("T")

Cell = tuple[Table, int]
Floor = tuple[int, bool]  # the lowest raw value allowed, and whether the word is signed
WHOLE = 0xFFFF


@dataclass(frozen=True, slots=True)
class Guard:
    """The guarded cells of one unit."""

    dangerous: Mapping[Cell, int] = field(default_factory=dict)  # cell -> guarded bits
    hidden: frozenset[Cell] = frozenset()
    dangerous_words: Mapping[Cell, frozenset[int]] = field(default_factory=dict)
    floors: Mapping[Cell, frozenset[Floor]] = field(default_factory=dict)
    harmless: Mapping[Cell, frozenset[int]] = field(default_factory=dict)

    @classmethod
    def of(cls, points: Iterable[Point]) -> Guard:
        """The cells a mapping's points mark dangerous (where they write, with their bits)
        and secret or write-only (where they read and write)."""
        points = list(points)
        shared = {
            cell
            for p in points
            if p.entity.writable and not p.entity.dangerous
            for cell in _cells(p.table, p.write_address, p.count)
        }
        dangerous: dict[Cell, int] = {}
        words: dict[Cell, frozenset[int]] = {}
        floors: dict[Cell, frozenset[Floor]] = {}
        hidden: set[Cell] = set()
        for point in points:
            entity = point.entity
            if entity.dangerous_below is not None:
                cell = (point.table, point.write_address)
                floors[cell] = floors.get(cell, frozenset()) | {_floor(entity)}
            written = _cells(point.table, point.write_address, point.count)
            if entity.dangerous and _is_command_word(point) and written <= shared:
                for write in encode(point, COMMAND_PRESS, {}):
                    cell = (write.table, write.address)
                    words[cell] = words.get(cell, frozenset()) | set(write.values)
            elif entity.dangerous:
                for guarded in (point, point.sign):
                    if guarded is not None:
                        _add(dangerous, guarded)
            if entity.secret or not entity.readable:
                hidden |= written | _cells(point.table, point.address, point.count)
        hidden -= _published(points)  # a write-only register another entity publishes
        return cls(dangerous, frozenset(hidden), words, floors, _harmless(points, dangerous))

    def __or__(self, other: Guard) -> Guard:
        if not other:
            return self
        if not self:
            return other
        return Guard(
            _merged(self.dangerous, other.dangerous, lambda a, b: a | b),
            self.hidden | other.hidden,
            _merged(self.dangerous_words, other.dangerous_words, frozenset.union),
            _merged(self.floors, other.floors, frozenset.union),
            _harmless_of_both(self, other),
        )

    def __bool__(self) -> bool:
        """True when anything is guarded or hidden."""
        return bool(self.dangerous or self.hidden or self.dangerous_words or self.floors)

    def dangerous_in(self, table: Table, address: int, values: tuple[int, ...]) -> list[int]:
        """Guarded addresses a raw write of ``values`` from ``address`` would touch: any
        cell with guarded bits, whatever it holds, and a guarded word of a command
        register."""
        return self.dangerous_changed(table, address, values, {})

    def dangerous_changed(
        self, table: Table, address: int, values: tuple[int, ...], before: Mapping[Cell, int]
    ) -> list[int]:
        """Guarded addresses whose guarded bits a write of ``values`` from ``address``
        would change, given what the unit holds (``before``, freshly read), or that it
        would set below their floor. A coil, or a register whose content is not known,
        counts as changed."""
        changed: list[int] = []
        for offset, word in enumerate(values):
            cell = (table, address + offset)
            bits = self.dangerous.get(cell)
            old = before.get(cell)
            declared = bits == WHOLE and word in self.harmless.get(cell, ())
            if (
                word in self.dangerous_words.get(cell, ())
                or (
                    bits is not None
                    and not declared
                    and (table.is_bits or old is None or (old ^ word) & bits)
                )
                or _below(word, self.floors.get(cell, ()))
            ):
                changed.append(cell[1])
        return changed

    def hidden_in(self, table: Table, address: int, count: int) -> list[int]:
        """Secret or write-only addresses a read of ``count`` cells would return."""
        return sorted(a for t, a in self.hidden if t is table and address <= a < address + count)


UNGUARDED = Guard()


def _published(points: list[Point]) -> set[Cell]:
    """The cells a readable, not secret entity publishes, less any a secret reads or
    writes (a secret stays hidden whatever else claims its register)."""
    secret = {
        cell
        for p in points
        if p.entity.secret
        for start in (p.address, p.write_address)
        for cell in _cells(p.table, start, p.count)
    }
    published = {
        cell
        for p in points
        if p.entity.readable and not p.entity.secret
        for cell in _cells(p.table, p.address, p.count)
    }
    return published - secret


def _harmless(points: list[Point], dangerous: Mapping[Cell, int]) -> dict[Cell, frozenset[int]]:
    """The words harmless buttons and switches declare on registers guarded whole, less
    the words dangerous entities there name."""
    declared: dict[Cell, set[int]] = {}
    named: dict[Cell, set[int]] = {}
    for point in points:
        cell = (point.table, point.write_address)
        if dangerous.get(cell) != WHOLE or point.count != 1:
            continue
        words = _declared_words(point)
        target = named if point.entity.dangerous else declared
        target.setdefault(cell, set()).update(words)
    return {
        cell: frozenset(words - named.get(cell, set()))
        for cell, words in declared.items()
        if words - named.get(cell, set())
    }


def _declared_words(point: Point) -> frozenset[int]:
    """The words a whole-register button, switch or select writes (none for a number: it
    writes any word of its range, which names none)."""
    entity = point.entity
    if point.table.is_bits or entity.bit is not None:
        return frozenset()
    if entity.press is not None:
        return frozenset(w for write in encode(point, COMMAND_PRESS, {}) for w in write.values)
    if entity.words is not None:
        return frozenset({entity.words.write_on, entity.words.write_off})
    if entity.data_type is DataType.BOOL:
        return frozenset({0, 1})
    if entity.enum is not None and entity.dangerous:
        return frozenset(code & WHOLE for code in entity.enum)
    return frozenset()


def _harmless_of_both(first: Guard, second: Guard) -> dict[Cell, frozenset[int]]:
    """A register either guard guards keeps only the words every guard guarding it
    declares harmless (a reloaded mapping cannot add a harmless word)."""
    cells = set(first.dangerous) | set(second.dangerous)
    both: dict[Cell, frozenset[int]] = {}
    for cell in cells:
        allowed = [
            g.harmless.get(cell, frozenset()) for g in (first, second) if cell in g.dangerous
        ]
        words = frozenset.intersection(*allowed)
        if words:
            both[cell] = words
    return both


def _floor(entity: Entity) -> Floor:
    """The lowest raw value of ``entity`` that is not below ``dangerous_below``: raw *
    scale + offset >= limit (the entity's checks make the scale positive)."""
    limit = Decimal(repr(entity.dangerous_below))
    exact = (limit - Decimal(repr(entity.offset))) / Decimal(repr(entity.scale))
    return int(exact.to_integral_value(ROUND_CEILING)), entity.data_type is DataType.S16


def _below(word: int, floors: Iterable[Floor]) -> bool:
    return any((to_signed(word, 16) if signed else word) < floor for floor, signed in floors)


def _is_command_word(point: Point) -> bool:
    """A button that writes a whole register (not a bit, not a coil)."""
    entity = point.entity
    return entity.press is not None and entity.bit is None and not point.table.is_bits


def _add(dangerous: dict[Cell, int], point: Point) -> None:
    entity = point.entity
    width = entity.field_width
    bits = WHOLE if width is None or entity.bit is None else ((1 << width) - 1) << entity.bit
    if point.table.is_bits:
        bits = 1
    for cell in _cells(point.table, point.write_address, point.count):
        dangerous[cell] = dangerous.get(cell, 0) | bits


def _merged(
    first: Mapping[Cell, T], second: Mapping[Cell, T], join: Callable[[T, T], T]
) -> dict[Cell, T]:
    merged = dict(first)
    for cell, value in second.items():
        merged[cell] = join(merged[cell], value) if cell in merged else value
    return merged


def _cells(table: Table, address: int, count: int) -> set[Cell]:
    return {(table, address + offset) for offset in range(count)}
