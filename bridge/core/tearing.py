"""Tear-free 32-bit values on devices that read one register at a time. Pure.

A device that answers one register per read (the Nastec: ``max_read_registers: 1``) gets a
u32 counter in two reads. When the low word rolls over between them (0x0000FFFF becoming
0x00010000), the pair read is (0x0000, 0x0000): 65535 s of run time lost for a poll, or
worse the other way. ``torn_values(points, reads)`` names the two-register numbers a plan
reads in more than one read; ``untear(...)`` is the check the poller runs after the pass,
as a generator of one-register reads (send each answer in): read the high word again,
and while it moved since the last high read, read the low word and the high word again.
It returns the (high, low) words that belong together, or None when the high word kept
moving for ``ATTEMPTS`` rounds (the value is then not updated this poll).

    check = untear(torn, high_read, low_read)
    read = next(check)
    try:
        while True:
            read = check.send(answer_of(read))
    except StopIteration as done:
        words = done.value   # (high, low) or None
"""

from __future__ import annotations

from collections.abc import Generator, Iterable, Sequence
from dataclasses import dataclass

from bridge.core.entity import Order, Table
from bridge.core.mapping import Point
from bridge.core.request import Read

ATTEMPTS = 3  # rounds of "low, high again" before a value is given up for this poll


@dataclass(frozen=True, slots=True)
class Torn:
    """A two-register number read in two reads: where its high and low words are."""

    point: Point
    high: int  # wire address of the high word
    low: int

    @property
    def table(self) -> Table:
        return self.point.table

    @property
    def high_first(self) -> bool:
        """A plan reads ascending addresses: the high word came first (big word order)."""
        return self.high < self.low


def torn_values(points: Iterable[Point], reads: Sequence[Read]) -> list[Torn]:
    """The two-register numbers (u32, s32, f32) whose words ``reads`` fetch in different
    reads (one register per read, or a block boundary between them)."""
    torn: list[Torn] = []
    for point in points:
        entity = point.entity
        if point.count != 2 or entity.kind != "number" or not entity.readable:
            continue
        first = _read_of(reads, point.table, point.address)
        second = _read_of(reads, point.table, point.address + 1)
        if first is None or second is None or first == second:
            continue
        big = entity.word_order is Order.BIG
        high, low = (
            (point.address, point.address + 1) if big else (point.address + 1, point.address)
        )
        torn.append(Torn(point, high, low))
    return torn


def untear(
    torn: Torn, high: int, low: int, attempts: int = ATTEMPTS
) -> Generator[Read, int, tuple[int, int] | None]:
    """Check a torn value read as ``high`` and ``low``: yields one-register reads, takes
    their answers, returns the (high, low) that belong together or None."""
    need_low = not torn.high_first  # the low word was read before the high one: again
    for _ in range(attempts):
        if need_low:
            low = yield Read(torn.table, torn.low, 1)
        again = yield Read(torn.table, torn.high, 1)
        if again == high:
            return high, low
        high, need_low = again, True
    return None


def _read_of(reads: Sequence[Read], table: Table, address: int) -> Read | None:
    return next((r for r in reads if r.table is table and address in r.span), None)
